"""Adaptation metric: change times, rolling RMSE, recovery time, frozen ratio (known answers)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lf_predictor_ros.benchmark.adaptation import (
    adaptation_events,
    change_times,
    rolling_rmse,
)
from sim_ros.physics import schedule


def test_change_times_of_the_thesis_ramps_and_of_steps() -> None:
    fig41 = schedule.thesis_fig_4_1()  # corners at 60, 180, 300, 420 min; flat to 480 min
    assert change_times(fig41, 0.0, 28800.0) == (3600.0, 10800.0, 18000.0, 25200.0)
    assert change_times(fig41, 5000.0, 20000.0) == (10800.0, 18000.0)
    steps = schedule.steps(0.8, [(1000.0, 0.5), (2000.0, 0.5), (3000.0, 1.1)])
    assert change_times(steps, 0.0, 5000.0) == (1000.0, 3000.0)  # 2000 s changes nothing
    assert change_times(schedule.constant(0.8), 0.0, 1e5) == ()
    ramp = schedule.ramp(100.0, 700.0, 0.4, 1.0)
    assert change_times(ramp, 0.0, 1000.0) == (100.0, 700.0)


def test_rolling_rmse_is_the_trailing_window_rms() -> None:
    t = np.arange(10.0)
    error = np.array([3.0, 4.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, -2.0, 2.0])
    out = rolling_rmse(t, error, 2.0)
    assert np.isnan(out[0])
    np.testing.assert_allclose(out[1:], [math.sqrt(12.5), math.sqrt(8.0), 0.0, math.sqrt(0.5),
                                         1.0, 1.0, 1.0, math.sqrt(2.5), 2.0])
    assert np.all(np.isnan(rolling_rmse(t[:3], error[:3], 5.0)))


def test_recovery_time_and_frozen_ratio_known_answer() -> None:
    """Adaptive error 1 except 5 over [2000, 2050); frozen error 4; Δ = 60 s, 1 s samples.

    The trailing window (s − 60, s] holds nb samples of 5: RMS² = (25 nb + 60 − nb)/60 ≤ 1.44
    needs nb ≤ 1, i.e. s ≥ 2049 + 59 = 2108: recovery 108 s. Over [2000, 2120): 50 samples of
    5 and 70 of 1, RMS = √(1320/120) = √11; frozen 4: ratio 4/√11.
    """
    t = np.arange(0.0, 4000.0)
    adaptive = np.ones_like(t)
    adaptive[(t >= 2000.0) & (t < 2050.0)] = 5.0
    frozen = np.full_like(t, 4.0)
    (event,) = adaptation_events(t, adaptive, frozen, (2000.0,), 60.0)
    assert event.time == 2000.0
    assert event.steady_rmse == 1.0
    assert event.recovery_time == 108.0
    assert event.adaptive_rmse_after == pytest.approx(math.sqrt(11.0), rel=1e-12)
    assert event.frozen_ratio == pytest.approx(4.0 / math.sqrt(11.0), rel=1e-12)
    assert event.to_dict()['recovery_time'] == 108.0


def test_steady_rmse_is_the_settled_level_of_the_following_segment() -> None:
    """Two changes (1000 s, 2000 s); steady = median r(t) over the second half after each.

    After 1000: error 5 until 1300, then 3: steady 3, bound 3.6. A trailing 60-s window with nb
    samples of 5 has RMS² = (25 nb + 9 (60 − nb))/60 ≤ 12.96 for nb ≤ 14, i.e. from s = 1345:
    recovery 345 s. After 2000: error 1, steady 1, bound 1.2: nb samples of 3 allowed while
    (9 nb + 60 − nb)/60 ≤ 1.44, nb ≤ 3, from s = 2056: recovery 56 s. Frozen = 3 × adaptive.
    """
    t = np.arange(0.0, 3000.0)
    adaptive = np.ones_like(t)
    adaptive[(t >= 1000.0) & (t < 2000.0)] = 3.0
    adaptive[(t >= 1000.0) & (t < 1300.0)] = 5.0
    first, second = adaptation_events(t, adaptive, 3.0 * adaptive, (1000.0, 2000.0, 5000.0),
                                      60.0)
    assert first.steady_rmse == 3.0 and first.recovery_time == 345.0
    assert second.steady_rmse == 1.0 and second.recovery_time == 56.0
    assert first.frozen_ratio == pytest.approx(3.0)


def test_a_level_never_reached_again_is_no_recovery() -> None:
    """At its new level at once: recovery 0; a rolling RMSE that keeps swinging: +inf.

    The swing: a 10-s burst every 50 s, so every 60-s window holds 10–20 burst samples and never
    stays within 1.2× its median for a full window.
    """
    t = np.arange(0.0, 2000.0)
    adaptive = np.ones_like(t)
    adaptive[t >= 1000.0] = 4.0
    (event,) = adaptation_events(t, adaptive, adaptive, (1000.0,), 60.0)
    assert event.steady_rmse == 4.0
    assert event.recovery_time == 0.0  # already at its (bad) steady level
    spiky = np.ones_like(t)
    spiky[t >= 1000.0] = np.where(np.arange(1000) % 50 < 10, 10.0, 1.0)  # a burst every 50 s
    (burst,) = adaptation_events(t, spiky, spiky, (1000.0,), 60.0)
    assert math.isinf(burst.recovery_time)  # every 60-s window holds a burst


def test_invalid_inputs_are_rejected() -> None:
    t = np.arange(10.0)
    with pytest.raises(ValueError, match='window'):
        rolling_rmse(t, np.zeros(10), 0.0)
    with pytest.raises(ValueError, match='uniformly'):
        rolling_rmse(np.array([0.0, 1.0, 3.0]), np.zeros(3), 1.0)
    with pytest.raises(ValueError, match='tolerance'):
        adaptation_events(t, np.zeros(10), np.zeros(10), (5.0,), 2.0, tolerance=0.9)
