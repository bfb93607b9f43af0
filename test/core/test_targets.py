"""Target appending (thesis §4.2.2, Algorithm 4.1 lines 30–35): bookkeeping and a reference."""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
import pytest
from scipy import signal

from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.targets import (
    TargetWindow,
    append_targets,
    start_targets,
    training_mask,
)


def test_append_drops_newest_beta_minus_delta_and_oldest_delta() -> None:
    # old targets are samples 0..9 (value = index); the filtered window (α = 8) covers samples
    # 5..12 (value = 1000 + index). Δ = 3, β = 5.
    old = np.arange(10.0)
    filtered = 1000.0 + np.arange(5.0, 13.0)
    new = append_targets(old, filtered, retrain_every=3, append_len=5)
    # line 31 drops 8, 9 (newest β − Δ = 2); line 32 drops 0, 1, 2; line 33 appends 8..12
    np.testing.assert_array_equal(new, [3, 4, 5, 6, 7, 1008, 1009, 1010, 1011, 1012])
    assert np.all(np.mod(new, 1000.0) == np.arange(3, 13))  # contiguous sample indices
    np.testing.assert_array_equal(old, np.arange(10.0))  # inputs untouched
    new[0] = -1.0
    assert old[3] == 3.0  # result is not a view of the input


def test_append_multi_dof_columns() -> None:
    old = np.column_stack([np.arange(6.0), -np.arange(6.0)])
    filtered = np.column_stack([100.0 + np.arange(2.0, 8.0), -100.0 - np.arange(2.0, 8.0)])
    new = append_targets(old, filtered, retrain_every=2, append_len=3)
    np.testing.assert_array_equal(new[:, 0], [2, 3, 4, 105, 106, 107])
    np.testing.assert_array_equal(new[:, 1], -new[:, 0])


def test_start_up_and_growth_to_max_len() -> None:
    filtered = np.arange(8.0)  # samples 0..7, transient ε = 2
    first = append_targets(None, filtered, 3, 5, transient_len=2)
    np.testing.assert_array_equal(first, np.arange(2.0, 8.0))
    np.testing.assert_array_equal(start_targets(filtered, 2), first)
    # window slides by Δ = 3 each time; N = 10 caps the growth
    second = append_targets(first, np.arange(3.0, 11.0), 3, 5, max_len=10)
    np.testing.assert_array_equal(second, np.arange(2.0, 11.0))  # 9 ≤ N: nothing dropped
    third = append_targets(second, np.arange(6.0, 14.0), 3, 5, max_len=10)
    np.testing.assert_array_equal(third, np.arange(4.0, 14.0))  # capped at N = 10
    fourth = append_targets(third, np.arange(9.0, 17.0), 3, 5, max_len=10)
    np.testing.assert_array_equal(fourth, np.arange(7.0, 17.0))  # steady state: drops Δ
    # thesis-literal (no max_len): the length stays at its start-up length
    literal = append_targets(first, np.arange(3.0, 11.0), 3, 5)
    assert literal.shape == first.shape


def test_target_window_tracks_sample_indices() -> None:
    window = TargetWindow.start(np.arange(20.0, 28.0), end_index=27, transient_len=2)
    np.testing.assert_array_equal(window.indices(), np.arange(22, 28))
    np.testing.assert_allclose(window.times(0.5, time_offset=100.0),
                               100.0 + 0.5 * np.arange(22, 28))
    later = window.append(np.arange(23.0, 31.0), end_index=30, append_len=5, max_len=10)
    assert (later.start_index, later.end_index, len(later)) == (22, 30, 9)
    np.testing.assert_array_equal(later.values, later.indices())  # value = index everywhere
    # a late training (shift 4 instead of 3) still joins without a gap
    late = later.append(np.arange(27.0, 35.0), end_index=34, append_len=5, max_len=10)
    np.testing.assert_array_equal(late.values, np.arange(25.0, 35.0))
    np.testing.assert_array_equal(late.values, late.indices())
    assert not late.values.flags.writeable
    with pytest.raises(ValueError, match='gap'):
        late.append(np.arange(33.0, 41.0), end_index=40, append_len=5)  # shift 6 > β


def test_training_mask() -> None:
    np.testing.assert_array_equal(training_mask(10, 3), [True] * 7 + [False] * 3)
    assert not training_mask(2, 5).any()
    assert training_mask(4, 0).all()
    with pytest.raises(ValueError):
        training_mask(-1, 2)


def test_invalid_lengths_raise() -> None:
    old = np.arange(10.0)
    with pytest.raises(ValueError, match='Δ must be ≥ 1'):
        append_targets(old, np.arange(8.0), 0, 5)
    with pytest.raises(ValueError, match='Δ ≤ β ≤ α'):
        append_targets(old, np.arange(8.0), 3, 9)
    with pytest.raises(ValueError, match='DOFs'):
        append_targets(old, np.ones((8, 2)), 3, 5)
    with pytest.raises(ValueError, match='transient_len'):
        start_targets(np.arange(4.0), 4)


def _signal(n: int, sample_time: float) -> NDArray[np.float64]:
    """LF sinusoids + a 0.8 rad/s wave-like oscillation + noise, seeded."""
    rng = np.random.default_rng(42)
    t = np.arange(n) * sample_time
    y = (2.0 * np.sin(0.02 * t + 0.3) + 1.0 * np.sin(0.05 * t + 1.1)
         + 0.7 * np.sin(0.8 * t) + 0.05 * rng.standard_normal(n))
    return np.asarray(y, dtype=np.float64)


def _build_by_appending(y: NDArray[np.float64], sos: NDArray[np.float64],
                        params: PredictorParams, append_len: int) -> list[TargetWindow]:
    """Run the retraining loop of Algorithm 4.1 over y, return every target window."""
    alpha, delta = params.filter_samples, params.retrain_samples
    windows: list[TargetWindow] = []
    window: TargetWindow | None = None
    for end in range(alpha - 1, y.size, delta):
        filtered = signal.sosfiltfilt(sos, y[end - alpha + 1:end + 1])
        if window is None:
            window = TargetWindow.start(filtered, end, params.transient_samples)
        else:
            window = window.append(filtered, end, append_len,
                                   max_len=params.training_samples)
        windows.append(window)
    return windows


def test_appended_targets_equal_whole_signal_filtering_away_from_transients() -> None:
    # h = 0.5 s, Δ = 120, ε = 60, α = 360, β = 240, N = 1200 samples
    params = PredictorParams(sample_time=0.5)
    sample_time = params.sample_time
    y = _signal(8000, sample_time)
    # the test's own zero-phase wave filter: 4th-order Butterworth low-pass at 0.3 rad/s
    sos = signal.butter(4, 0.3 / (math.pi / sample_time), output='sos')
    reference = signal.sosfiltfilt(sos, y)
    windows = _build_by_appending(y, sos, params, params.append_samples)
    assert len(windows[-1]) == params.training_samples
    errors = []
    for window in windows:
        mask = training_mask(len(window), params.transient_samples)
        idx = window.indices()
        assert idx[0] >= 0 and idx[-1] < y.size
        errors.append(np.max(np.abs(window.values[mask] - reference[idx[mask]])))
    worst = max(errors)
    # ε = 30 s is about 3.5 time constants of the filter: the transient has decayed to
    # 0.3 % of the 1.7 m signal std (measured worst 5.2e-3 m, median 2.8e-3 m)
    assert worst < 1e-2
    # the newest ε targets (masked) and appending with β = α − 1 (start transient kept) are
    # visibly worse, so the bound above really tests the overlap rule
    last = windows[-1]
    tail = np.max(np.abs(last.values[-params.transient_samples:]
                         - reference[last.indices()[-params.transient_samples:]]))
    assert tail > 10 * worst
    bad = _build_by_appending(y, sos, params, params.filter_samples - 1)
    bad_errors = [np.max(np.abs(w.values[training_mask(len(w), params.transient_samples)]
                                - reference[w.indices()[training_mask(len(w),
                                                                      params.transient_samples)]]))
                  for w in bad]
    assert max(bad_errors) > 10 * worst
