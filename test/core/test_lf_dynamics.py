"""Vessel memory (core.lf_dynamics): fit against a known mass–damper, drift tests, choice."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lf_predictor_ros.core import lf_dynamics
from lf_predictor_ros.core.lf_dynamics import (
    FORCE_MARGIN,
    DriftCurve,
    LfDynamics,
    balanced_at,
    body_velocity,
    dead_reckon_step,
    drift_test,
    fit_lf_dynamics,
    heading_basis,
    learn_vessel_memory,
    paired_forces,
)
from lf_predictor_ros.core.odometry_params import OdometryParams

H = 1.0  # s
MASS = np.array([5e6, 6e6, 4e9])  # kg, kg, kg·m²
DAMPING = np.array([5e4, 1e5, 1e8])  # N·s/m, N·s/m, N·m·s
ENV_FORCE = np.array([2e4, -1e4])  # N, earth frame (north, east)


def _vessel_run(seed: int, samples: int = 1800, thrust_scale: float = 3e5,
                yaw_scale: float = 100.0, heading: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """M ν̇ + D ν = τ + R(ψ)ᵀ b (Fossen 2011 eq. 7.8, no Coriolis at DP speed), Euler at h.

    The yaw moment is ``yaw_scale`` [m] times the force scale; the run starts at ``heading``.
    """
    rng = np.random.default_rng(seed)
    eta, nu, tau = np.array([0.0, 0.0, heading]), np.zeros(3), np.zeros(3)
    poses, forces = [], []
    for _ in range(samples):
        tau = tau + 0.02 * (rng.normal(size=3) * thrust_scale * np.array([1, 1, yaw_scale])
                            - tau)
        c, s = math.cos(eta[2]), math.sin(eta[2])
        env_body = np.array([c * ENV_FORCE[0] + s * ENV_FORCE[1],
                             -s * ENV_FORCE[0] + c * ENV_FORCE[1], 0.0])
        nu_dot = (tau - DAMPING * nu + env_body) / MASS
        poses.append(eta.copy())
        forces.append(tau.copy())
        nu = nu + H * nu_dot
        eta = eta + H * np.array([c * nu[0] - s * nu[1], s * nu[0] + c * nu[1], nu[2]])
    return np.array(poses), np.array(forces)


def test_fit_recovers_mass_damping_and_earth_fixed_force() -> None:
    poses, forces = _vessel_run(0)
    model = fit_lf_dynamics(poses, forces, H)
    np.testing.assert_allclose(np.diag(model.damping), -DAMPING / MASS, rtol=0.05)
    np.testing.assert_allclose(np.diag(model.input_gain), 1.0 / MASS, rtol=0.05)
    # u̇ bias = (b_N cos ψ + b_E sin ψ)/m: basis [1, cos, sin] coefficients
    np.testing.assert_allclose(model.bias[0, 1:], ENV_FORCE / MASS[0], rtol=0.05, atol=1e-5)
    assert model.growth_rate() < 0.0


def test_fit_recovers_mass_and_damping_at_a_steady_heading() -> None:
    """DP station keeping: the heading hardly moves, so cos ψ is nearly constant.

    A nearly constant regressor must not dominate the ridge penalty (before the fix the columns
    were divided by their standard deviation without centring: cos ψ became ~1e5 and the fitted
    M⁻¹ came out ~1e-7 of the truth on the supply vessel).
    """
    poses, forces = _vessel_run(4, yaw_scale=0.1, heading=0.3)
    assert np.ptp(poses[:, 2]) < 0.02  # rad: a steady heading indeed
    model = fit_lf_dynamics(poses, forces, H)
    np.testing.assert_allclose(np.diag(model.input_gain)[:2], 1.0 / MASS[:2], rtol=0.05)
    np.testing.assert_allclose(np.diag(model.damping)[:2], -DAMPING[:2] / MASS[:2], rtol=0.1)
    # the earth-fixed force at that heading (the basis terms are collinear there: only their
    # sum at ψ is identified): u̇ bias = (b_N cos ψ + b_E sin ψ)/m
    c, s = math.cos(0.3), math.sin(0.3)
    expected = (c * ENV_FORCE[0] + s * ENV_FORCE[1]) / MASS[0]
    assert model.bias[0] @ np.array([1.0, c, s]) == pytest.approx(expected, rel=0.1)


@pytest.mark.parametrize(('seed', 'kwargs'), [(0, {}), (4, {'yaw_scale': 0.1, 'heading': 0.3})])
def test_known_inertia_fits_damping_and_one_earth_fixed_force(seed: int,
                                                             kwargs: dict[str, float]) -> None:
    """With G = 1/M given, surge and sway share one earth-fixed force b = [b_N, b_E].

    u̇ bias = G_u (b_N cos ψ + b_E sin ψ), v̇ bias = G_v (−b_N sin ψ + b_E cos ψ): the
    coefficients of [1, cos ψ, sin ψ] are [0, G_u b_N, G_u b_E] and [0, G_v b_E, −G_v b_N],
    turning or at a steady heading (where a free basis per DOF is not identified).
    """
    poses, forces = _vessel_run(seed, **kwargs)
    model = fit_lf_dynamics(poses, forces, H, input_gain=1.0 / MASS)
    np.testing.assert_array_equal(np.diag(model.input_gain), 1.0 / MASS)
    np.testing.assert_allclose(np.diag(model.damping), -DAMPING / MASS, rtol=0.03)
    north, east = ENV_FORCE
    np.testing.assert_allclose(model.bias[0], [0.0, north / MASS[0], east / MASS[0]], rtol=0.03,
                               atol=1e-9)
    np.testing.assert_allclose(model.bias[1], [0.0, east / MASS[1], -north / MASS[1]], rtol=0.03,
                               atol=1e-9)
    with pytest.raises(ValueError, match='input_gain'):
        fit_lf_dynamics(poses, forces, H, input_gain=[1e-7, 0.0, 1e-9])


@pytest.mark.parametrize('earth_fixed', [False, True])
def test_the_free_fit_extrapolates_to_another_heading_only_earth_fixed(earth_fixed: bool
                                                                       ) -> None:
    """A window at a steady heading ψ = 0.3 rad, no known gain, evaluated 90° away.

    With ``earth_fixed`` the gains and damping come from a fit with a constant environment
    and the environment is one earth-fixed force: R(ψ)ᵀ b at ψ = 0.3 + π/2 within 5 % of
    |b| in surge and sway. The free [1, cos ψ, sin ψ] per DOF gets the force at 0.3 rad (the
    sum there is identified) but not at the new heading: its surge force there has the
    wrong sign (+21 kN against −15 kN). The gains are the same either way (1/M within 5 %).
    """
    poses, forces = _vessel_run(4, yaw_scale=0.1, heading=0.3)
    model = fit_lf_dynamics(poses, forces, H, earth_fixed=earth_fixed)
    np.testing.assert_allclose(np.diag(model.input_gain), 1.0 / MASS, rtol=0.05)
    scale = float(np.hypot(*ENV_FORCE))
    for heading in (0.3, 0.3 + math.pi / 2):
        c, s = math.cos(heading), math.sin(heading)
        expected = np.array([c * ENV_FORCE[0] + s * ENV_FORCE[1],
                             -s * ENV_FORCE[0] + c * ENV_FORCE[1]])  # R(ψ)ᵀ b
        force = (model.bias @ heading_basis(heading, 3))[:2] * MASS[:2]
        error = float(np.max(np.abs(force - expected)))
        if earth_fixed or heading == 0.3:
            assert error < 0.05 * scale
        else:
            assert error > scale
    if earth_fixed:  # the form of `_fit_known_gain`: no constant in surge/sway, none in yaw's
        assert model.bias[:2, 0].tolist() == [0.0, 0.0]
        assert model.bias[2, 1:].tolist() == [0.0, 0.0]


def test_a_thrust_gain_far_too_large_gives_a_refused_fit() -> None:
    """A known gain 10³× the truth makes F absorb it (rate ≈ 25 1/s ≫ 1/h): refused.

    At 10× the damping rates are 0.10 / 0.13 / 0.25 1/s (time constants 4–10 s, still a
    vessel's); the explicit dead-reckoning step stays bounded only for rates below 2/h.
    """
    poses, forces = _vessel_run(1)
    model = fit_lf_dynamics(poses, forces, H, input_gain=10.0 / MASS)
    assert model.fastest_rate() == pytest.approx(0.25, rel=0.05)
    assert model.fastest_rate() * H < lf_dynamics.MAX_DAMPING_STEP
    with pytest.raises(ValueError, match='time constant below the sample time'):
        fit_lf_dynamics(poses, forces, H, input_gain=1e3 / MASS)
    with pytest.raises(ValueError, match='time constant below the sample time'):
        fit_lf_dynamics(poses[:, :1], forces[:, :1], H, input_gain=[1e4 / MASS[0]])


def test_fit_refuses_bad_input_with_a_message() -> None:
    poses, forces = _vessel_run(1, samples=200)
    with pytest.raises(ValueError, match='shape'):
        fit_lf_dynamics(poses, forces[:, :1], H)
    with pytest.raises(ValueError, match='too few'):
        fit_lf_dynamics(poses[:20], forces[:20], H)
    bad = poses.copy()
    bad[5, 0] = np.nan
    with pytest.raises(ValueError, match='finite'):
        fit_lf_dynamics(bad, forces, H)
    with pytest.raises(ValueError, match='sample_time'):
        fit_lf_dynamics(poses, forces, 0.0)


def test_learned_model_wins_on_an_excited_vessel_and_drifts_little() -> None:
    poses, forces = _vessel_run(2)
    memory = learn_vessel_memory(poses, forces, H, horizon=120.0)
    assert memory.reckoner == 'model'
    model_drift = memory.drift_by_reckoner['model']
    assert np.all(model_drift < 0.2 * memory.drift_by_reckoner['constant_velocity'])
    assert memory.drift.starts >= 4
    # the measured drift grows with the dead-reckoning time
    assert np.all(memory.drift.variance(120.0) >= memory.drift.variance(30.0))


def test_force_limit_is_the_margin_times_the_windows_largest_force() -> None:
    """``force_margin``: the memory believes forces up to that × the window's largest; 0: all."""
    poses, forces = _vessel_run(2)
    largest = np.max(np.abs(forces), axis=0)
    clipped = learn_vessel_memory(poses, forces, H, horizon=120.0, force_margin=2.0)
    np.testing.assert_allclose(clipped.force_limit, 2.0 * largest)
    wide = learn_vessel_memory(poses, forces, H, horizon=120.0, force_margin=10.0)
    np.testing.assert_allclose(wide.force_limit, 10.0 * largest)
    default = learn_vessel_memory(poses, forces, H, horizon=120.0)  # FORCE_MARGIN: no clip,
    assert np.all(np.isinf(default.force_limit))  # as the odometry's default
    assert OdometryParams().dead_reckoning_force_margin == FORCE_MARGIN == 0.0
    turn = np.array([0.0, 0.0, 5.0 * largest[2]])  # a turn's moment, 5 × the window's
    assert clipped.plausible_force(turn)[2] == pytest.approx(2.0 * largest[2])
    assert default.plausible_force(turn)[2] == turn[2]
    for bad in (0.5, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match='force_margin'):
            learn_vessel_memory(poses, forces, H, horizon=120.0, force_margin=bad)


def test_thrust_that_does_not_move_the_vessel_is_not_trusted() -> None:
    """Forces unrelated to the motion (e.g. wrong channel): the model must not be chosen."""
    poses, _ = _vessel_run(3)
    rng = np.random.default_rng(7)
    unrelated = rng.normal(size=poses.shape) * 1e5
    memory = learn_vessel_memory(poses, unrelated, H, horizon=120.0)
    assert memory.reckoner != 'model'
    if memory.model is None:  # refused by the fit itself (a thrust gain <= 0)
        assert 'not used' in memory.message
    else:  # or fitted and then beaten in the drift test
        assert np.sum(memory.drift_by_reckoner['model']) > np.sum(
            memory.drift_by_reckoner[memory.reckoner])


def test_dead_reckon_step_is_pure_and_exact_for_constant_velocity() -> None:
    eta = np.array([1.0, 2.0, math.pi / 2])
    nu = np.array([1.0, 0.0, 0.0])
    eta_copy, nu_copy = eta.copy(), nu.copy()
    new_eta, new_nu = dead_reckon_step(None, 'constant_velocity', eta, nu, np.zeros(3), 2.0)
    np.testing.assert_array_equal(eta, eta_copy)
    np.testing.assert_array_equal(nu, nu_copy)
    np.testing.assert_allclose(new_eta, [1.0, 4.0, math.pi / 2], atol=1e-12)  # heading east
    np.testing.assert_array_equal(new_nu, nu)
    held, zero = dead_reckon_step(None, 'hold', eta, nu, np.zeros(3), 2.0)
    np.testing.assert_array_equal(held, eta)
    np.testing.assert_array_equal(zero, np.zeros(3))
    with pytest.raises(ValueError, match='LfDynamics'):
        dead_reckon_step(None, 'model', eta, nu, np.zeros(3), 1.0)


def test_model_step_matches_first_order_surge_analytically() -> None:
    """1 DOF u̇ = −u/T + τ/m: after k steps u = u0 (1 − h/T)^k for τ = 0."""
    model = LfDynamics(damping=np.array([[-0.1]]), input_gain=np.array([[1e-6]]),
                       bias=np.zeros((1, 1)), residual_std=np.zeros(1))
    eta, nu = np.zeros(1), np.array([1.0])
    for _ in range(10):
        eta, nu = dead_reckon_step(model, 'model', eta, nu, np.zeros(1), 1.0)
    assert nu[0] == pytest.approx(0.9 ** 10)
    assert eta[0] == pytest.approx(sum(0.9 ** k for k in range(1, 11)))


def test_drift_curve_interpolates_and_extrapolates() -> None:
    curve = DriftCurve(np.array([10.0, 20.0]), np.array([[1.0], [4.0]]),
                       np.array([[0.1], [0.2]]), starts=5)
    assert curve.variance(0.0)[0] == 0.0
    assert curve.variance(5.0)[0] == pytest.approx(0.5)
    assert curve.variance(15.0)[0] == pytest.approx(2.5)
    assert curve.variance(40.0)[0] == pytest.approx(16.0)  # quadratic growth beyond
    assert curve.velocity_variance(40.0)[0] == pytest.approx(0.4)  # linear growth beyond
    # a measured curve that dips (few starts, oscillating LF motion): the variance never does
    # (DDS loop test, seed 3: the published pose variance fell 0.70 → 0.57 m² in a dropout)
    dipping = DriftCurve(np.array([10.0, 20.0, 30.0]), np.array([[1.0], [0.25], [2.0]]),
                         np.array([[0.2], [0.1], [0.3]]), starts=2)
    values = [float(dipping.variance(e)[0]) for e in np.arange(0.0, 40.0, 0.5)]
    assert np.all(np.diff(values) >= 0.0)
    assert dipping.variance(20.0)[0] == pytest.approx(1.0)
    assert dipping.variance(25.0)[0] == pytest.approx(1.5)
    assert dipping.velocity_variance(20.0)[0] == pytest.approx(0.2)


def test_drift_test_of_hold_on_uniform_motion_is_exact() -> None:
    """Hold on a vessel moving at 0.5 m/s north: the drift after τ is 0.5 τ exactly."""
    t = np.arange(600.0)
    poses = np.column_stack([0.5 * t, np.zeros_like(t)])[:, :1]
    curve = drift_test(None, 'hold', poses, np.zeros_like(poses), 1.0, horizon=60.0)
    np.testing.assert_allclose(np.sqrt(curve.mean_square[:, 0]), 0.5 * curve.horizons)
    cv = drift_test(None, 'constant_velocity', poses, np.zeros_like(poses), 1.0, horizon=60.0)
    np.testing.assert_allclose(cv.mean_square, 0.0, atol=1e-20)


def test_body_velocity_rotates_into_the_body_frame() -> None:
    t = np.arange(10.0)
    heading_east = np.full_like(t, math.pi / 2)
    poses = np.column_stack([np.zeros_like(t), 2.0 * t, heading_east])  # moving east, bow east
    np.testing.assert_allclose(body_velocity(poses, 1.0), np.tile([2.0, 0.0, 0.0], (10, 1)),
                               atol=1e-12)


def test_forces_are_paired_with_the_targets_by_their_filter() -> None:
    from lf_predictor_ros.core.filters import design_wave_filter, zero_phase

    rng = np.random.default_rng(9)
    forces = rng.normal(size=(300, 3)) * 1e5
    same = paired_forces(forces, None)
    np.testing.assert_array_equal(same, forces)
    assert same is not forces
    sos = design_wave_filter(0.8, H)
    np.testing.assert_array_equal(paired_forces(forces, sos), zero_phase(forces, sos))
    # the wave-band part is what the filter removes: a 0.8 rad/s thrust is notched out
    wave = np.sin(0.8 * np.arange(300.0))[:, None] * np.ones(3) * 1e5
    assert np.max(np.abs(paired_forces(wave, sos)[50:-50])) < 0.05 * 1e5


def test_balanced_at_puts_the_model_in_equilibrium_with_an_earth_fixed_force() -> None:
    """ν̇ = 0 at the balance point; the environment force turns with the vessel (earth-fixed)."""
    model = LfDynamics(damping=-np.diag(DAMPING / MASS), input_gain=np.diag(1.0 / MASS),
                       bias=np.ones((3, 3)) * 1e-3, residual_std=np.full(3, 1e-4))
    nu, force, heading = np.array([0.05, -0.02, 1e-3]), np.array([3e4, -2e4, 1e6]), 0.7
    copies = nu.copy(), force.copy()
    balanced = balanced_at(model, heading, nu, force)
    np.testing.assert_allclose(balanced.acceleration(nu, force, heading), 0.0, atol=1e-15)
    np.testing.assert_array_equal(balanced.damping, model.damping)
    np.testing.assert_array_equal(balanced.input_gain, model.input_gain)
    np.testing.assert_array_equal(nu, copies[0])
    np.testing.assert_array_equal(force, copies[1])

    def earth_force(psi: float) -> np.ndarray:
        """The environment part of ν̇ at rest without thrust, as an earth-frame force [N]."""
        accel = balanced.acceleration(np.zeros(3), np.zeros(3), psi)
        body = accel[:2] * MASS[:2]
        c, s = np.cos(psi), np.sin(psi)
        return np.array([c * body[0] - s * body[1], s * body[0] + c * body[1]])

    np.testing.assert_allclose(earth_force(heading + 1.5), earth_force(heading), rtol=1e-12)
    # at the balance point: −(τ + D ν) rotated to the earth
    expected = -(force[:2] - DAMPING[:2] * nu[:2])
    c, s = np.cos(heading), np.sin(heading)
    np.testing.assert_allclose(earth_force(heading), [c * expected[0] - s * expected[1],
                                                      s * expected[0] + c * expected[1]])
    # 1 DOF: a constant; a thrust gain <= 0 in surge/sway: the model unchanged
    one = LfDynamics(damping=np.array([[-0.01]]), input_gain=np.array([[1e-6]]),
                     bias=np.array([[0.5]]), residual_std=np.array([1e-4]))
    assert balanced_at(one, 0.0, [0.1], [2e3]).bias[0, 0] == pytest.approx(0.01 * 0.1 - 2e-3)
    pushing_back = LfDynamics(model.damping, -model.input_gain, model.bias, model.residual_std)
    assert balanced_at(pushing_back, heading, nu, force) is pushing_back
    # only some DOFs: the others keep the fitted term; surge and sway go together
    yaw_only = balanced_at(model, heading, nu, force, dofs=[False, False, True])
    np.testing.assert_array_equal(yaw_only.bias[:2], model.bias[:2])
    np.testing.assert_array_equal(yaw_only.bias[2], balanced.bias[2])
    surge = balanced_at(model, heading, nu, force, dofs=[True, False, False])
    np.testing.assert_array_equal(surge.bias[:2], balanced.bias[:2])
    np.testing.assert_array_equal(surge.bias[2], model.bias[2])

def test_balanced_at_with_an_acceleration_leaves_the_model_accelerating_so() -> None:
    """``accel``: ν̇ at the balance point is that acceleration (a move's), not 0."""
    model = LfDynamics(damping=-np.diag(DAMPING / MASS), input_gain=np.diag(1.0 / MASS),
                       bias=np.ones((3, 3)) * 1e-3, residual_std=np.full(3, 1e-4))
    nu, force, heading = np.array([0.2, -0.05, 2e-3]), np.array([3e5, -2e4, 1e6]), -0.4
    accel = np.array([0.01, -0.002, 1e-4])
    moving = balanced_at(model, heading, nu, force, accel=accel)
    np.testing.assert_allclose(moving.acceleration(nu, force, heading), accel, atol=1e-15)
    # the environment differs from the one balanced at rest by the force of that acceleration
    rest = balanced_at(model, heading, nu, force)
    np.testing.assert_allclose(moving.acceleration(nu, force, heading) -
                               rest.acceleration(nu, force, heading), accel, atol=1e-15)
    np.testing.assert_array_equal(balanced_at(model, heading, nu, force, accel=np.zeros(3)).bias,
                                  rest.bias)


def test_a_known_damping_rate_is_kept_and_only_the_environment_fitted() -> None:
    """fit_lf_dynamics with input_gain and damping_rate: F = −diag(f) exactly; B recovered."""
    h = 1.0
    model = LfDynamics(damping=np.diag([-1 / 80.0, -1 / 40.0, -1 / 12.0]),
                       input_gain=np.diag([1.5e-7, 9e-8, 2.2e-10]),
                       bias=np.array([[0.0, 2e-4, -1e-4], [0.0, 1e-4, 2e-4], [3e-4, 0.0, 0.0]]),
                       residual_std=np.zeros(3))
    rng = np.random.default_rng(4)
    m = 3000
    tau = np.column_stack([rng.standard_normal(m) * 2e5, rng.standard_normal(m) * 2e5,
                           rng.standard_normal(m) * 5e7])
    tau = np.apply_along_axis(lambda x: np.convolve(x, np.ones(30) / 30.0, 'same'), 0, tau)
    eta, nu = np.zeros(3), np.zeros(3)
    poses = np.empty((m, 3))
    for k in range(m):
        poses[k] = eta
        eta, nu = dead_reckon_step(model, 'model', eta, nu, tau[k], h)
    gain = np.diag(model.input_gain)
    fitted = fit_lf_dynamics(poses, tau, h, input_gain=gain, damping_rate=[1 / 80, 1 / 40, 1 / 12])
    np.testing.assert_array_equal(np.diag(fitted.damping), [-1 / 80, -1 / 40, -1 / 12])
    np.testing.assert_array_equal(np.diag(fitted.input_gain), gain)
    assert fitted.bias[2, 0] == pytest.approx(3e-4, rel=0.05)
    with pytest.raises(ValueError, match='needs input_gain'):
        fit_lf_dynamics(poses, tau, h, damping_rate=[1 / 80, 1 / 40, 1 / 12])
    with pytest.raises(ValueError, match='damping_rate must be 3 positive'):
        fit_lf_dynamics(poses, tau, h, input_gain=gain, damping_rate=[1 / 80, 0.0, 1 / 12])
    memory = learn_vessel_memory(poses, tau, h, 120.0, gain, damping_rate=[0.02, 0.03, 0.1])
    assert memory.model is not None
    np.testing.assert_array_equal(np.diag(memory.model.damping), [-0.02, -0.03, -0.1])
