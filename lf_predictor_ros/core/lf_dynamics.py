"""Vessel memory: the LF dynamics learned from the predictor's own zero-phase targets.

The learned filter (thesis Alg. 4.1) maps measurements to an LF pose but holds no model of how
the vessel moves. Dead reckoning through a position-reference dropout and a velocity for the DP
controller's D term need one. This module learns it from the same data the network learns from:
the zero-phase filtered targets η_T (thesis §4.2.2, an LF pose series of the past) and the
applied thrust τ, with the low-speed DP model of Fossen (2011) §7.3 / eq. 7.8 in the body frame

    η̇ = R(ψ) ν,          ν̇ = F ν + G τ + B β(ψ),          β(ψ) = [1, cos ψ, sin ψ]

where F ≈ −M⁻¹D, G ≈ M⁻¹ and B β(ψ) ≈ M⁻¹ R(ψ)ᵀ b is the slowly varying environment force
(wind, current, mean wave drift) fixed in the earth frame, hence its cos ψ / sin ψ terms in the
body frame. The coefficients are fitted per DOF by ridge least squares on ν and ν̇ obtained by
differentiating the smooth targets (``fit_lf_dynamics``). Nothing about the hull is assumed.

Whether the thrust can be trusted is decided by the data (issue 13, hypothesis 1): a
dead-reckoning test on the newest part of the window that the fit did not see compares three
dead reckoners — the learned model, constant velocity and holding the pose — and keeps the one
that drifts least (``learn_vessel_memory``). In a DP loop without excitation the learned model can
lose to constant velocity, and then it is not used. The same test measures the drift variance as
a function of the dead-reckoning time, which is the covariance growth published while dead
reckoning.

Conventions: 1 DOF = surge only (η = north, ν = u, no heading basis); 3 DOF = [north m, east m,
heading rad] with the heading unwrapped, ν = [u m/s, v m/s, r rad/s], τ = [X N, Y N, N N·m] in
``base_link_fsd``. All functions are pure: inputs are never modified.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lf_predictor_ros.core.filters import zero_phase
from lf_predictor_ros.core.readonly import ReadOnlyArrays

FloatArray = NDArray[np.float64]
DeadReckoner = Literal['model', 'constant_velocity', 'hold']
DEAD_RECKONERS: tuple[DeadReckoner, ...] = ('model', 'constant_velocity', 'hold')

# Relative ridge penalty of the least-squares fit (on standardized regressors) [-].
RIDGE = 1e-3
# A fitted F with an eigenvalue whose real part exceeds this is not a DP vessel (it would double
# its velocity in < 200 s without thrust): the fit is refused [1/s].
MAX_GROWTH_RATE = 1.0 / 200.0
# Least damping rate of a diagonal fit, 1/(time constant): LF time constants of DP vessels are
# 10–200 s (supply vessel 88 / 44 / 11.5 s, Fossen 2011 §7.3); 1000 s is far beyond [1/s].
MIN_DAMPING_RATE = 1.0 / 1000.0
# A fitted F with an eigenvalue of modulus ≥ this / h is refused: a time constant shorter than
# the sample time is no vessel's LF dynamics, and the explicit dead-reckoning step
# ν⁺ = (1 + h f) ν flips the velocity's sign every step below f = −1/h and grows without bound
# below −2/h (a controller read 10⁴× off gave f = −314 1/s on onedof_feedback, and the dead
# reckoning reached 10⁷³ m in 30 s: docs/BENCHMARKS.md, fifty-second session) [-].
MAX_DAMPING_STEP = 1.0
# Spacing of the dead-reckoning test starts in the validation part of the window [s].
TEST_START_SPACING = 20.0
# Fraction of the window (its newest part) kept out of the fit for the dead-reckoning test [-].
VALIDATION_FRACTION = 1.0 / 3.0
# Fewer starts than this: the drift statistics are not trusted and no choice is made.
MIN_TEST_STARTS = 4
# The default force margin (`learn_vessel_memory`'s ``force_margin``, the odometry's
# ``dead_reckoning_force_margin``): a force beyond this multiple of the largest one in the
# learned window is not believed by the dead reckoner (clipped); 0: no clip (a DP turn commands
# up to 26× the yaw moment of the station keeping before it; clipped at 2×, loops were lost:
# docs/BENCHMARKS.md) [-].
FORCE_MARGIN = 0.0
# The thrust counts as informative when it cuts the held-out dead-reckoning drift by at least
# this fraction: an unrelated thrust changes it by chance by ≈ 1 % (onedof_excited, random
# thrust: 14.69 vs 14.55 m), the real one by 79 % (3.1 vs 14.6 m) [-].
THRUST_MIN_GAIN = 0.1


def heading_basis(heading: float | FloatArray, ndof: int) -> FloatArray:
    """β(ψ) = [1, cos ψ, sin ψ] for 3 DOF, [1] for 1 DOF (shape (..., nb))."""
    psi = np.asarray(heading, dtype=np.float64)
    if ndof == 1:
        return np.ones(psi.shape + (1,))
    return np.stack([np.ones_like(psi), np.cos(psi), np.sin(psi)], axis=-1)


def earth_to_body(eta: FloatArray, eta_dot: FloatArray, ndof: int) -> FloatArray:
    """R(ψ)ᵀ v row by row for earth-frame [north, east, yaw] rows v, ψ from the poses ``eta``.

    For rates ν = R(ψ)ᵀ η̇ (the yaw rate is ψ̇); forces turn the same way. 1 DOF: v unchanged.
    """
    if ndof == 1:
        return np.array(eta_dot, dtype=np.float64)
    c, s = np.cos(eta[:, 2]), np.sin(eta[:, 2])
    return np.stack([c * eta_dot[:, 0] + s * eta_dot[:, 1],
                     -s * eta_dot[:, 0] + c * eta_dot[:, 1], eta_dot[:, 2]], axis=1)


def body_velocity(targets: ArrayLike, sample_time: float) -> FloatArray:
    """LF body velocity ν of an LF pose series (central differences, then rotated)."""
    eta = as_series(targets, 'targets')
    if eta.shape[0] < 3:
        raise ValueError(f'need at least 3 LF poses to differentiate, got {eta.shape[0]}')
    return earth_to_body(eta, np.gradient(eta, sample_time, axis=0), eta.shape[1])


@dataclass(frozen=True)
class LfDynamics(ReadOnlyArrays):
    """ν̇ = F ν + G τ + B β(ψ), one row per DOF (see the module docstring).

    Attributes:
        damping: F, shape (n, n) [1/s] (≈ −M⁻¹D).
        input_gain: G, shape (n, n) [1/kg, 1/(kg·m²)] (≈ M⁻¹).
        bias: B, shape (n, nb) [m/s², rad/s²] (environment force over mass, earth-fixed).
        residual_std: std of the fit residual of ν̇ per DOF [m/s², rad/s²].
    """

    damping: FloatArray
    input_gain: FloatArray
    bias: FloatArray
    residual_std: FloatArray

    def __post_init__(self) -> None:
        """Check shapes and finiteness (read-only copies are stored)."""
        n = np.asarray(self.damping).shape[0]
        shapes = {'damping': (n, n), 'input_gain': (n, n), 'bias': (n, 1 if n == 1 else 3),
                  'residual_std': (n,)}
        for name, shape in shapes.items():
            value = np.array(getattr(self, name), dtype=np.float64)
            if value.shape != shape or not np.all(np.isfinite(value)):
                raise ValueError(f'LfDynamics.{name} must be a finite array of shape {shape}, '
                                 f'got shape {value.shape}')
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def ndof(self) -> int:
        """Degrees of freedom (1 or 3)."""
        return int(self.damping.shape[0])

    def acceleration(self, nu: FloatArray, force: FloatArray, heading: float) -> FloatArray:
        """ν̇ for body velocity ν (n,), body force τ (n,) and heading ψ [rad]."""
        basis = heading_basis(heading, self.ndof)
        return self.damping @ nu + self.input_gain @ force + self.bias @ basis

    def growth_rate(self) -> float:
        """Largest real part of the eigenvalues of F [1/s] (< 0: a damped vessel)."""
        return float(np.max(np.linalg.eigvals(self.damping).real))

    def fastest_rate(self) -> float:
        """Largest modulus of the eigenvalues of F [1/s] (1 / the shortest time constant)."""
        return float(np.max(np.abs(np.linalg.eigvals(self.damping))))


def fit_lf_dynamics(targets: ArrayLike, forces: ArrayLike, sample_time: float,
                    ridge: float = RIDGE, input_gain: ArrayLike | None = None,
                    damping_rate: ArrayLike | None = None,
                    earth_fixed: bool = False) -> LfDynamics:
    """Least-squares fit of ν̇ = F ν + G τ + B β(ψ) on an LF pose series and its body forces.

    F and G are diagonal: each DOF is fitted on its own velocity and force (+ the environment
    basis), its damping rate held ≥ ``MIN_DAMPING_RATE``. Data from a DP loop are closed-loop
    data: the thrust is computed from the vessel's own motion, and a full fit (every DOF on all
    of them, before fbce964) spreads that correlation over the cross terms. On
    supply_closed_loop (tuning seed 1, the predictor in the loop) the full fit was unstable in
    every window (growth 0.04–0.16 1/s); on the fair recording of the same seed the diagonal fit
    gave M⁻¹ at 0.94 / 1.37 / 0.39 of the truth (docs/BENCHMARKS.md, issue 14).

    Args:
        targets: LF poses, shape (m, n) (n = 1 or 3, heading unwrapped), uniform sample time.
        forces: body-frame forces applied at the same instants, shape (m, n).
        sample_time: h [s].
        ridge: relative ridge penalty on RMS-scaled regressors.
        input_gain: a known diagonal thrust gain G_ii = 1 / M_ii per DOF (M the vessel's inertia
            with added mass) [1/kg, 1/(kg·m²)], or None to fit it; with it only the damping and
            the environment terms are fitted (`_fit_known_gain`).
        damping_rate: with ``input_gain``, known damping rates f_i = D_ii / M_ii per DOF
            (F = −diag(f)) [1/s], or None to fit them; with both only the environment is
            fitted.
        earth_fixed: without ``input_gain``, 3 DOF: the environment as with a known gain (one
            earth-fixed force, a constant yaw moment; `_fit_earth_fixed`) instead of a free
            [1, cos ψ, sin ψ] per DOF, which a window at one heading cannot identify: fitted
            there, it extrapolates to absurd forces at another heading.

    Raises:
        ValueError: bad shapes, too few samples, non-finite data, or a fit that is not a damped
            vessel (growth rate above ``MAX_GROWTH_RATE``, a time constant shorter than
            h / ``MAX_DAMPING_STEP``, or a thrust that does not push the vessel its way,
            G_ii ≤ 0): collect more (excited) data, or check a given or read thrust gain.
    """
    eta = as_series(targets, 'targets')
    tau = as_series(forces, 'forces')
    n = eta.shape[1]
    if n not in (1, 3) or tau.shape != eta.shape:
        raise ValueError(f'targets and forces must both have shape (m, 1) or (m, 3), got '
                         f'{eta.shape} and {tau.shape}')
    _check_sample_time(sample_time)
    nu = body_velocity(eta, sample_time)
    nu_dot = np.gradient(nu, sample_time, axis=0)
    basis = heading_basis(eta[:, 2] if n == 3 else np.zeros(eta.shape[0]), n)
    phi = np.hstack([nu, tau, basis])
    if phi.shape[0] < 5 * phi.shape[1]:
        raise ValueError(f'{phi.shape[0]} samples are too few to fit {phi.shape[1]} '
                         'coefficients per DOF: use a longer window')
    known = None if input_gain is None else np.asarray(input_gain, dtype=np.float64)
    if known is not None and (known.shape != (n,) or not np.all(np.isfinite(known)) or
                              np.any(known <= 0.0)):
        raise ValueError(f'input_gain must be {n} positive finite numbers 1/M_ii, got {known}')
    rate = None if damping_rate is None else np.asarray(damping_rate, dtype=np.float64)
    if rate is not None and (known is None or rate.shape != (n,) or
                             not np.all(np.isfinite(rate)) or np.any(rate <= 0.0)):
        raise ValueError(f'damping_rate must be {n} positive finite numbers D_ii/M_ii [1/s] '
                         f'and needs input_gain, got {rate}')
    if known is not None:
        coef, residual_std = _fit_known_gain(nu, nu_dot, tau, eta, known, ridge, rate)
    elif earth_fixed and n == 3:
        coef, residual_std = _fit_earth_fixed(nu, nu_dot, tau, eta, ridge)
    else:
        coef, residual_std = _fit_diagonal(phi, nu, nu_dot, ridge)
    model = LfDynamics(damping=coef[:, :n], input_gain=coef[:, n:2 * n], bias=coef[:, 2 * n:],
                       residual_std=residual_std)
    if model.growth_rate() > MAX_GROWTH_RATE:
        raise ValueError(f'the fitted LF dynamics grow at {model.growth_rate():.3g} 1/s (> '
                         f'{MAX_GROWTH_RATE:.3g}): not a damped vessel, not used')
    if model.fastest_rate() * sample_time >= MAX_DAMPING_STEP:
        raise ValueError(f'the fitted LF dynamics have a rate of {model.fastest_rate():.3g} 1/s '
                         f'(a time constant below the sample time {sample_time:g} s): not a '
                         'vessel, not used (a thrust gain far too large, e.g. a wrong '
                         'controller read, gives this)')
    if np.any((np.diag(model.input_gain) <= 0.0) & (np.std(tau, axis=0) > 0.0)):
        raise ValueError(f'the fitted thrust gain {np.diag(model.input_gain)} has an entry <= 0 '
                         '(the thrust would push the vessel the other way): not used')
    return model


def _fit_diagonal(phi: FloatArray, nu: FloatArray, nu_dot: FloatArray,
                  ridge: float) -> tuple[FloatArray, FloatArray]:
    """Each DOF on its own velocity and force + the basis (coefficient rows as ``phi``)."""
    n = nu.shape[1]
    coef = np.zeros((n, phi.shape[1]))
    residual_std = np.zeros(n)
    for i in range(n):
        columns = [i, n + i, *range(2 * n, phi.shape[1])]
        own, residual_std[i:i + 1] = _ridge(phi[:, columns], nu_dot[:, i:i + 1], ridge)
        if own[0, 0] > -MIN_DAMPING_RATE:
            # no vessel is undamped: closed-loop data (τ ≈ −K_d ν) let a larger G pass for a
            # negative damping; the damping is set to the least and G, B refitted
            own[0, 0] = -MIN_DAMPING_RATE
            rest, residual_std[i:i + 1] = _ridge(
                phi[:, columns[1:]], nu_dot[:, i:i + 1] + MIN_DAMPING_RATE * nu[:, i:i + 1],
                ridge)
            own[0, 1:] = rest[0]
        coef[i, columns] = own[0]
    return coef, residual_std


def _fit_earth_fixed(nu: FloatArray, nu_dot: FloatArray, tau: FloatArray, eta: FloatArray,
                     ridge: float) -> tuple[FloatArray, FloatArray]:
    """3 DOF, no known gain: F and G with a constant environment, then the earth-fixed one.

    First each DOF on its own velocity, force and a constant (`_fit_diagonal`): at one heading
    a constant is the environment, and over a turn it stands in for it. Then, with those
    thrust gains and damping rates, the environment as `_fit_known_gain` fits it: one
    earth-fixed force for surge and sway (Fossen 2011 eq. 7.8), a constant yaw moment. A free
    [1, cos ψ, sin ψ] per DOF on a window at one heading is nearly collinear: on a simulated DP
    window at ψ ≈ 0.3 rad its yaw term, evaluated 0.5 rad away, was −55 MN m against a true
    0.2 MN m (docs/BENCHMARKS.md, fifty-seventh session; the steady-heading case is
    test_the_free_fit_extrapolates_to_another_heading_only_earth_fixed).
    """
    n = nu.shape[1]
    constant = np.hstack([nu, tau, np.ones((nu.shape[0], 1))])
    first, _ = _fit_diagonal(constant, nu, nu_dot, ridge)
    gain = np.diag(first[:, n:2 * n]).copy()
    if np.any(gain <= 0.0):  # the thrust would push the vessel the other way (or no thrust)
        coef = np.zeros((n, 3 * n))
        coef[:, :2 * n] = first[:, :2 * n]
        coef[:, 2 * n] = first[:, 2 * n]
        return coef, np.std(nu_dot - constant @ first.T, axis=0)
    return _fit_known_gain(nu, nu_dot, tau, eta, gain, ridge, -np.diag(first[:, :n]))


def _fit_known_gain(nu: FloatArray, nu_dot: FloatArray, tau: FloatArray, eta: FloatArray,
                    gain: FloatArray, ridge: float, rate: FloatArray | None = None
                    ) -> tuple[FloatArray, FloatArray]:
    """Damping and environment with a known diagonal thrust gain G (coefficient rows as `phi`).

    With known damping rates ``rate`` (f_i, F = −diag(f)) only the environment is fitted.

    Surge and sway share one earth-fixed environment force b = [b_N, b_E] (Fossen 2011 eq. 7.8,
    R(ψ)ᵀ b): u̇ − G_u τ_u = f_u u + G_u (b_N cos ψ + b_E sin ψ), v̇ − G_v τ_v = f_v v +
    G_v (−b_N sin ψ + b_E cos ψ), one least squares over both; yaw a constant moment. A free
    [1, cos ψ, sin ψ] per DOF fitted on a window of one heading extrapolates to absurd forces
    at another (rao_supply after a 45° turn: 0.09 m/s² in sway, the loop ran away).
    """
    n = gain.shape[0]
    coef = np.zeros((n, 3 * n if n == 3 else 3))
    residual = nu_dot - tau * gain
    if rate is not None:
        residual = residual + nu * rate  # ν̇ − G τ − F ν, F = −diag(f): the environment's part
    if n == 1:
        if rate is not None:
            bias = float(np.mean(residual))
            coef[0, 0], coef[0, 1], coef[0, 2] = -rate[0], gain[0], bias
            return coef, np.std(residual - bias, axis=0)
        own, std = _ridge(np.column_stack([nu[:, 0], np.ones(nu.shape[0])]), residual, ridge)
        coef[0, 0], coef[0, 1], coef[0, 2] = min(float(own[0, 0]), -MIN_DAMPING_RATE), gain[0], \
            own[0, 1]
        return coef, std
    c, s = np.cos(eta[:, 2]), np.sin(eta[:, 2])
    zero = np.zeros_like(c)
    phi = np.vstack([np.column_stack([nu[:, 0], zero, gain[0] * c, gain[0] * s]),
                     np.column_stack([zero, nu[:, 1], -gain[1] * s, gain[1] * c])])
    if rate is None:
        own, _ = _ridge(phi, np.concatenate([residual[:, 0], residual[:, 1]])[:, None], ridge)
        f_u, f_v, b_north, b_east = own[0]
        yaw, _ = _ridge(np.column_stack([nu[:, 2], np.ones(nu.shape[0])]), residual[:, 2:3],
                        ridge)
        f_r, n_env = float(yaw[0, 0]), float(yaw[0, 1])
    else:
        own, _ = _ridge(phi[:, 2:], np.concatenate([residual[:, 0], residual[:, 1]])[:, None],
                        ridge)
        (b_north, b_east), (f_u, f_v, f_r) = own[0], -rate
        n_env = float(np.mean(residual[:, 2]))
    coef[0, 0] = min(float(f_u), -MIN_DAMPING_RATE)
    coef[1, 1] = min(float(f_v), -MIN_DAMPING_RATE)
    coef[2, 2] = min(f_r, -MIN_DAMPING_RATE)
    coef[np.arange(3), 3 + np.arange(3)] = gain
    coef[0, 7:9] = gain[0] * b_north, gain[0] * b_east  # u̇: cos ψ, sin ψ
    coef[1, 7:9] = gain[1] * b_east, -gain[1] * b_north  # v̇: cos ψ, sin ψ
    coef[2, 6] = n_env
    basis = heading_basis(eta[:, 2], 3)
    fitted = nu @ np.diag(np.diag(coef[:, :3])) + tau * gain + basis @ coef[:, 6:].T
    return coef, np.std(nu_dot - fitted, axis=0)


def balanced_at(model: LfDynamics, heading: float, nu: ArrayLike, force: ArrayLike,
                dofs: ArrayLike | None = None, accel: ArrayLike | None = None) -> LfDynamics:
    """The model with its environment term re-set so that ν̇ = ``accel`` at (ν, τ, ψ); new.

    The environment force the window's fit gives is a mean over 20 minutes; the one acting when
    the fixes stop is the one the thrust was balancing then (in station keeping τ ≈ −b(t)), as
    the passive observer's bias estimate holds it (Fossen 2011 §11.4). With ν, τ the twist and
    thrust low-passed over the last seconds: B β(ψ) = −(F ν + G τ). Surge and sway keep it an
    earth-fixed force (so it turns with the vessel), R(ψ) G⁻¹ (−F ν − G τ) [N]; yaw a constant
    moment. A thrust gain ≤ 0 in surge or sway (not a damped, thrust-driven vessel) gives the
    model back unchanged. ``dofs`` (n booleans, default all): the DOFs re-set; the others keep
    the fitted term (surge and sway go together: one earth-fixed force). ``accel``: ν̇ at that
    point (n), e.g. a setpoint move's acceleration, so that the thrust that caused it is not
    taken for environment: B β(ψ) = ν̇ − (F ν + G τ); None: 0 (at rest).
    """
    n = model.ndof
    nu_a = np.asarray(nu, dtype=np.float64).reshape(n)
    tau = np.asarray(force, dtype=np.float64).reshape(-1)[:n]
    nu_dot = np.zeros(n) if accel is None else np.asarray(accel, dtype=np.float64).reshape(n)
    required = nu_dot - (model.damping @ nu_a + model.input_gain @ tau)  # environment's ν̇ now
    if n == 1:
        bias = required[:, None]
    else:
        gain = np.diag(model.input_gain)
        if np.any(gain[:2] <= 0.0):
            return model
        f_u, f_v = required[0] / gain[0], required[1] / gain[1]  # body force [N]
        c, s = math.cos(heading), math.sin(heading)
        b_north, b_east = c * f_u - s * f_v, s * f_u + c * f_v  # R(ψ) f, earth-fixed [N]
        bias = np.zeros((3, 3))
        bias[0, 1:] = gain[0] * b_north, gain[0] * b_east  # u̇: cos ψ, sin ψ
        bias[1, 1:] = gain[1] * b_east, -gain[1] * b_north  # v̇: cos ψ, sin ψ
        bias[2, 0] = required[2]
    keep = np.ones(n, dtype=bool) if dofs is None else np.asarray(dofs, dtype=bool).reshape(n)
    if n == 3:
        keep[:2] = keep[0] or keep[1]
    bias = np.where(keep[:, None], bias, model.bias)
    return LfDynamics(model.damping, model.input_gain, bias, model.residual_std)


def dead_reckon_step(model: LfDynamics | None, reckoner: DeadReckoner, eta: FloatArray,
                     nu: FloatArray, force: FloatArray, sample_time: float) -> tuple[
                         FloatArray, FloatArray]:
    """One dead-reckoning step of h (semi-implicit Euler); returns new (η, ν), inputs untouched.

    'model': ν⁺ = ν + h ν̇(ν, τ, ψ), η⁺ = η + h R(ψ) ν⁺; 'constant_velocity': ν⁺ = ν;
    'hold': ν⁺ = 0 (η stays). Works on a single state (n,) or a batch (k, n).
    """
    eta_a, nu_a = np.asarray(eta, dtype=np.float64), np.asarray(nu, dtype=np.float64)
    if reckoner == 'hold':
        return eta_a.copy(), np.zeros_like(nu_a)
    if reckoner == 'model':
        if model is None:
            raise ValueError("dead reckoner 'model' needs a fitted LfDynamics")
        nu_a = nu_a + sample_time * _batch_acceleration(model, eta_a, nu_a,
                                                        np.asarray(force, dtype=np.float64))
    else:
        nu_a = nu_a.copy()
    return eta_a + sample_time * body_to_earth(eta_a, nu_a), nu_a


@dataclass(frozen=True)
class DriftCurve:
    """Mean-square dead-reckoning drift per DOF against dead-reckoning time.

    Attributes:
        horizons: dead-reckoning times [s], increasing, shape (H,).
        mean_square: mean-square pose error at each horizon, shape (H, n) [m², rad²].
        velocity_mean_square: mean-square body-velocity error at each horizon, shape (H, n)
            [m²/s², rad²/s²].
        starts: number of test starts the statistics come from.
    """

    horizons: FloatArray
    mean_square: FloatArray
    velocity_mean_square: FloatArray
    starts: int

    def variance(self, elapsed: float) -> FloatArray:
        """Pose drift variance per DOF after ``elapsed`` seconds.

        The largest mean square reached up to that horizon (a measured curve from a few test
        starts oscillates with the LF motion; a covariance that shrinks while dead reckoning
        would claim the pose got better without a fix), linearly interpolated from 0; beyond
        the longest horizon it grows with the square of the time, as for a velocity error.
        """
        return _interpolate(self.horizons, np.maximum.accumulate(self.mean_square, axis=0),
                            elapsed, 2.0)

    def velocity_variance(self, elapsed: float) -> FloatArray:
        """Velocity drift variance per DOF after ``elapsed`` seconds.

        The largest reached so far, as ``variance``; beyond the longest horizon it grows
        linearly with the time, as for a random walk.
        """
        return _interpolate(self.horizons,
                            np.maximum.accumulate(self.velocity_mean_square, axis=0), elapsed,
                            1.0)

    def rms_at(self, elapsed: float) -> FloatArray:
        """RMS drift per DOF after ``elapsed`` seconds."""
        return np.sqrt(self.variance(elapsed))


@dataclass(frozen=True)
class VesselMemory:
    """What was learned from one target window: the model, the chosen dead reckoner, its drift.

    Attributes:
        model: the fitted LF dynamics (None if the fit was refused).
        reckoner: the dead reckoner that drifted least on the validation part of the window.
        drift: that reckoner's drift curve (validation part).
        drift_by_reckoner: RMS drift per DOF at the longest tested horizon, per reckoner.
        message: why a reckoner was chosen or the model refused.
        accel_std: std of the LF acceleration ν̇ of the targets per DOF [m/s², rad/s²] (the
            process noise of a constant-velocity model).
        force_limit: largest force per DOF the model is used with (`learn_vessel_memory`'s
            ``force_margin``, by default ``FORCE_MARGIN``, × the largest in the window; inf if
            the window had none or the margin is 0) [N, N, N·m].
        drift_curves: the drift curve of every tested reckoner (``curve``).
        known_gain: where the thrust gain 1/M_ii of a known-gain fit came from: '' (fitted),
            'vessel_inertia' (given) or 'controller' (`core.controller_gains`).
        dp_controlled: the thrust was read as a DP controller's (its PD law explains the
            commands on the published estimates): its LF part balances the environment.
        damping_score: with a damping memory (``OdometryParams.dead_reckoning_damping_memory``),
            per DOF the velocity energy Σ ν_i² of the target body velocity of the window whose
            fit gave the model's damping rate (the excitation it was identified with) [m²/s²,
            m²/s², rad²/s²]; None otherwise.
    """

    model: LfDynamics | None
    reckoner: DeadReckoner
    drift: DriftCurve
    drift_by_reckoner: dict[str, FloatArray]
    message: str
    accel_std: FloatArray
    force_limit: FloatArray = field(default_factory=lambda: np.full(3, np.inf))
    drift_curves: dict[DeadReckoner, DriftCurve] = field(default_factory=dict)
    known_gain: str = ''
    dp_controlled: bool = False
    damping_score: FloatArray | None = None

    def curve(self, reckoner: DeadReckoner) -> DriftCurve:
        """The drift curve of ``reckoner`` (the chosen one's if it was not tested)."""
        return self.drift_curves.get(reckoner, self.drift)

    def plausible_force(self, force: FloatArray) -> FloatArray:
        """The force clipped to ±``force_limit`` per DOF (a new array)."""
        limit = self.force_limit[:force.shape[-1]]
        return np.clip(force, -limit, limit)


def drift_test(model: LfDynamics | None, reckoner: DeadReckoner, targets: ArrayLike,
               forces: ArrayLike, sample_time: float, horizon: float,
               start_spacing: float = TEST_START_SPACING) -> DriftCurve:
    """Dead-reckon from the LF state at starts spaced ``start_spacing`` apart; measure drift.

    Each test starts from the target pose and its differentiated body velocity and integrates
    ``dead_reckon_step`` with the recorded forces for ``horizon`` seconds (or as far as the series
    allows); the error against the targets at every step gives the mean-square drift.
    """
    eta_t = as_series(targets, 'targets')
    tau = as_series(forces, 'forces')
    _check_sample_time(sample_time)
    steps = int(round(horizon / sample_time))
    spacing = max(1, int(round(start_spacing / sample_time)))
    m = eta_t.shape[0]
    steps = min(steps, m - 2)
    starts = np.arange(1, m - steps, spacing)
    n = eta_t.shape[1]
    if steps < 1 or starts.size == 0:
        return DriftCurve(np.zeros(0), np.zeros((0, n)), np.zeros((0, n)), 0)
    nu_t = body_velocity(eta_t, sample_time)
    eta, nu = eta_t[starts].copy(), nu_t[starts].copy()
    mean_square = np.empty((steps, n))
    velocity_mean_square = np.empty((steps, n))
    for j in range(steps):
        eta, nu = dead_reckon_step(model, reckoner, eta, nu, tau[starts + j], sample_time)
        mean_square[j] = np.mean((eta - eta_t[starts + j + 1]) ** 2, axis=0)
        velocity_mean_square[j] = np.mean((nu - nu_t[starts + j + 1]) ** 2, axis=0)
    horizons = sample_time * np.arange(1, steps + 1, dtype=np.float64)
    return DriftCurve(horizons, mean_square, velocity_mean_square, int(starts.size))


def learn_vessel_memory(targets: ArrayLike, forces: ArrayLike, sample_time: float,
                        horizon: float, input_gain: ArrayLike | None = None,
                        targets_filter: FloatArray | None = None,
                        force_margin: float = FORCE_MARGIN,
                        damping_rate: ArrayLike | None = None,
                        earth_fixed: bool = False) -> VesselMemory:
    """Fit the LF dynamics on the older part of a window; pick the dead reckoner on the newest.

    The fit uses the oldest 1 − ``VALIDATION_FRACTION`` of the window; each dead reckoner is
    tested on the rest (``drift_test`` over ``horizon`` seconds, capped by the data); the one with
    the smallest drift summed over DOFs (each DOF normalized by the hold reckoner's drift) wins.
    The returned model is refitted on the whole window. Ties and too few test starts keep
    'hold': in a DP loop the controller acts on the dead-reckoned pose, and a velocity that is
    extrapolated without the thrust that would stop it is acted against (on tuning seeds 1–2 of
    the closed loops through 60 s dropouts, constant velocity turned rao_supply by 2.1 rad where
    hold kept 0.95 rad; docs/BENCHMARKS.md, issue 14).

    ``input_gain``: a known thrust gain (`fit_lf_dynamics`). ``targets_filter``: the SOS the
    targets were zero-phase filtered with (`paired_forces`). ``force_margin``: the memory's
    ``force_limit`` is this multiple of the window's largest force per DOF; 0: no limit.
    ``damping_rate``: known damping rates with ``input_gain`` (`fit_lf_dynamics`).
    ``earth_fixed``: without ``input_gain``, the environment's form (`fit_lf_dynamics`).
    """
    check_force_margin(force_margin, 'force_margin')
    eta_t = as_series(targets, 'targets')
    tau = paired_forces(forces, targets_filter)
    split, test_horizon = _held_out_split(eta_t.shape[0], sample_time, horizon)
    model: LfDynamics | None = None
    message = ''
    try:
        model = fit_lf_dynamics(eta_t[:split], tau[:split], sample_time,
                                input_gain=input_gain, damping_rate=damping_rate,
                                earth_fixed=earth_fixed)
    except ValueError as exc:
        message = f'LF dynamics not fitted: {exc}'
    curves = {name: drift_test(model, name, eta_t[split:], tau[split:], sample_time,
                               test_horizon)
              for name in DEAD_RECKONERS if name != 'model' or model is not None}
    rms: dict[str, FloatArray] = {name: np.sqrt(curve.mean_square[-1]) if curve.starts else
           np.full(eta_t.shape[1], np.inf) for name, curve in curves.items()}
    chosen: DeadReckoner = 'hold'
    if curves['hold'].starts >= MIN_TEST_STARTS:
        scale = np.maximum(rms['hold'], 1e-9)
        score = {name: float(np.sum(value / scale)) for name, value in rms.items()}
        best: DeadReckoner = min(curves, key=lambda name: score[name])
        if score[best] < score['hold']:
            chosen = best
        message = message or (f"dead reckoner '{chosen}' drifts least on the newest "
                              f'{test_horizon:.0f} s tests')
    else:
        message = message or 'too few dead-reckoning tests: hold kept'
    if model is not None:
        try:
            model = fit_lf_dynamics(eta_t, tau, sample_time, input_gain=input_gain,
                                    damping_rate=damping_rate, earth_fixed=earth_fixed)
        except ValueError as exc:
            model, message = None, f'LF dynamics not refitted: {exc}'
            chosen = 'hold' if chosen == 'model' else chosen
    accel = np.gradient(body_velocity(eta_t, sample_time), sample_time, axis=0)
    largest = np.max(np.abs(tau), axis=0)
    force_limit = np.where((largest > 0.0) & (force_margin > 0.0), force_margin * largest,
                           np.inf)
    return VesselMemory(model, chosen, curves[chosen], rms, message, np.std(accel, axis=0),
                        force_limit, dict(curves))


def thrust_improves_dead_reckoning(targets: ArrayLike, forces: ArrayLike, sample_time: float,
                                   horizon: float,
                                   targets_filter: FloatArray | None = None) -> bool:
    """Does the thrust make the learned LF model dead-reckon better? (issue 13, hypothesis 1).

    This is the thrust's validated contribution on the newest data. Two models are fitted on the
    older two thirds of the window, one with the forces and one with the forces set to 0
    (damping and environment terms only), and both dead-reckon the newest third
    (``drift_test``). True if the model with thrust drifts at least ``THRUST_MIN_GAIN`` less,
    summed over DOFs (each normalized by the hold reckoner's drift). A fit with thrust that is
    refused where the one without is not (e.g. a thrust gain <= 0) gives False; any other failed
    fit, or too few tests, gives True: the thesis's structure is kept when the data cannot tell.
    ``targets_filter``: as `learn_vessel_memory`.
    """
    eta_t = as_series(targets, 'targets')
    tau = paired_forces(forces, targets_filter)
    split, test_horizon = _held_out_split(eta_t.shape[0], sample_time, horizon)
    try:
        without = fit_lf_dynamics(eta_t[:split], np.zeros_like(tau[:split]), sample_time)
    except ValueError:
        return True
    try:
        with_thrust = fit_lf_dynamics(eta_t[:split], tau[:split], sample_time)
    except ValueError:
        return False
    hold = drift_test(None, 'hold', eta_t[split:], tau[split:], sample_time, test_horizon)
    if hold.starts < MIN_TEST_STARTS:
        return True
    scale = np.maximum(np.sqrt(hold.mean_square[-1]), 1e-9)
    drift = {}
    for name, model, force in (('with', with_thrust, tau), ('without', without,
                                                            np.zeros_like(tau))):
        curve = drift_test(model, 'model', eta_t[split:], force[split:], sample_time,
                           test_horizon)
        drift[name] = float(np.sum(np.sqrt(curve.mean_square[-1]) / scale))
    return drift['with'] < (1.0 - THRUST_MIN_GAIN) * drift['without']


def paired_forces(forces: ArrayLike, targets_filter: FloatArray | None) -> FloatArray:
    """The forces as the fit pairs them with zero-phase targets: filtered by the same SOS.

    The model ν̇ = F ν + G τ + B β is linear, so it holds between the filtered signals too;
    unfiltered, the wave-band thrust a DP loop makes from its estimate's wave leakage is an
    error in the regressor and biases the thrust gain G towards 0 (errors in variables).
    None: the forces as given (new array).
    """
    tau = as_series(forces, 'forces')
    if targets_filter is None or tau.shape[0] < 2:
        return tau
    return zero_phase(tau, targets_filter)


def _held_out_split(samples: int, sample_time: float, horizon: float) -> tuple[int, float]:
    """(first sample of the held-out newest part of a window, drift-test horizon [s]).

    The held-out part is the newest ``VALIDATION_FRACTION``; the horizon is ``horizon`` capped
    at half of it.
    """
    split = int(round(samples * (1.0 - VALIDATION_FRACTION)))
    return split, min(horizon, (samples - split) * sample_time / 2.0)


def _interpolate(horizons: FloatArray, table: FloatArray, elapsed: float,
                 power: float) -> FloatArray:
    if elapsed <= 0.0 or horizons.size == 0:
        return np.zeros(table.shape[1])
    last = float(horizons[-1])
    if elapsed > last:
        return np.asarray(table[-1] * (elapsed / last) ** power, dtype=np.float64)
    grid = np.concatenate([[0.0], horizons])
    padded = np.vstack([np.zeros((1, table.shape[1])), table])
    return np.array([np.interp(elapsed, grid, padded[:, j]) for j in range(padded.shape[1])])


def _batch_acceleration(model: LfDynamics, eta: FloatArray, nu: FloatArray,
                        force: FloatArray) -> FloatArray:
    heading = eta[..., 2] if model.ndof == 3 else np.zeros(eta.shape[:-1])
    basis = heading_basis(heading, model.ndof)
    return nu @ model.damping.T + force @ model.input_gain.T + basis @ model.bias.T


def body_to_earth(eta: FloatArray, nu: FloatArray) -> FloatArray:
    """R(ψ) v for body-frame rows v = [x, y, yaw] (rates, forces), ψ from the poses ``eta``.

    Any leading shape (..., 3); 1 DOF (shape (..., 1)): v unchanged. The inverse of
    `earth_to_body`.
    """
    if eta.shape[-1] == 1:
        return nu
    c, s = np.cos(eta[..., 2]), np.sin(eta[..., 2])
    return np.stack([c * nu[..., 0] - s * nu[..., 1], s * nu[..., 0] + c * nu[..., 1],
                     nu[..., 2]], axis=-1)


def _ridge(phi: FloatArray, y: FloatArray, ridge: float) -> tuple[FloatArray, FloatArray]:
    """Per-output ridge least squares on RMS-scaled columns; returns (coef, residual std).

    Each column is divided by its root mean square, so every scaled column has unit mean
    square and the penalty ``ridge`` · tr(ZᵀZ) / p is ``ridge`` · m whatever the units. (Dividing
    by the standard deviation instead, without centring, blew up a nearly constant column such
    as cos ψ at a steady heading to ~1e5 and let the penalty shrink every other coefficient to
    zero: the fitted M⁻¹ came out 1e-7 of the truth.)
    """
    scale = np.sqrt(np.mean(phi**2, axis=0))
    scale = np.where(scale > 0.0, scale, 1.0)
    z = phi / scale
    gram = z.T @ z
    penalty = ridge * np.trace(gram) / gram.shape[0] * np.eye(gram.shape[0])
    coef_z = np.linalg.solve(gram + penalty, z.T @ y)
    coef = (coef_z / scale[:, None]).T
    residual = y - phi @ coef.T
    return coef, np.std(residual, axis=0)


def as_series(values: ArrayLike, name: str) -> FloatArray:
    """A finite (m, n) float copy of a series ((m,) becomes (m, 1)); ValueError names it."""
    array = np.array(values, dtype=np.float64)
    if array.ndim == 1:
        array = array[:, None]
    if array.ndim != 2 or not np.all(np.isfinite(array)):
        raise ValueError(f'{name} must be a finite (m,) or (m, n) array, got shape {array.shape}')
    return array


def check_force_margin(value: float, name: str) -> None:
    """A thrust clip margin: 0 (no clip) or a finite multiple >= 1; ValueError naming ``name``."""
    if not (isinstance(value, (int, float)) and math.isfinite(value) and
            (value == 0.0 or value >= 1.0)):
        raise ValueError(f"{name} must be 0 (no clip) or a finite number >= 1 (× the window's "
                         f'largest thrust), got {value!r}')


def _check_sample_time(sample_time: float) -> None:
    if not (math.isfinite(sample_time) and sample_time > 0.0):
        raise ValueError(f'sample_time must be a positive finite number of seconds, '
                         f'got {sample_time}')
