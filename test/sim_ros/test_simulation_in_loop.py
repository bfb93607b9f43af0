"""`simulate_in_loop`: the scenario's PID fed by an estimator callback (zero-order hold)."""
from __future__ import annotations

from dataclasses import replace
import math

import numpy as np
from numpy.typing import NDArray
import pytest

from sim_ros.control.pid import PidState, pid_step
from sim_ros.simulation import (
    SimRecord,
    Simulator,
    WaveConfig,
    controller_gains,
    load_scenario,
    simulate,
    simulate_in_loop,
)

FloatArray = NDArray[np.float64]
FIELDS = ('t', 'measured_pose', 'measured_valid', 'truth_pose', 'truth_lf_pose', 'thrust',
          'thrust_command', 'wave_peak_freq')


def _measurement(t: float, pose: FloatArray, thrust: FloatArray) -> FloatArray:
    return pose


def _assert_same(a: SimRecord, b: SimRecord) -> None:
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


@pytest.mark.parametrize(('name', 'duration'), [('supply_closed_loop', 120.0),
                                                 ('onedof_feedback', 300.0)])
def test_measurement_fed_back_every_sample_is_simulate_measured(name: str,
                                                                duration: float) -> None:
    """With period = sample_time, estimate = measurement is simulate(measured), bit for bit."""
    scn = load_scenario(name)
    run = simulate_in_loop(scn, 3, duration, _measurement, scn.sample_time)
    _assert_same(run.record, simulate(scn, seed=3, duration=duration, feedback='measured'))
    n = int(round(duration / scn.sample_time))
    assert run.estimate_t.shape == (n,) and run.estimates.shape == (n, 3)
    assert run.nonfinite_estimates == 0 and run.aborted_at is None


def test_estimate_at_the_setpoint_gives_zero_pid_force() -> None:
    """A constant estimate equal to the setpoint: PID output 0, i.e. the open-loop run."""
    scn = load_scenario('supply_closed_loop')
    setpoint = np.asarray(scn.controller.setpoint, dtype=np.float64)

    def at_setpoint(t: float, pose: FloatArray, thrust: FloatArray) -> FloatArray:
        return setpoint.copy()

    # before the first call the PID sees the first measurement; start the vessel there
    scn = replace(scn, waves=WaveConfig(), initial_pose=(0.0, 0.0, 0.0))
    run = simulate_in_loop(scn, 4, 60.0, at_setpoint, 1.0)
    _assert_same(run.record, simulate(scn, seed=4, duration=60.0, controller=False))
    np.testing.assert_array_equal(run.record.thrust_command, 0.0)


def test_constant_estimate_gives_the_analytic_pid_command() -> None:
    """1 DOF, constant estimate c, setpoint s: the PID law in closed form (no saturation).

    The reference filter starts at c: η_d,k = s + (c − s)(1 − α)^(k+1), α = 1 − e^(−dt/T_f);
    e_k = c − η_d,k; the velocity estimate stays 0, so τ_k = −(Kp e_k + Ki dt Σ_{j<k} e_j).
    """
    c, dt = 1.5, 1.0  # m, s
    base = load_scenario('onedof_feedback')
    scn = replace(base, waves=WaveConfig(), initial_pose=(c, 0.0, 0.0))  # 1st measurement: c
    run = simulate_in_loop(scn, 2, 200.0, lambda t, y, u: np.array([c, 0.0, 0.0]), dt)
    gains = controller_gains(scn, Simulator(scn, 2).true_model())
    alpha = 1.0 - math.exp(-dt / scn.controller.setpoint_filter_time)
    k = np.arange(200)
    error = (c - 0.0) * (1.0 - (1.0 - alpha) ** (k + 1))
    integral = np.concatenate([[0.0], np.cumsum(error)[:-1]]) * dt
    expected = -(gains.kp[0] * error + gains.ki[0] * integral)
    assert np.max(np.abs(expected)) < 50.0  # below the 50 N actuator limit: no saturation
    np.testing.assert_allclose(run.record.thrust_command[:, 0], expected, rtol=1e-12,
                               atol=1e-12)
    np.testing.assert_array_equal(run.record.thrust_command[:, 1:], 0.0)
    assert error[-1] == pytest.approx(c, rel=1e-8)  # 20 T_f later the reference reached s


def test_estimator_is_called_every_period_and_held_in_between() -> None:
    """10 Hz simulator, 1 s estimator: calls at 1, 2, … s with that sample; the PID holds it."""
    scn = load_scenario('supply_closed_loop')
    calls: list[tuple[float, FloatArray, FloatArray]] = []

    def recording(t: float, pose: FloatArray, thrust: FloatArray) -> FloatArray:
        calls.append((t, pose.copy(), thrust.copy()))
        return np.asarray(pose + [0.3, -0.2, 0.01], dtype=np.float64)  # biased: the hold matters

    run = simulate_in_loop(scn, 5, 30.0, recording, 1.0)
    rec = run.record
    assert rec.t.size == 300 and len(calls) == 30
    np.testing.assert_allclose([c[0] for c in calls], np.arange(1, 31) * 1.0, rtol=1e-12)
    np.testing.assert_array_equal(np.array([c[1] for c in calls]), rec.measured_pose[9::10])
    np.testing.assert_array_equal(np.array([c[2] for c in calls]), rec.thrust[9::10])
    np.testing.assert_array_equal(run.estimates, rec.measured_pose[9::10] + [0.3, -0.2, 0.01])
    # replay the PID on the held pose sequence: the commands must be those of the run
    sim = Simulator(scn, 5)
    gains = controller_gains(scn, sim.true_model())
    limit = scn.controller.tau_max or sim.actuator_limit()
    held = sim.sample.measured_pose.copy()
    state = PidState()
    for k in range(rec.t.size):
        tau, state = pid_step(state, gains, held, np.zeros(3), scn.sample_time, limit)
        np.testing.assert_array_equal(rec.thrust_command[k], tau)
        if (k + 1) % 10 == 0:
            held = run.estimates[k // 10]


def test_nonfinite_estimate_holds_the_last_finite_one_and_is_counted() -> None:
    """Every third estimate NaN: same run as returning the previous finite estimate."""
    scn = load_scenario('onedof_feedback')
    last: list[FloatArray] = []

    def flaky(t: float, pose: FloatArray, thrust: FloatArray) -> FloatArray:
        if int(round(t)) % 3 == 0:
            return np.array([math.nan, 0.0, 0.0])
        return pose

    def holding(t: float, pose: FloatArray, thrust: FloatArray) -> FloatArray:
        if int(round(t)) % 3 == 0 and last:
            return last[-1]
        last.append(pose.copy())
        return pose

    a = simulate_in_loop(scn, 6, 120.0, flaky, 1.0)
    b = simulate_in_loop(scn, 6, 120.0, holding, 1.0)
    assert a.nonfinite_estimates == 40 and b.nonfinite_estimates == 0
    _assert_same(a.record, b.record)
    assert np.isnan(a.estimates[2, 0]) and np.isfinite(a.estimates[1, 0])


def test_callback_cannot_corrupt_the_run_and_runs_repeat() -> None:
    """The callback gets copies (scribbling on them changes nothing); same seed, same run."""
    scn = load_scenario('supply_closed_loop')

    def vandal(t: float, pose: FloatArray, thrust: FloatArray) -> FloatArray:
        out = pose.copy()
        pose[:] = 1e6
        thrust[:] = -1e9
        return out

    a = simulate_in_loop(scn, 7, 20.0, vandal, 1.0)
    b = simulate_in_loop(scn, 7, 20.0, _measurement, 1.0)
    _assert_same(a.record, b.record)
    _assert_same(b.record, simulate_in_loop(scn, 7, 20.0, _measurement, 1.0).record)
    assert not np.array_equal(b.record.measured_pose,
                              simulate_in_loop(scn, 8, 20.0, _measurement, 1.0)
                              .record.measured_pose)


def test_diverging_loop_is_aborted_at_the_excursion_limit() -> None:
    """An estimate stuck 30 m east: the PID pushes the vessel west until it leaves 5 m."""
    scn = load_scenario('supply_closed_loop')
    run = simulate_in_loop(scn, 1, 600.0, lambda t, y, u: np.array([0.0, 30.0, 0.0]), 1.0,
                           abort_excursion=5.0)
    assert run.aborted_at is not None and run.aborted_at < 600.0
    lf = run.record.truth_lf_pose
    assert run.record.t[-1] == run.aborted_at
    assert math.hypot(lf[-1, 0], lf[-1, 1]) > 5.0
    assert np.all(np.hypot(lf[:-1, 0], lf[:-1, 1]) <= 5.0)
    assert lf[-1, 1] < 0.0  # pushed west, away from the phantom offset


@pytest.mark.parametrize('period', [0.0, 0.25, -1.0])
def test_period_must_be_a_multiple_of_the_sample_time(period: float) -> None:
    with pytest.raises(ValueError, match='integer multiple'):
        simulate_in_loop(load_scenario('supply_closed_loop'), 1, 10.0, _measurement, period)


def test_wrong_estimate_shape_is_rejected() -> None:
    with pytest.raises(ValueError, match=r'\(3,\) pose'):
        simulate_in_loop(load_scenario('onedof_feedback'), 1, 10.0,
                         lambda t, y, u: np.zeros(2), 1.0)


def test_pid_once_per_estimate_holds_the_command() -> None:
    """pid_period = period (the DDS pipeline): one PID step per second, dt = 1 s, command held."""
    scn = load_scenario('supply_closed_loop')
    run = simulate_in_loop(scn, 5, 30.0, _measurement, 1.0, pid_period=1.0)
    rec = run.record
    blocks = rec.thrust_command.reshape(30, 10, 3)
    np.testing.assert_array_equal(blocks, np.repeat(blocks[:, :1], 10, axis=1))
    sim = Simulator(scn, 5)
    gains = controller_gains(scn, sim.true_model())
    limit = scn.controller.tau_max or sim.actuator_limit()
    poses = [sim.sample.measured_pose, *rec.measured_pose[9:-1:10]]
    state = PidState()
    for j, pose in enumerate(poses):
        tau, state = pid_step(state, gains, pose, np.zeros(3), 1.0, limit)
        np.testing.assert_array_equal(blocks[j, 0], tau)
    assert not np.array_equal(rec.thrust_command,
                              simulate_in_loop(scn, 5, 30.0, _measurement, 1.0).record
                              .thrust_command)


def test_velocity_hook_off_or_empty_is_bit_identical() -> None:
    """A hook that never has a velocity (None) runs exactly the loop without the hook."""
    scn = load_scenario('supply_closed_loop')
    calls: list[float] = []

    def no_velocity() -> None:
        calls.append(1.0)

    plain = simulate_in_loop(scn, 5, 30.0, _measurement, 1.0, pid_period=1.0)
    hooked = simulate_in_loop(scn, 5, 30.0, _measurement, 1.0, pid_period=1.0,
                              velocity=no_velocity)
    off = simulate_in_loop(scn, 5, 30.0, _measurement, 1.0, pid_period=1.0, velocity=None)
    _assert_same(plain.record, hooked.record)
    _assert_same(plain.record, off.record)
    np.testing.assert_array_equal(plain.estimates, hooked.estimates)
    assert len(calls) == 30 and hooked.missing_velocities == 30  # one per finite estimate
    assert plain.missing_velocities == off.missing_velocities == 0


def test_velocity_hook_sets_the_d_term_to_minus_kd_nu() -> None:
    """Estimate = setpoint = start, no waves: P = I = 0 and the difference is 0, so τ = −Kd ν.

    The estimator is called at 1, 2, … s; the PID runs every 0.1 s on the held estimate and
    velocity: 0 before the first call (no velocity yet: finite difference of a constant = 0),
    −Kd ν after; every third velocity is NaN (not used: τ = 0 until the next valid one).
    """
    base = load_scenario('supply_closed_loop')
    scn = replace(base, waves=WaveConfig(), initial_pose=(0.0, 0.0, 0.0))
    setpoint = np.asarray(scn.controller.setpoint, dtype=np.float64)
    np.testing.assert_array_equal(setpoint, 0.0)
    nu = np.array([0.02, -0.01, 0.0005])  # [m/s, m/s, rad/s]
    count = [0]

    def velocity() -> FloatArray:
        count[0] += 1
        return np.full(3, math.nan) if count[0] % 3 == 0 else nu

    run = simulate_in_loop(scn, 4, 30.0, lambda t, y, u: setpoint.copy(), 1.0,
                           velocity=velocity)
    gains = controller_gains(scn, Simulator(scn, 4).true_model())
    expected = np.zeros((300, 3))
    for call in range(1, 31):  # call c at t = c s: held for PID steps 10c .. 10c + 9
        if call % 3 != 0:
            expected[10 * call:10 * call + 10] = -gains.kd * nu
    limit = Simulator(scn, 4).actuator_limit()
    assert np.all(np.abs(gains.kd * nu) < limit)  # no saturation
    np.testing.assert_array_equal(run.record.thrust_command, expected)
    assert run.missing_velocities == 10


def test_velocity_hook_shape_is_checked() -> None:
    with pytest.raises(ValueError, match=r'\(3,\) body velocity'):
        simulate_in_loop(load_scenario('onedof_feedback'), 1, 10.0, _measurement, 1.0,
                         velocity=lambda: np.zeros(2))
