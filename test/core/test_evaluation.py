"""Tests for offline evaluation: run_estimator, score (RMSE, rates, wave band, lag), tables."""
from __future__ import annotations

import json
import math

import numpy as np
from numpy.typing import NDArray
import pytest
from scipy import signal

from lf_predictor_ros.core.estimator import EstimatorStatus
from lf_predictor_ros.core.evaluation import (
    LoopRun,
    Metrics,
    band_rms,
    format_table,
    loop_metrics,
    run_estimator,
    score,
)

FloatArray = NDArray[np.float64]


def _lf_series(seed: int, n: int, dt: float) -> FloatArray:
    """Three seeded LF channels: white noise through a 2nd-order low-pass at 0.05 rad/s."""
    rng = np.random.default_rng(seed)
    b, a = signal.bilinear([0.05**2], [1.0, 2 * 0.7 * 0.05, 0.05**2], 1.0 / dt)
    lf = signal.lfilter(b, a, rng.normal(size=(n + 5000, 3)), axis=0)[5000:]
    return np.asarray(lf / np.std(lf, axis=0), dtype=np.float64)


@pytest.mark.parametrize('delay', [1, 7, 25, -12])
def test_pure_delay_gives_lag_within_one_sample(delay: int) -> None:
    dt, n = 0.1, 6000
    t = np.arange(n) * dt
    truth = _lf_series(1, n + abs(delay), dt)
    if delay >= 0:
        estimate, truth = truth[:n], truth[delay : delay + n]  # estimate[k] = truth[k − delay]
    else:
        estimate, truth = truth[-delay : -delay + n], truth[:n]
    metrics = score(t, estimate, truth, 3)
    for lag in metrics.lag:
        assert lag == pytest.approx(delay * dt, abs=dt)


def test_delay_of_a_dp_move_is_not_biased_to_zero() -> None:
    dt, n, delay = 0.1, 9000, 30
    t = np.arange(n + delay) * dt
    move = 20.0 * np.clip((t - 300.0) / 200.0, 0.0, 1.0) + np.sin(0.03 * t)
    truth = np.zeros((n, 3))
    estimate = np.zeros((n, 3))
    truth[:, 0], estimate[:, 0] = move[delay:], move[:n]
    assert score(t[:n], estimate, truth, 1).lag[0] == pytest.approx(delay * dt, abs=dt)


def test_constant_offset_gives_exact_rmse_and_no_rate_error() -> None:
    dt, n = 0.5, 2000
    t = np.arange(n) * dt
    truth = _lf_series(2, n, dt)
    offset = np.array([0.3, -1.5, 0.02])
    metrics = score(t, truth + offset, truth, 3)
    np.testing.assert_allclose(metrics.rmse, np.abs(offset), rtol=1e-12)
    np.testing.assert_allclose(metrics.derivative_rmse, 0.0, atol=1e-12)
    np.testing.assert_allclose(metrics.lag, 0.0, atol=1e-3)  # [s], dt = 0.5 s
    np.testing.assert_allclose(metrics.wave_band_power, 0.0, atol=1e-20)


def test_yaw_error_is_wrapped() -> None:
    dt, n = 0.1, 1000
    t = np.arange(n) * dt
    truth = np.zeros((n, 3))
    truth[:, 2] = np.angle(np.exp(1j * (np.pi - 0.2 + 0.4 * t / t[-1])))  # crosses ±π
    estimate = truth.copy()
    estimate[:, 2] = np.angle(np.exp(1j * (truth[:, 2] + 0.1)))
    metrics = score(t, estimate, truth, 3)
    assert metrics.rmse[2] == pytest.approx(0.1, rel=1e-9)
    assert metrics.derivative_rmse[2] == pytest.approx(0.0, abs=1e-9)


def test_band_rms_counts_the_mean_only_in_a_band_from_zero() -> None:
    """A 0.3 m offset plus a 0.2 m sine at 0.8 rad/s: RMS 0.3 in (0, 0.1), 0.2/√2 in (0.3, 1.3)."""
    t = np.arange(12000) * 0.1
    x = 0.3 + 0.2 * np.sin(0.8 * t)
    assert band_rms(x, 0.1, (0.0, 0.1)) == pytest.approx(0.3, rel=0.01)
    assert band_rms(x, 0.1, (0.3, 1.3)) == pytest.approx(0.2 / math.sqrt(2), rel=0.02)


def test_wave_band_power_of_a_sinusoidal_error() -> None:
    dt, n = 0.1, 12000
    t = np.arange(n) * dt
    truth = _lf_series(3, n, dt)
    estimate = truth.copy()
    estimate[:, 0] += 0.2 * np.sin(0.8 * t)  # in band: power 0.2²/2 = 0.02 m²
    estimate[:, 1] += 0.2 * np.sin(0.05 * t)  # below the band
    estimate[:, 2] += 0.2 * np.sin(2.5 * t)  # above the band
    metrics = score(t, estimate, truth, 3, wave_band=(0.3, 1.3))
    assert metrics.wave_band_power[0] == pytest.approx(0.02, rel=0.03)
    assert metrics.wave_band_power[1] < 1e-4 * 0.02
    assert metrics.wave_band_power[2] < 1e-4 * 0.02


def test_derivative_rmse_of_a_sinusoidal_error() -> None:
    dt, n = 0.1, 6283  # ≈ 50 periods of 0.5 rad/s (2π/0.5 = 12.57 s)
    t = np.arange(n) * dt
    truth = _lf_series(4, n, dt)
    estimate = truth.copy()
    amplitude, omega = 0.1, 0.5  # [m], [rad/s]
    estimate[:, 0] += amplitude * np.sin(omega * t)
    # Finite difference of A sin(ωt): amplitude A·2 sin(ωT/2)/T, RMS /√2.
    expected = amplitude * 2.0 * np.sin(omega * dt / 2.0) / dt / np.sqrt(2.0)
    metrics = score(t, estimate, truth, 1)
    assert metrics.derivative_rmse[0] == pytest.approx(expected, rel=5e-3)
    assert metrics.rmse[0] == pytest.approx(amplitude / np.sqrt(2.0), rel=5e-3)


class _Echo:
    """Minimal LfEstimator returning the measured pose plus t in yaw (to check alignment)."""

    ndof = 3
    sample_time = 0.1

    def update(self, t: float, pose: FloatArray, force: FloatArray) -> FloatArray:
        return np.array([pose[0], force[0], t])

    def reset(self) -> None:
        """Nothing to reset."""

    def status(self) -> EstimatorStatus:
        return EstimatorStatus(state='ok')


def test_run_estimator_aligns_and_shifts() -> None:
    n = 5
    t = np.arange(n) * 0.1
    pose = np.column_stack([np.arange(n, dtype=float), np.zeros(n), np.zeros(n)])
    force = np.column_stack([10.0 * np.arange(n), np.zeros(n), np.zeros(n)])
    out = run_estimator(_Echo(), t, pose, force)
    np.testing.assert_array_equal(out[:, 0], np.arange(n))
    np.testing.assert_array_equal(out[:, 1], 10.0 * np.arange(n))
    ahead = run_estimator(_Echo(), t, pose, force, steps_ahead=1)
    np.testing.assert_array_equal(ahead[:, 0], [0.0, 0.0, 1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match='shape'):
        run_estimator(_Echo(), t, pose[:3], force)


def test_largest_step_ratio_of_a_ramp_with_one_jump_and_across_the_heading_wrap() -> None:
    """Truth ramps 0.1 / sample (north), 0.02 rad / sample across ±π (yaw), east holds.

    The estimate follows with one 0.5 m jump in north (a step of 0.6 m: ratio 6), its heading
    wrapped as the truth's (no jump: ratio 1); east: an estimate that moves 0.01 m once against a
    truth that never moves is inf, one that never moves either 0.
    """
    n = 200
    t = np.arange(n, dtype=np.float64)
    truth = np.zeros((n, 3))
    truth[:, 0] = 0.1 * t
    truth[:, 2] = np.angle(np.exp(1j * (np.pi - 2.0 + 0.02 * t)))  # crosses ±π near k = 100
    estimate = truth.copy()
    estimate[120:, 0] += 0.5
    estimate[50:, 1] += 0.01
    metrics = score(t, estimate, truth, 3)
    assert metrics.largest_step_ratio[0] == pytest.approx(6.0, rel=1e-9)
    assert metrics.largest_step_ratio[1] == math.inf
    assert metrics.largest_step_ratio[2] == pytest.approx(1.0, rel=1e-9)
    assert score(t, truth, truth, 3).largest_step_ratio[1] == 0.0
    assert json.loads(json.dumps(metrics.to_dict()))['north']['largest_step_ratio'] == \
        pytest.approx(6.0, rel=1e-9)


def test_to_dict_is_json_and_table_is_aligned() -> None:
    metrics = Metrics(ndof=3, samples=100, rmse=(0.1, 0.25, 0.004),
                      derivative_rmse=(0.01, 0.02, 0.001), wave_band_power=(1e-3, 2e-3, 1e-6),
                      lag=(4.2, -0.1, 1.0))
    data = json.loads(json.dumps(metrics.to_dict()))
    assert data['east']['rmse'] == 0.25
    assert data['yaw']['lag'] == 1.0
    table = format_table({'cascade': metrics, 'observer (true model)': Metrics(
        ndof=1, samples=100, rmse=(0.12,), derivative_rmse=(0.3,), wave_band_power=(0.5,),
        lag=(12.25,))})
    lines = table.splitlines()
    assert len(lines) == 2 + 3 + 1
    assert lines[0].startswith('estimator')
    assert set(lines[1]) == {'-'}
    # Every numeric column right-aligned: the lag column ends at the same position.
    assert len({len(line) for line in lines}) == 1
    assert lines[-1].split() == ['observer', '(true', 'model)', 'north', '0.12', '0.3',
                                 '5.000e-01', '12.25']


def test_score_rejects_bad_input() -> None:
    t = np.arange(10) * 0.1
    with pytest.raises(ValueError, match='increasing'):
        score(t[::-1], np.zeros((10, 3)), np.zeros((10, 3)), 3)
    with pytest.raises(ValueError, match='ndof'):
        score(t, np.zeros((10, 3)), np.zeros((10, 3)), 2)
    with pytest.raises(ValueError, match='wave_band'):
        score(t, np.zeros((10, 3)), np.zeros((10, 3)), 3, wave_band=(1.3, 0.3))


def test_loop_metrics_of_a_synthetic_loop() -> None:
    """3 m north + 4 m east off the setpoint: 5 m; yaw ±0.1 rad across ±π; A = 2 N thrust line."""
    n = 4000
    t = np.arange(n, dtype=np.float64)
    setpoint = (10.0, -2.0, math.pi - 0.05)
    pose = np.column_stack([np.full(n, 13.0), np.full(n, 2.0),
                            np.where(np.arange(n) % 2 == 0, -math.pi + 0.05, math.pi - 0.15)])
    thrust = np.column_stack([2.0 * np.sin(0.8 * t), t, np.full(n, 7.0)])
    pose[:1000] = 1e3  # before the warm-up: ignored
    out = loop_metrics(LoopRun(t, pose, thrust), 3, setpoint, (0.3, 1.3), start=1000.0)
    assert out['samples'] == 3000
    assert out['position_rmse'] == pytest.approx(5.0, rel=1e-12)
    assert out['max_excursion'] == pytest.approx(5.0, rel=1e-12)
    assert out['heading_rmse'] == pytest.approx(0.1, rel=1e-9)
    power = out['thrust_wave_band_power']
    assert power['north'] == pytest.approx(2.0, rel=0.05)  # A²/2
    assert power['yaw'] == 0.0
    variation = out['thrust_total_variation']
    assert variation['east'] == pytest.approx(2999.0) and variation['yaw'] == 0.0
    one = loop_metrics(LoopRun(t, pose, thrust), 1, setpoint, (0.3, 1.3), start=1000.0)
    assert one['position_rmse'] == pytest.approx(3.0) and 'heading_rmse' not in one
    assert set(one['thrust_total_variation']) == {'north'}
