"""The oracle Kalman filter on short seeded simulator runs (it must beat raw and the observer)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from lf_predictor_ros.benchmark.oracle import (
    RAO_WAVE_DAMPING,
    make_oracle,
    oracle_model,
    rao_wave_sigma,
)
from lf_predictor_ros.core.alignment import block_mean_poses
from lf_predictor_ros.core.baselines.kalman import unit_wave_filter
from lf_predictor_ros.core.baselines.observer import PassiveObserver
from sim_ros.physics.vessels import GRAVITY, SUPPLY_LENGTH
from sim_ros.physics.waves import make_filter
from sim_ros.simulation import load_scenario, simulate

WARMUP = 200.0  # s, scored after


def _grid(name: str, seed: int, duration: float) -> tuple[object, dict[str, np.ndarray]]:
    scenario = load_scenario(name)
    record = simulate(scenario, seed=seed, duration=duration)
    stride = int(round(max(1.0, scenario.sample_time) / scenario.sample_time))
    sl = slice(stride - 1, None, stride)
    return scenario, {'t': record.t[sl], 'y': block_mean_poses(record.measured_pose, stride),
                      'u': record.thrust[sl], 'truth': record.truth_lf_pose[sl]}


def _rmse(estimator: object, data: dict[str, np.ndarray], ndof: int) -> np.ndarray:
    out = np.array([estimator.update(float(t), y, u)  # type: ignore[attr-defined]
                    for t, y, u in zip(data['t'], data['y'], data['u'], strict=True)])
    keep = data['t'] >= WARMUP
    err = out[keep] - data['truth'][keep]
    err[:, 2] = np.remainder(err[:, 2] + np.pi, 2 * np.pi) - np.pi
    return np.sqrt(np.mean(err**2, axis=0))[:ndof]


def _observer(scenario: object, ndof: int) -> PassiveObserver:
    from sim_ros.simulation import Simulator

    model = Simulator(scenario, 0).true_model()  # type: ignore[arg-type]
    k4 = 0.1 * np.diag(model.mass) * GRAVITY / SUPPLY_LENGTH
    k3 = 0.1 * np.sqrt(GRAVITY / SUPPLY_LENGTH) * k4
    mass = model.mass[:ndof, :ndof] if ndof == 3 else float(model.mass[0, 0])
    damping = model.damping[:ndof, :ndof] if ndof == 3 else float(model.damping[0, 0])
    return PassiveObserver(ndof, 1.0, 0.8, mass, damping, k3=k3[:ndof], k4=k4[:ndof])


def test_supply_closed_loop_beats_raw_and_observer() -> None:
    scenario, data = _grid('supply_closed_loop', 2, 500.0)
    oracle = _rmse(make_oracle(scenario, 1.0), data, 3)  # type: ignore[arg-type]
    raw = np.sqrt(np.mean((data['y'] - data['truth'])[data['t'] >= WARMUP] ** 2, axis=0))
    observer = _rmse(_observer(scenario, 3), data, 3)
    # measured: 0.080 / 0.065 m / 0.0014 rad over 1800 s (seeds 2, 3); issue: 0.080–0.083
    assert oracle[0] == pytest.approx(0.08, abs=0.03)
    assert oracle[1] == pytest.approx(0.065, abs=0.03)
    assert oracle[2] == pytest.approx(0.0014, abs=0.0006)
    assert np.all(oracle < 0.5 * raw) and np.all(oracle < observer)


def test_onedof_reference_open_loop_beats_raw_and_observer() -> None:
    scenario, data = _grid('onedof_reference', 2, 600.0)
    oracle = _rmse(make_oracle(scenario, 1.0), data, 1)  # type: ignore[arg-type]
    observer = _rmse(_observer(scenario, 1), data, 1)
    raw = np.sqrt(np.mean((data['y'] - data['truth'])[data['t'] >= WARMUP, 0] ** 2))
    assert oracle[0] < 0.02  # measured 0.001–0.004 m; issue ≈ 0.01 m
    assert oracle[0] < 0.1 * raw and oracle[0] < observer[0]


def test_unsupported_wave_model_raises() -> None:
    scenario = load_scenario('onedof_reference')
    waves = dataclasses.replace(scenario.waves)
    object.__setattr__(waves, 'model', 'tabulated')  # bypass the simulator's own validation
    broken = dataclasses.replace(scenario)
    object.__setattr__(broken, 'waves', waves)
    with pytest.raises(ValueError, match='oracle'):
        oracle_model(broken, 1.0)


def test_rao_sea_gets_the_fitted_second_order_wave_model() -> None:
    """σ² λ ω_p equals the sea's earth-frame WF variance averaged over the scheduled headings."""
    scenario = load_scenario('rao_supply')
    sigma = rao_wave_sigma(scenario)
    model = oracle_model(scenario, 1.0)
    assert model.wave_model == 'motion' and model.wave_sigma == pytest.approx(sigma)
    omega_p = float(scenario.waves.peak_freq(0.0))
    variance = np.array(sigma) ** 2 * RAO_WAVE_DAMPING * omega_p
    # WF std 0.41 / 0.31 m and ≈ 0.8° over the run (the scenario header's measurement)
    assert np.sqrt(variance[:2]) == pytest.approx([0.41, 0.31], rel=0.35)
    assert math.degrees(math.sqrt(variance[2])) == pytest.approx(0.8, rel=0.5)


def test_sample_time_must_be_a_multiple_of_the_sensor_period() -> None:
    with pytest.raises(ValueError, match='whole multiple'):
        oracle_model(load_scenario('supply_closed_loop'), 0.25)


@pytest.mark.parametrize('model', ['force', 'motion'])
@pytest.mark.parametrize(('peak_freq', 'damping'), [(0.3, 0.1), (0.8, 0.05), (1.25, 0.3)])
def test_the_oracle_wave_filter_is_the_simulator_s(model: str, peak_freq: float,
                                                   damping: float) -> None:
    """core/baselines/kalman.py keeps its own copy (the core must not import sim_ros): same."""
    a, g, c, c_int = unit_wave_filter(model, peak_freq, damping)
    sim = make_filter(model, peak_freq, damping, 1.0)
    np.testing.assert_array_equal(a, sim.a)
    np.testing.assert_array_equal(g, sim.g)
    np.testing.assert_array_equal(c, sim.c.reshape(-1))
    np.testing.assert_array_equal(c_int, sim.c_integrals)
