"""Fair recordings: provenance, the thrust-only leak check, and the truth-fed recording refused."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lf_predictor_ros.benchmark.estimators import StreamingEstimator
from lf_predictor_ros.benchmark.recordings import (
    LEAK_LAGS,
    LeakError,
    Provenance,
    Recording,
    check_scorable,
    decimate,
    leak_check,
    record,
    require_fair,
    run_loop,
    thrust_features,
    thrust_only_rmse,
)
from lf_predictor_ros.core.baselines.observer import PassiveObserver
from lf_predictor_ros.core.evaluation import score
from sim_ros.control.pid import PidState, pid_step
from sim_ros.physics.vessels import GRAVITY, SUPPLY_LENGTH
from sim_ros.simulation import Simulator, controller_gains, load_scenario, simulate

DURATION = 1200.0  # [s]
BEGIN = 300  # first scored grid sample


def _observer() -> StreamingEstimator:
    """The passive observer with the true supply model and the issue's retuned gains."""
    model = Simulator(load_scenario('supply_closed_loop'), 0).true_model()
    k4 = np.diag(model.mass) * GRAVITY / SUPPLY_LENGTH
    k3 = 0.1 * math.sqrt(GRAVITY / SUPPLY_LENGTH) * k4
    return StreamingEstimator(PassiveObserver(3, 1.0, 0.8, model.mass, model.damping, k3=k3,
                                              k4=k4, relative_damping=2.0, cutoff_ratio=1.01,
                                              bias_time=1e4), retune=True)


def _observer_rmse(rec: Recording) -> tuple[float, ...]:
    stream = _observer()
    out = np.array([stream.step(float(t), y, u, float(w))
                    for t, y, u, w in zip(rec.t, rec.y, rec.u, rec.omega, strict=True)])
    return score(rec.t[BEGIN:], out[BEGIN:], rec.truth[BEGIN:], 3).rmse


@pytest.fixture(scope='module')
def supply_recordings() -> dict[str, Recording]:
    scenario = load_scenario('supply_closed_loop')
    return {'truth': record(scenario, 5, DURATION, 1.0, None, truth_fed=True),
            'fair': record(scenario, 5, DURATION, 1.0, 'observer',
                           lambda name: _observer().step)}


def test_provenance_says_how_the_thrust_was_made(supply_recordings: dict[str, Recording]) -> None:
    truth, fair = supply_recordings['truth'], supply_recordings['fair']
    assert truth.provenance.loop == 'truth_lf' and truth.provenance.estimator is None
    assert fair.provenance == Provenance('supply_closed_loop', 5, DURATION, 1.0, 'estimator',
                                         'observer')
    assert fair.t.shape == (1200,) and fair.y.shape == (1200, 3)
    open_loop = record(load_scenario('onedof_reference'), 5, 600.0, 1.0, None)
    assert open_loop.provenance.loop == 'open'
    check_scorable(fair, 'supply_closed_loop', 5)
    check_scorable(open_loop)
    with pytest.raises(LeakError, match='true LF pose'):
        check_scorable(truth)
    with pytest.raises(LeakError, match='seed'):
        check_scorable(fair, seed=6)
    with pytest.raises(ValueError, match='must name its estimator'):
        Provenance('x', 1, 1.0, 1.0, 'estimator')


def test_a_controlled_scenario_needs_a_loop_estimator() -> None:
    with pytest.raises(ValueError, match='name the causal estimator'):
        record(load_scenario('supply_closed_loop'), 5, 100.0, 1.0, None)


def test_leak_check_rejects_the_truth_fed_recording(supply_recordings: dict[str, Recording],
                                                    ) -> None:
    """Thrust alone ≈ truth when the PID saw the truth (ratio ≪ 1); ≈ the loop's estimator not."""
    truth, fair = supply_recordings['truth'], supply_recordings['fair']
    leaking = leak_check(truth, {'observer': _observer_rmse(truth)}, 3, BEGIN)
    assert leaking.leaking and max(leaking.ratios) < 0.2
    with pytest.raises(LeakError):
        require_fair(truth, leaking)
    # the data test alone (provenance forged as fair) still refuses it
    forged = Recording(fair.provenance, truth.t, truth.y, truth.u, truth.truth, truth.omega)
    with pytest.raises(LeakError, match='thrust alone'):
        require_fair(forged, leak_check(forged, {'observer': _observer_rmse(truth)}, 3, BEGIN))
    clean = leak_check(fair, {'observer': _observer_rmse(fair)}, 3, BEGIN)
    assert not clean.leaking and min(clean.ratios) > 0.5, clean.ratios
    require_fair(fair, clean)


def test_thrust_only_fit_recovers_a_thrust_linear_truth() -> None:
    """Truth = a first-order low-pass (T = 30 s) of the thrust: inside the features' span."""
    rng = np.random.default_rng(3)
    u = rng.standard_normal((2000, 3)) * [1e4, 1e4, 1e5]
    column = LEAK_LAGS * 3 + 2 * 3  # the T = 30 s low-pass of the first channel
    truth = 1e-4 * thrust_features(u, 1.0)[:, [column]].repeat(3, axis=1)
    truth[:, 2] *= 1e-3
    rmse = thrust_only_rmse(u, truth, 3, 1.0, begin=100)
    assert np.all(rmse < 1e-8 * np.std(truth, axis=0) + 1e-12)
    noise = rng.standard_normal((2000, 3))
    assert np.all(thrust_only_rmse(u, noise, 3, 1.0, 100) > 0.9)  # no information: std ≈ 1


def test_thrust_features_are_causal() -> None:
    u = np.zeros((50, 1))
    u[30] = 1.0
    features = thrust_features(u, 1.0)
    assert np.all(features[:30] == 0.0) and np.any(features[30] != 0.0)


def test_decimate_averages_the_poses_of_each_interval() -> None:
    rec = simulate(load_scenario('supply_closed_loop'), seed=2, duration=5.0)
    grid = decimate(rec, 10)
    assert grid['t'].tolist() == pytest.approx([1.0, 2.0, 3.0, 4.0, 5.0])
    assert grid['y'][0, 0] == pytest.approx(np.mean(rec.measured_pose[:10, 0]))
    assert np.array_equal(grid['u'][0], rec.thrust[9])
    assert np.allclose(grid['wave'][0], rec.truth_pose[9] - rec.truth_lf_pose[9], atol=1e-12)
    with pytest.raises(ValueError, match='stride'):
        decimate(rec, 0)


def test_run_loop_passes_the_estimators_velocity_to_the_pid() -> None:
    """run_loop on the observer, with and without its ν̂ as the PID's D term.

    Without the hook (or with ``velocity=None``) the run is bit for bit the default one. With
    ``velocity=lambda: observer.velocity`` every PID step (once per h = 1 s, dt = 1 s) is
    `pid_step` on the held estimate with ``velocity_body`` = the ν̂ read after that estimate:
    the commands are replayed exactly.
    """
    scenario = load_scenario('supply_closed_loop')
    default = run_loop(scenario, 5, 60.0, 1.0, _observer().step)
    off = run_loop(scenario, 5, 60.0, 1.0, _observer().step, velocity=None)
    for name in ('t', 'measured_pose', 'truth_lf_pose', 'thrust', 'thrust_command'):
        np.testing.assert_array_equal(getattr(default.record, name), getattr(off.record, name))
    stream = _observer()
    seen: list[np.ndarray] = []

    def velocity() -> np.ndarray:
        seen.append(np.array(stream.estimator.velocity))
        return seen[-1]

    run = run_loop(scenario, 5, 60.0, 1.0, stream.step, velocity=velocity)
    assert run.missing_velocities == 0 and run.aborted_at is None
    assert len(seen) == run.estimates.shape[0] == 600  # one read per sensor sample
    sim = Simulator(scenario, 5)
    gains = controller_gains(scenario, sim.true_model())
    limit = scenario.controller.tau_max or sim.actuator_limit()
    held, held_nu = sim.sample.measured_pose.copy(), None
    state = PidState()
    commands = run.record.thrust_command
    for k in range(0, 600, 10):
        if k > 0:
            held, held_nu = run.estimates[k - 1], seen[k - 1]
        tau, state = pid_step(state, gains, held, np.zeros(3), 1.0, limit, held_nu)
        np.testing.assert_array_equal(commands[k:k + 10], np.repeat(tau[None], 10, axis=0))
    assert np.max(np.abs(commands - default.record.thrust_command)) > 1e3  # [N] the D term moved
