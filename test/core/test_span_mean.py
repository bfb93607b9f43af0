"""The running mean over a time span (core.span_mean)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lf_predictor_ros.core.span_mean import SpanMean


def test_one_wave_period_drops_the_wave_and_keeps_a_constant() -> None:
    """0.3 + 0.8 sin(ω0 t + 0.4), ω0 = 2π/12.5 s, h = 0.1 s: the mean over one period is 0.3.

    The window holds span / h = 125 samples; each mean once it reaches back is 0.3 within
    rounding, whatever the phase.
    """
    h, period = 0.1, 12.5
    window = SpanMean(h)
    means = []
    for k in range(400):
        t = k * h
        value = np.array([0.3 + 0.8 * math.sin(2.0 * math.pi / period * t + 0.4), -1.0])
        window.add(t, value, period)
        mean = window.mean()
        if k < 125:
            assert mean is None  # the window does not reach back over the span yet
        else:
            assert mean is not None
            means.append(mean)
    np.testing.assert_allclose(np.array(means), np.tile([0.3, -1.0], (len(means), 1)),
                               atol=1e-12)
    assert len(window._samples) == 125  # noqa: SLF001 - span / h samples


def test_a_ramp_is_averaged_to_its_value_half_a_span_ago() -> None:
    """v(t) = 0.02 t at h = 1 s over a 10 s span: the mean is v(t − 4.5 s) (samples t−9 … t)."""
    window = SpanMean(1.0)
    for k in range(30):
        window.add(float(k), np.array([0.02 * k]), 10.0)
    mean = window.mean()
    assert mean is not None
    assert mean[0] == pytest.approx(0.02 * 24.5, abs=1e-12)


def test_a_new_span_a_short_span_and_off() -> None:
    """A shorter span trims at once; one below h keeps the newest; None clears; shapes reset."""
    window = SpanMean(1.0)
    for k in range(20):
        window.add(float(k), np.array([float(k)]), 10.0)
    window.add(20.0, np.array([20.0]), 4.0)  # samples 17 … 20
    assert window.mean() == pytest.approx([18.5])
    window.add(21.0, np.array([21.0]), 0.2)  # below h: the newest alone
    assert window.mean() == pytest.approx([21.0])
    window.add(22.0, np.array([22.0]), None)
    assert window.mean() is None
    window.add(23.0, np.array([1.0, 2.0]), 2.0)  # a new shape starts again
    assert window.mean() is None
    window.add(24.0, np.array([3.0, 4.0]), 2.0)
    window.add(25.0, np.array([5.0, 6.0]), 2.0)
    assert window.mean() == pytest.approx([4.0, 5.0])


@pytest.mark.parametrize('bad', [0.0, -1.0, math.nan, math.inf])
def test_a_span_or_sample_time_that_is_no_time_is_refused(bad: float) -> None:
    with pytest.raises(ValueError, match='sample_time'):
        SpanMean(bad)
    window = SpanMean(1.0)
    with pytest.raises(ValueError, match='span'):
        window.add(0.0, np.zeros(3), bad)
