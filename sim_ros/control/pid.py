"""Nonlinear MIMO PID for dynamic positioning (MSS `PIDnonlinearMIMO.m`, Fossen 2011 §13.2).

    τ = −R(ψ)ᵀ (Kp e + Ki ∫e dt) − Kd ν,   e = η − η_d  (heading error wrapped to (−π, π])

- η_d is the setpoint through the reference filter 1/(T_f s + 1), T_f = 10 s, discretized
  exactly (α = 1 − e^{−h/T_f}); it starts at the first pose it is given, so a setpoint step
  is approached smoothly.
- ν is estimated as R(ψ)ᵀ η̇ with η̇ a finite difference of the pose (heading difference
  wrapped) through a first-order low-pass of time constant T_v, unless the caller passes a
  measured body velocity ``velocity_body`` = [u, v, r] (e.g. an estimator's ``lf_odom`` twist):
  then the D term is −Kd ν with that ν. The finite-difference filter runs on the poses in both
  cases, so the state is the same and a later step without ``velocity_body`` falls back to a
  warm estimate.
- Gains from the bandwidth ω_n and relative damping ζ per DOF (MSS): Kp = M ω_n²,
  Kd = 2ζ ω_n M − D (D the linear(ized) damping, 0 in MSS; the closed loop is then
  M s² + (D + Kd) s + Kp), Ki = (ω_n/10) Kp.
- Anti-windup: the integrator stops while the command saturates (|τ_i| > τ_max,i for any i).
All functions are pure; gains and state are frozen dataclasses.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
import math

import numpy as np

from sim_ros.physics.kinematics import FloatArray, earth_to_body, wrap_angle

SETPOINT_FILTER_TIME = 10.0  # s, T_f (MSS PIDnonlinearMIMO.m)
VELOCITY_FILTER_TIME = 1.0  # s, T_v of the finite-difference velocity estimate
# Where the D term's velocity comes from: 'difference', the filtered finite difference of the
# poses (`pid_step` without ``velocity_body``); 'odometry', an estimator's twist (with it)
VELOCITY_SOURCES = ('difference', 'odometry')


def _vec3(values: float | Sequence[float] | FloatArray, name: str) -> FloatArray:
    arr = np.broadcast_to(np.asarray(values, dtype=np.float64), (3,)).copy()
    if not np.all(np.isfinite(arr)):
        raise ValueError(f'{name} must be finite, got {values}')
    return arr


@dataclass(frozen=True)
class PidGains:
    """Kp, Ki, Kd per DOF (surge/north, sway/east, yaw) and filter time constants [s]."""

    kp: FloatArray
    ki: FloatArray
    kd: FloatArray
    setpoint_filter_time: float = SETPOINT_FILTER_TIME
    velocity_filter_time: float = VELOCITY_FILTER_TIME

    def __post_init__(self) -> None:
        """Validate: 3 non-negative gains each, positive time constants."""
        for name in ('kp', 'ki', 'kd'):
            value = getattr(self, name)
            if np.shape(value) != (3,) or np.any(np.asarray(value) < 0):
                raise ValueError(f'PID {name} must be 3 values >= 0, got {value}')
        if not (self.setpoint_filter_time > 0 and self.velocity_filter_time > 0):
            raise ValueError('PID filter time constants must be > 0 s')


def gains_from_bandwidth(mass_diag: Sequence[float] | FloatArray,
                         bandwidth: float | Sequence[float] | FloatArray,
                         zeta: float | Sequence[float] | FloatArray = 1.0,
                         damping_diag: Sequence[float] | FloatArray | None = None,
                         setpoint_filter_time: float = SETPOINT_FILTER_TIME,
                         velocity_filter_time: float = VELOCITY_FILTER_TIME) -> PidGains:
    """Kp = M ω_n², Kd = max(2ζω_n M − D, 0), Ki = ω_n/10 Kp (MSS PIDnonlinearMIMO.m)."""
    mass = _vec3(mass_diag, 'mass_diag')
    omega = _vec3(bandwidth, 'bandwidth')
    rel_damping = _vec3(zeta, 'zeta')
    lin_damping = np.zeros(3) if damping_diag is None else _vec3(damping_diag, 'damping_diag')
    if np.any(mass <= 0) or np.any(omega <= 0) or np.any(rel_damping <= 0):
        raise ValueError('mass_diag, bandwidth and zeta must be > 0 (bandwidth in rad/s, '
                         'e.g. 0.1 for surge/sway and 0.2 for yaw of a supply vessel)')
    kp = mass * omega**2
    kd = np.maximum(2.0 * rel_damping * omega * mass - lin_damping, 0.0)
    ki = omega / 10.0 * kp
    return PidGains(kp, ki, kd, setpoint_filter_time, velocity_filter_time)


def _zeros() -> FloatArray:
    return np.zeros(3)


@dataclass(frozen=True)
class PidState:
    """Controller memory: filtered setpoint, integral of e, last pose, velocity estimate."""

    initialized: bool = False
    setpoint_filtered: FloatArray = field(default_factory=_zeros)  # η_d
    integral: FloatArray = field(default_factory=_zeros)  # ∫e dt, earth frame
    last_pose: FloatArray = field(default_factory=_zeros)
    velocity_earth: FloatArray = field(default_factory=_zeros)  # filtered η̇ estimate


def pid_step(state: PidState, gains: PidGains, pose: FloatArray, setpoint: FloatArray,
             dt: float, tau_max: float | Sequence[float] | FloatArray | None = None,
             velocity_body: Sequence[float] | FloatArray | None = None,
             ) -> tuple[FloatArray, PidState]:
    """One control period: (τ (3,) body [N, N, N·m], new state); inputs are not modified.

    ``velocity_body`` (3,) [u m/s, v m/s, r rad/s], body frame: the measured or estimated
    velocity for the D term (−Kd ν); None: ν from the filtered finite difference of the poses.
    The new state does not depend on it (module docstring).
    """
    if not (dt > 0.0):
        raise ValueError(f'PID dt must be > 0 s, got {dt}')
    pose = np.asarray(pose, dtype=np.float64)
    setpoint = np.asarray(setpoint, dtype=np.float64)
    if pose.shape != (3,) or setpoint.shape != (3,) or not np.all(np.isfinite(pose)):
        raise ValueError('PID pose and setpoint must be finite (3,) arrays [north, east, yaw]')
    measured_nu = None
    if velocity_body is not None:
        measured_nu = np.array(velocity_body, dtype=np.float64)
        if measured_nu.shape != (3,) or not np.all(np.isfinite(measured_nu)):
            raise ValueError(f'PID velocity_body must be a finite (3,) array [u m/s, v m/s, '
                             f'r rad/s] in the body frame, got {velocity_body!r}; pass None to '
                             'use the finite difference of the poses')
    if not state.initialized:
        state = PidState(True, pose.copy(), np.zeros(3), pose.copy(), np.zeros(3))
    # reference filter 1/(T_f s + 1), exact discretization, heading on the circle
    alpha_ref = 1.0 - math.exp(-dt / gains.setpoint_filter_time)
    delta_ref = setpoint - state.setpoint_filtered
    delta_ref[2] = wrap_angle(float(delta_ref[2]))
    eta_d = state.setpoint_filtered + alpha_ref * delta_ref
    eta_d[2] = wrap_angle(float(eta_d[2]))
    # filtered finite-difference velocity
    step = pose - state.last_pose
    step[2] = wrap_angle(float(step[2]))
    alpha_vel = 1.0 - math.exp(-dt / gains.velocity_filter_time)
    velocity = state.velocity_earth + alpha_vel * (step / dt - state.velocity_earth)
    heading = float(pose[2])
    nu = earth_to_body(heading, velocity) if measured_nu is None else measured_nu
    # PID law
    error = pose - eta_d
    error[2] = wrap_angle(float(error[2]))
    tau = -earth_to_body(heading, gains.kp * error + gains.ki * state.integral) - gains.kd * nu
    integral = state.integral + error * dt
    if tau_max is not None:
        limit = _vec3(tau_max, 'tau_max')
        if np.any(limit <= 0):
            raise ValueError('tau_max must be > 0 per DOF (or None for no limit)')
        if np.any(np.abs(tau) > limit):
            integral = state.integral.copy()  # anti-windup: stop integrating
            tau = np.clip(tau, -limit, limit)
    return tau, PidState(True, eta_d, integral, pose.copy(), velocity)
