"""benchmark.suite helpers with known answers (the end-to-end runs are in test_benchmark.py)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lf_predictor_ros.benchmark.suite import (
    BETWEEN_BAND,
    CONTROL_BAND,
    _estimate_errors,
    _estimate_wave_power,
    _grid_estimates,
    _LoopOutcome,
    _timed_loop_estimate_error,
)
from sim_ros.simulation import SimRecord

H = 1.0  # [s] estimator period


def _outcome(t: np.ndarray, truth: np.ndarray, estimate_t: np.ndarray,
             estimates: np.ndarray) -> _LoopOutcome:
    zeros = np.zeros_like(truth)
    record = SimRecord(t, zeros, np.ones(t.size), truth, truth, zeros, zeros, np.ones(t.size))
    return _LoopOutcome(record, False, {}, estimate_t, estimates)


def test_loop_estimate_error_compares_each_estimate_with_the_truth_when_it_was_fed() -> None:
    """Truth on a 0.1 s grid, estimates every 1 s with known errors; heading wrapped.

    North: ±0.3 m alternating (at 0.5 Hz, far above the control band: RMSE 0.3, control band
    ≈ 0); east: a constant 0.4 m (all in the control band: the mean counts); yaw: 0.02 rad
    across ±π; a slow 0.2 m sine at 0.05 rad/s added to north shows up in the control band.
    """
    t = np.round(np.arange(0.0, 2000.0, 0.1), 10)
    truth = np.zeros((t.size, 3))
    truth[:, 0] = 0.05 * t  # moving north: an estimate compared at the wrong sample would show
    truth[:, 2] = math.pi - 0.01  # heading just below π
    estimate_t = np.arange(1.0, 2000.0, H)
    estimates = np.zeros((estimate_t.size, 3))
    fast = np.where(np.arange(estimate_t.size) % 2, 0.3, -0.3)
    estimates[:, 0] = 0.05 * estimate_t + fast
    estimates[:, 1] = 0.4
    estimates[:, 2] = -math.pi + 0.01  # 0.02 rad from the truth across ±π
    out = _estimate_errors(_outcome(t, truth, estimate_t, estimates), 3, 10.0, H)
    rmse, control = out['estimate_rmse'], out['estimate_error_control_band']
    assert rmse['north'] == pytest.approx(0.3, rel=1e-9)
    assert rmse['east'] == pytest.approx(0.4, rel=1e-9)
    assert rmse['yaw'] == pytest.approx(0.02, rel=1e-6)
    assert control['north'] < 0.01  # the 0.5 Hz error is outside the control band
    assert control['east'] == pytest.approx(0.4, rel=1e-6)  # a bias is all control band
    assert control['yaw'] == pytest.approx(0.02, rel=1e-4)
    # a 0.2 m sine error in north (RMS 0.2/√2) at 0.05 rad/s is seen in CONTROL_BAND = (0, 0.1)
    # only, one at 0.2 rad/s in BETWEEN_BAND = (0.1, 0.3) only; east's bias is never between
    for omega, inside, outside in ((0.05, 'control', 'between'), (0.2, 'between', 'control')):
        band = CONTROL_BAND if inside == 'control' else BETWEEN_BAND
        assert band[0] <= omega <= band[1]
        sine = estimates.copy()
        sine[:, 0] += 0.2 * np.sin(omega * estimate_t)
        out = _estimate_errors(_outcome(t, truth, estimate_t, sine), 3, 10.0, H)
        assert out[f'estimate_error_{inside}_band']['north'] == pytest.approx(
            0.2 / math.sqrt(2), rel=0.1)
        assert out[f'estimate_error_{outside}_band']['north'] < 0.02
        assert out['estimate_error_between_band']['east'] < 1e-6
    # the timed form: the same rows, each with its estimate time, from start on
    times, error = _timed_loop_estimate_error(_outcome(t, truth, estimate_t, estimates), 3, 10.0)
    np.testing.assert_array_equal(times, estimate_t[estimate_t >= 10.0])
    np.testing.assert_allclose(error[:, 1], 0.4, rtol=1e-9)
    # samples before start are not scored: a large early error changes nothing
    early = estimates.copy()
    early[:5, 0] += 100.0
    assert _estimate_errors(_outcome(t, truth, estimate_t, early), 3, 10.0, H)['estimate_rmse'] \
        == rmse
    # one DOF; an empty (aborted before start) loop is NaN, not a crash
    one = _estimate_errors(_outcome(t, truth, estimate_t, estimates), 1, 10.0, H)
    assert one['estimate_rmse'] == {'north': pytest.approx(0.3, rel=1e-9)}
    empty = _estimate_errors(_outcome(t, truth, np.zeros(0), np.zeros((0, 3))), 3, 10.0, H)
    assert all(math.isnan(v) for part in empty.values() for v in part.values())


def test_held_estimates_are_read_once_per_estimate_on_a_finer_sensor_grid() -> None:
    """A 0.1 s scenario records the held estimate at every sensor sample (`GridInput`).

    An estimate series that is a 0.5 rad/s sine (amplitude 1 m) on the 1 s estimator grid, held
    for ten 0.1 s samples: its wave-band power (0.3–1.3 rad/s) is ≈ 1/2 m² and its error
    against a still truth is all outside the control band, once the series is read one sample
    per estimate (stride 10). Read at the 1 s period without the stride (the bug before the
    twenty-fourth session), the sine would sit at 0.05 rad/s: no wave power, all in the control
    band.
    """
    sensor = 0.1
    t = np.round(np.arange(sensor, 3000.0 + sensor / 2, sensor), 10)
    grid = np.floor(t + 1e-9)  # the time of the estimate held at each sensor sample
    truth = np.zeros((t.size, 3))
    estimates = np.zeros((t.size, 3))
    estimates[:, 0] = np.sin(0.5 * grid)
    # what `_run_loop` keeps: one sample per estimate
    outcome = _outcome(t, truth, *_grid_estimates(t, estimates, 10))
    assert outcome.estimate_t[:3].tolist() == [1.0, 2.0, 3.0]
    power = _estimate_wave_power(outcome, 3, 100.0, 1.0)
    assert power['north'] == pytest.approx(0.5, rel=0.05)
    errors = _estimate_errors(outcome, 3, 100.0, 1.0)
    assert errors['estimate_rmse']['north'] == pytest.approx(1 / math.sqrt(2), rel=0.01)
    assert errors['estimate_error_control_band']['north'] < 0.05
    held = _outcome(t, truth, t, estimates)  # the held series read as if at h (the old bug)
    wrong = _estimate_wave_power(held, 3, 100.0, 1.0)
    assert wrong['north'] < 0.05
