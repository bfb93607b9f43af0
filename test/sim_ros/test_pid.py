"""DP controller law (MSS PIDnonlinearMIMO.m).

Gains, purity, heading wrapping, D-term, anti-windup, and closed-loop settling without
steady-state error on all three vessels.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from sim_ros.control.pid import PidGains, PidState, gains_from_bandwidth, pid_step
from sim_ros.physics import vessels
from sim_ros.physics.environment import EnvironmentConfig, MarkovBias
from sim_ros.simulation import ControllerConfig, Scenario, simulate


def test_gains_from_bandwidth_numbers() -> None:
    """Kp = M ω², Kd = 2ζωM − D, Ki = ω/10 Kp."""
    gains = gains_from_bandwidth([6.7644e6, 1.1341e7, 4.4524e9], [0.1, 0.1, 0.2], 1.0)
    np.testing.assert_allclose(gains.kp, [6.7644e4, 1.1341e5, 1.780960e8])
    np.testing.assert_allclose(gains.kd, [1.35288e6, 2.2682e6, 1.780960e9])
    np.testing.assert_allclose(gains.ki, [6.7644e2, 1.1341e3, 3.561920e6])
    with_d = gains_from_bandwidth([100.0] * 3, 0.5, 0.7, damping_diag=[10.0, 0.0, 200.0])
    np.testing.assert_allclose(with_d.kd, [60.0, 70.0, 0.0])
    with pytest.raises(ValueError, match='bandwidth'):
        gains_from_bandwidth([1.0, 1.0, 1.0], 0.0)


def test_pure_and_zero_at_setpoint() -> None:
    """Inputs are not modified; at the setpoint and at rest the command is zero."""
    gains = gains_from_bandwidth([1e6] * 3, 0.1)
    pose = np.array([1.0, 2.0, 0.3])
    before = pose.copy()
    state = PidState()
    tau, new = pid_step(state, gains, pose, pose.copy(), 0.1)
    np.testing.assert_array_equal(pose, before)
    assert state.initialized is False and new.initialized is True
    np.testing.assert_allclose(tau, 0.0, atol=1e-12)


def test_heading_error_wrapped_across_pi() -> None:
    """ψ = π − 0.01, ψ_ref = −π + 0.01: the reference moves the short way.

    The filtered reference moves by +α·0.02 rad (α = 1 − e^{−h/T_f}) across π, and the yaw
    command is +Kp α 0.02, not a full turn the other way.
    """
    gains = gains_from_bandwidth([1e6, 1e6, 1e8], 0.1)
    pose = np.array([0.0, 0.0, math.pi - 0.01])
    tau, state = pid_step(PidState(), gains, pose, np.array([0.0, 0.0, -math.pi + 0.01]), 0.1)
    alpha = 1 - math.exp(-0.1 / 10.0)
    assert tau[2] == pytest.approx(gains.kp[2] * alpha * 0.02, rel=1e-6)
    assert state.setpoint_filtered[2] == pytest.approx(math.pi - 0.01 + 0.02 * alpha, abs=1e-12)


def test_derivative_term_from_filtered_finite_difference() -> None:
    """Poses moving north at 0.5 m/s with ψ = 90°: ν = Rᵀη̇ = (0, −0.5, 0), τ = −Kd ν."""
    gains = PidGains(np.zeros(3), np.zeros(3), np.array([10.0, 20.0, 30.0]),
                     velocity_filter_time=1.0)
    state = PidState()
    tau = np.zeros(3)
    for k in range(200):
        pose = np.array([0.05 * k, 0.0, math.pi / 2])
        tau, state = pid_step(state, gains, pose, pose, 0.1)
    np.testing.assert_allclose(tau, [0.0, 20.0 * 0.5, 0.0], atol=1e-6)


def test_measured_body_velocity_replaces_the_finite_difference_in_the_d_term() -> None:
    """Kp = Ki = 0, poses moving north at 0.5 m/s: with ν given, τ = −Kd ν exactly.

    The finite difference would give ν = (0.5, 0, 0) (ψ = 0); the measured ν = (0.2, −0.1, 0.01)
    wins, every step, and the state (filter, integral, last pose) is the one without it.
    """
    gains = PidGains(np.zeros(3), np.zeros(3), np.array([10.0, 20.0, 30.0]))
    nu = np.array([0.2, -0.1, 0.01])
    nu_before = nu.copy()
    with_nu, without = PidState(), PidState()
    for k in range(50):
        pose = np.array([0.05 * k, 0.0, 0.0])
        tau, with_nu = pid_step(with_nu, gains, pose, pose, 0.1, velocity_body=nu)
        np.testing.assert_array_equal(tau, [-2.0, 2.0, -0.3])  # −Kd ν, to the last bit
        tau_fd, without = pid_step(without, gains, pose, pose, 0.1)
        for name in ('setpoint_filtered', 'integral', 'last_pose', 'velocity_earth'):
            np.testing.assert_array_equal(getattr(with_nu, name), getattr(without, name))
    np.testing.assert_allclose(tau_fd, [-10.0 * 0.5, 0.0, 0.0], rtol=1e-2)  # FD ≈ 0.5 m/s
    np.testing.assert_array_equal(nu, nu_before)  # input not modified


def test_measured_velocity_with_full_pid_adds_exactly_the_d_term_difference() -> None:
    """Full gains, heading 120°, off the setpoint: τ(ν) − τ(None) = −Kd (ν − ν_fd).

    First step: the finite-difference velocity is 0 (state starts at the pose), so
    τ(ν) = τ(None) − Kd ν; passing None is bit for bit the call without the argument.
    """
    gains = gains_from_bandwidth([6.7644e6, 1.1341e7, 4.4524e9], [0.1, 0.1, 0.2], 1.0)
    pose = np.array([3.0, -2.0, 2.0 * math.pi / 3])
    setpoint = np.array([0.0, 1.0, 0.5])
    nu = np.array([0.3, -0.2, 0.004])
    plain, state_plain = pid_step(PidState(), gains, pose, setpoint, 0.1)
    none, state_none = pid_step(PidState(), gains, pose, setpoint, 0.1, None, None)
    np.testing.assert_array_equal(plain, none)
    measured, state_measured = pid_step(PidState(), gains, pose, setpoint, 0.1,
                                        velocity_body=nu)
    np.testing.assert_allclose(measured - plain, -gains.kd * nu, rtol=1e-12)
    for name in ('setpoint_filtered', 'integral', 'last_pose', 'velocity_earth'):
        np.testing.assert_array_equal(getattr(state_measured, name), getattr(state_plain, name))
        np.testing.assert_array_equal(getattr(state_none, name), getattr(state_plain, name))


@pytest.mark.parametrize('velocity', [[0.1, 0.2], [0.0, math.nan, 0.0], [[0.0, 0.0, 0.0]]])
def test_bad_measured_velocity_is_rejected(velocity: list[float]) -> None:
    gains = gains_from_bandwidth([1e6] * 3, 0.1)
    with pytest.raises(ValueError, match=r'velocity_body must be a finite \(3,\) array'):
        pid_step(PidState(), gains, np.zeros(3), np.zeros(3), 0.1, velocity_body=velocity)


def test_anti_windup_stops_integration_when_saturated() -> None:
    """A large error saturates τ at τ_max; the integral must not grow."""
    gains = gains_from_bandwidth([1e6] * 3, 0.1)
    state = PidState()
    for _ in range(100):
        tau, state = pid_step(state, gains, np.array([100.0, 0.0, 0.0]), np.zeros(3), 0.1,
                              tau_max=[1e3, 1e3, 1e3])
    np.testing.assert_allclose(tau[0], -1e3)
    np.testing.assert_array_equal(state.integral, 0.0)
    # without a limit the same first step integrates e·dt, e = 100 α (reference filter moved)
    _, free = pid_step(PidState(), gains, np.array([100.0, 0.0, 0.0]), np.zeros(3), 0.1)
    alpha = 1 - math.exp(-0.1 / 10.0)
    assert free.integral[0] == pytest.approx(100.0 * alpha * 0.1, rel=1e-12)


def _settling_time(bandwidth: float, amplitude: float, tol: float) -> float:
    """t_s = ln(3 A / tol) / |p_slow|, p_slow the slowest root of s³ + 2ω s² + ω² s + ω³/10."""
    roots = np.roots([1.0, 2.0 * bandwidth, bandwidth**2, bandwidth**3 / 10.0])
    return math.log(3.0 * amplitude / tol) / float(np.min(np.abs(roots.real)))


def test_supply_setpoint_step_no_steady_state_error_under_current() -> None:
    """Supply vessel, calm water, constant current 0.5 m/s at 20°, setpoint step (10, −5) m, 10°.

    Derivation of the bound: with Kd = 2ζω_n M − D and Ki = ω_n/10 Kp each DOF's closed loop is
    M (s³ + 2ζω_n s² + ω_n² s + ω_n³/10) (the sway–yaw coupling of M, D off-diagonals is small),
    for ζ = 1, ω_n = 0.1 rad/s its roots are −0.128, −0.059, −0.0133 rad/s (ω_n = 0.2: twice).
    The setpoint filter (pole −0.1), the velocity filter (−1) and the shafts (−1) are faster.
    The error therefore decays at least like C e^{−0.0133 t}; we allow C = 3× the step size
    (overshoot of the three-pole response plus the current's F/Kp ≈ 0.5 m), so
    t_s = ln(3 A / tol) / 0.0133 ≈ 480 s for A = 10 m, tol = 5 cm, and ≈ 235 s in yaw
    (A = 0.175 rad, tol = 1 mrad). No steady-state error: the mean over the last 200 s is below
    1 mm, where a PD law would keep D₁₁ u_c / Kp ≈ 0.54 m in surge.
    """
    setpoint = (10.0, -5.0, math.radians(10.0))
    scn = Scenario(vessel='supply', sample_time=0.1, duration=1000.0,
                   environment=EnvironmentConfig(current_speed=0.5,
                                                 current_direction=math.radians(20.0)),
                   controller=ControllerConfig(enabled=True, setpoint=setpoint,
                                               bandwidth=(0.1, 0.1, 0.2)))
    rec = simulate(scn, seed=0)
    err = rec.truth_lf_pose - np.array(setpoint)
    t_pos = _settling_time(0.1, 10.0, 0.05)
    t_yaw = _settling_time(0.2, setpoint[2], 1e-3)
    assert 400.0 < t_pos < 560.0 and 200.0 < t_yaw < 270.0
    after = rec.t >= t_pos
    assert np.abs(err[after, :2]).max() < 0.05
    assert np.abs(err[rec.t >= t_yaw, 2]).max() < 1e-3
    tail = rec.t >= 800.0
    assert np.abs(err[tail].mean(axis=0)).max() < 1e-3
    assert vessels.SUPPLY_D[0, 0] * 0.5 * math.cos(math.radians(20)) / 6.7644e4 > 0.5


@pytest.mark.parametrize('vessel', ['onedof', 'threedof'])
def test_thesis_vessels_reach_setpoint_against_constant_drift(vessel: str) -> None:
    """1-DOF/3-DOF with M = 1/b and D linearized: 5 m (and 0.3 rad) step, constant 2 N drift.

    Same derivation with ω_n = 0.05 rad/s: slowest pole −0.00665 rad/s,
    t_s = ln(3·5/0.01)/0.00665 ≈ 1100 s for tol = 1 cm.
    """
    setpoint = (5.0, -5.0, 0.3) if vessel == 'threedof' else (5.0, 0.0, 0.0)
    drift = MarkovBias((2.0, 1.0, 0.02), (0.0, 0.0, 0.0), 300.0)
    scn = Scenario(vessel=vessel, sample_time=1.0, internal_step=0.1, duration=2000.0,
                   environment=EnvironmentConfig(drift=drift),
                   controller=ControllerConfig(enabled=True, setpoint=setpoint,
                                               bandwidth=(0.05, 0.05, 0.05)))
    rec = simulate(scn, seed=0)
    err = rec.truth_lf_pose - np.array(setpoint)
    t_s = _settling_time(0.05, 5.0, 0.01)
    assert 1000.0 < t_s < 1200.0
    assert np.abs(err[rec.t >= t_s]).max() < 0.01
    assert np.abs(err[rec.t >= 1700.0].mean(axis=0)).max() < 1e-3
