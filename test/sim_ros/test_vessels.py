"""Vessel dynamics: DP vessels' time constants and step responses, 1-DOF terminal velocity."""
from __future__ import annotations

from dataclasses import replace
import math

import numpy as np
import pytest
import scipy.linalg

from sim_ros.physics import thrusters, vessels
from sim_ros.physics.integrate import rk4_step
from sim_ros.simulation import ExcitationConfig, Scenario, Simulator, load_scenario, simulate


def _integrate(vessel: vessels.Vessel, tau: tuple[float, float, float], duration: float,
               step: float, state: list[float] | None = None) -> list[list[float]]:
    rates = vessel.rates_fn()
    x = state or [0.0] * 6
    inp = [*tau, 0.0, 0.0, 0.0, 0.0, 0.0]
    out = [x]
    for _ in range(int(round(duration / step))):
        x = rk4_step(rates, x, step, inp, inp, inp)
        out.append(x)
    return out


def test_supply_matrices_and_time_constants() -> None:
    """M, D in SI (anchors §2) and open-loop time constants ≈ 88 / 44 / 11.5 s."""
    assert vessels.SUPPLY_M[1, 2] == pytest.approx(-3.4016e7, rel=1e-4)
    assert vessels.SUPPLY_M[2, 2] == pytest.approx(4.4524e9, rel=1e-4)
    assert vessels.SUPPLY_D[2, 1] == pytest.approx(-6.7258e5, rel=1e-4)
    assert vessels.SUPPLY_D[2, 2] == pytest.approx(3.8501e8, rel=1e-4)
    consts = vessels.SUPPLY.linearize().time_constants()
    np.testing.assert_allclose(consts, [88.0, 44.0, 11.5], rtol=0.015)


def test_bis_matrices_reproduce_the_anchors_and_leave_their_inputs() -> None:
    """bis_matrices on the supply vessel's Mbis, Dbis: anchors §2's SI values; inputs kept."""
    mass_bis, damping_bis = vessels.SUPPLY_MBIS.copy(), vessels.SUPPLY_DBIS.copy()
    mass, damping = vessels.bis_matrices(6000e3, 76.2, mass_bis, damping_bis)
    assert mass[0, 0] == pytest.approx(6.7644e6, rel=1e-4)
    assert mass[1, 2] == pytest.approx(-3.4016e7, rel=1e-4)
    assert damping[0, 0] == pytest.approx(7.7071e4, rel=1e-4)
    assert damping[1, 2] == pytest.approx(-2.0342e6, rel=1e-4)
    np.testing.assert_array_equal(mass_bis, vessels.SUPPLY_MBIS)
    np.testing.assert_array_equal(damping_bis, vessels.SUPPLY_DBIS)


def test_tanker_matrices_from_its_dimensions_and_chosen_time_constants() -> None:
    """Our tanker: m = ρ L B T C_b, bis-system M and D, time constants ≈ 200 / 60 / 25 s."""
    mass = 1025.0 * 150.0 * 27.0 * 9.5 * 0.80
    assert vessels.TANKER_DESIGN.displacement == pytest.approx(mass, rel=1e-12)
    assert mass == pytest.approx(31.5495e6, rel=1e-6)
    assert vessels.TANKER.mass[0, 0] == pytest.approx(1.05 * mass, rel=1e-12)
    assert vessels.TANKER.mass[1, 2] == pytest.approx(-0.06 * mass * 150.0, rel=1e-12)
    assert vessels.TANKER.mass[2, 2] == pytest.approx(0.12 * mass * 150.0**2, rel=1e-12)
    rate = math.sqrt(9.81 / 150.0)  # 1/s, √(g/L)
    assert vessels.TANKER.damping[0, 0] == pytest.approx(0.0205 * mass * rate, rel=1e-12)
    assert vessels.TANKER.damping[2, 1] == pytest.approx(-0.003 * mass * rate * 150.0, rel=1e-12)
    consts = vessels.TANKER.linearize().time_constants()
    np.testing.assert_allclose(consts, [200.0, 60.0, 25.0], rtol=0.005)
    # Slower than the supply vessel in every DOF, and not its Froude-scaled copy (× √(150/76.2))
    supply = vessels.SUPPLY.linearize().time_constants()
    assert np.all(consts > supply)
    assert consts[0] / supply[0] > 1.5 * math.sqrt(150.0 / 76.2)
    assert vessels.make_vessel('tanker') is vessels.TANKER


def test_tanker_surge_step_response_first_order() -> None:
    """Surge is decoupled on the tanker too: 63.2 % of F/D11 at T = M11/D11 ≈ 200 s."""
    force = 2e5  # N
    traj = np.array(_integrate(vessels.TANKER, (force, 0.0, 0.0), 800.0, 0.5))
    u = traj[:, 3]
    t63 = np.interp((1 - math.exp(-1)) * force / vessels.TANKER.damping[0, 0], u,
                    np.arange(len(u)) * 0.5)
    assert t63 == pytest.approx(vessels.TANKER.mass[0, 0] / vessels.TANKER.damping[0, 0], rel=1e-3)
    assert t63 == pytest.approx(200.0, rel=0.01)


def test_tanker_thrusters_are_its_own() -> None:
    """The simulator saturates the tanker at its thrusters' capacity, not the supply vessel's."""
    expected = [2 * 110.0 * 160.0**2,  # two mains [N]
                4 * 12.0 * 250.0**2,  # four tunnel thrusters [N]
                12.0 * 250.0**2 * (62.0 + 55.0 + 55.0 + 62.0) + 110.0 * 160.0**2 * 18.0]  # N·m
    np.testing.assert_allclose(vessels.TANKER.thrusters.max_generalized_force(), expected,
                               rtol=1e-12)
    limit = Simulator(Scenario(vessel='tanker', sample_time=0.1, duration=10.0),
                      seed=0).actuator_limit()
    assert limit is not None
    np.testing.assert_allclose(limit, expected, rtol=1e-12)
    supply = Simulator(Scenario(vessel='supply', sample_time=0.1, duration=10.0),
                       seed=0).actuator_limit()
    assert supply is not None and np.all(limit > 1.5 * supply)


def test_workboat_matrices_time_constants_and_thrusters() -> None:
    """Our workboat: m = ρ L B T C_b, time constants ≈ 50 / 20 / 6 s, its own thrusters."""
    mass = 1025.0 * 40.0 * 11.0 * 3.5 * 0.60
    assert vessels.WORKBOAT_DESIGN.displacement == pytest.approx(mass, rel=1e-12)
    assert vessels.WORKBOAT.mass[2, 2] == pytest.approx(0.14 * mass * 40.0**2, rel=1e-12)
    rate = math.sqrt(9.81 / 40.0)  # 1/s, √(g/L)
    assert vessels.WORKBOAT.damping[1, 1] == pytest.approx(0.1716 * mass * rate, rel=1e-12)
    consts = vessels.WORKBOAT.linearize().time_constants()
    np.testing.assert_allclose(consts, [50.0, 20.0, 6.0], rtol=0.005)
    # Faster than the supply vessel Froude-scaled to 40 m in every DOF
    froude = vessels.SUPPLY.linearize().time_constants() * math.sqrt(40.0 / 76.2)
    assert np.all(consts < 0.8 * froude)
    expected = [2 * 6.0 * 160.0**2, 4 * 0.8 * 250.0**2,
                0.8 * 250.0**2 * (16.0 + 13.0 + 14.0 + 17.0) + 6.0 * 160.0**2 * 8.0]
    limit = Simulator(Scenario(vessel='workboat', sample_time=0.1, duration=10.0),
                      seed=0).actuator_limit()
    assert limit is not None
    np.testing.assert_allclose(limit, expected, rtol=1e-12)
    assert vessels.make_vessel('workboat') is vessels.WORKBOAT


def test_crewboat_time_constants_and_thrusters() -> None:
    """The small class's development hull: m = ρ L B T C_b, 40 / 15 / 5 s, its thrusters."""
    mass = 1025.0 * 30.0 * 8.0 * 2.5 * 0.55
    assert vessels.CREWBOAT_DESIGN.displacement == pytest.approx(mass, rel=1e-12)
    np.testing.assert_allclose(vessels.CREWBOAT.linearize().time_constants(), [40.0, 15.0, 5.0],
                               rtol=0.005)
    expected = [2 * 2.5 * 160.0**2, 4 * 0.35 * 250.0**2,
                0.35 * 250.0**2 * (12.0 + 10.0 + 10.0 + 12.0) + 2.5 * 160.0**2 * 6.0]
    np.testing.assert_allclose(vessels.CREWBOAT.thrusters.max_generalized_force(), expected,
                               rtol=1e-12)
    assert vessels.make_vessel('crewboat') is vessels.CREWBOAT


def test_tunnels_and_mains_layout_is_the_supply_vessels() -> None:
    """The hulls' thruster layout, at the supply vessel's lever arms, is its configuration."""
    supply = thrusters.ThrusterConfig()
    np.testing.assert_array_equal(
        thrusters.tunnels_and_mains_layout((30.0, 22.0, -22.0, -30.0), 8.0),
        supply.configuration)
    same = thrusters.tunnels_and_mains((30.0, 22.0, -22.0, -30.0), 8.0, 3.2, 31.2)
    np.testing.assert_array_equal(same.input_matrix, supply.input_matrix)


def test_supply_surge_step_response_first_order() -> None:
    """Surge is decoupled: u(t) = F/D11 (1 − e^{−t/T}); 63.2 % is reached at T = M11/D11."""
    force = 5e4  # N
    traj = np.array(_integrate(vessels.SUPPLY, (force, 0.0, 0.0), 400.0, 0.1))
    u = traj[:, 3]
    u_inf = force / vessels.SUPPLY_D[0, 0]
    t63 = np.interp((1 - math.exp(-1)) * u_inf, u, np.arange(len(u)) * 0.1)
    assert t63 == pytest.approx(vessels.SUPPLY_M[0, 0] / vessels.SUPPLY_D[0, 0], rel=1e-3)
    assert t63 == pytest.approx(88.0, rel=0.01)
    assert traj[-1, 4] == 0.0 and traj[-1, 5] == 0.0


def test_supply_velocity_matches_matrix_exponential() -> None:
    """ν(t) = (I − e^{−M⁻¹D t}) D⁻¹ τ for a combined step; RK4 at 0.1 s to 1e-7 relative."""
    tau = np.array([3e4, 2e4, 4e6])
    traj = np.array(_integrate(vessels.SUPPLY, (3e4, 2e4, 4e6), 60.0, 0.1))
    a = np.linalg.solve(vessels.SUPPLY_M, vessels.SUPPLY_D)
    for t in (5.0, 11.5, 30.0, 60.0):
        expected = (np.eye(3) - scipy.linalg.expm(-a * t)) @ np.linalg.solve(vessels.SUPPLY_D, tau)
        np.testing.assert_allclose(traj[int(round(t / 0.1)), 3:], expected, rtol=1e-7,
                                   atol=1e-12)


def test_onedof_terminal_velocity_and_tanh_transient() -> None:
    """u̇ = a u|u| + bτ from rest: u = u∞ tanh(t/T_q), u∞ = √(bτ/−a), T_q = 1/√(−a b τ)."""
    tau = 10.0  # N
    a, b = vessels.ONEDOF_A, vessels.ONEDOF_B
    u_inf = math.sqrt(b * tau / -a)
    assert vessels.terminal_speed(a, b, tau) == pytest.approx(u_inf)
    assert u_inf == pytest.approx(0.632456, rel=1e-5)
    traj = np.array(_integrate(vessels.ONEDOF, (tau, 0.0, 0.0), 400.0, 0.05))
    t_q = 1.0 / math.sqrt(-a * b * tau)
    for t in (10.0, 30.0, 100.0):
        assert traj[int(round(t / 0.05)), 3] == pytest.approx(u_inf * math.tanh(t / t_q),
                                                              rel=1e-7)
    assert traj[-1, 3] == pytest.approx(u_inf * math.tanh(400.0 / t_q), rel=1e-7)
    assert np.all(traj[:, [1, 2, 4, 5]] == 0.0)
    long_run = _integrate(vessels.ONEDOF, (tau, 0.0, 0.0), 4000.0, 0.5)
    assert long_run[-1][3] == pytest.approx(u_inf, rel=1e-9)


def test_onedof_terminal_velocity_through_simulator() -> None:
    """The Simulator with a constant τ via a step excitation: position grows at u∞."""
    scn = Scenario(vessel='onedof', sample_time=1.0, internal_step=0.1, duration=600.0,
                   excitation=ExcitationConfig(kind='steps', table=((0.0, -20.0, 5.0, 5.0),)))
    rec = simulate(scn, seed=0, controller=False)
    speed = (rec.truth_pose[-1, 0] - rec.truth_pose[-101, 0]) / 100.0
    assert speed == pytest.approx(-math.sqrt(vessels.ONEDOF_B * 20.0 / -vessels.ONEDOF_A),
                                  rel=1e-6)
    assert np.all(rec.truth_pose[:, 1:] == 0.0)
    np.testing.assert_array_equal(rec.thrust[:, 1:], 0.0)


def test_threedof_yaw_faster_than_surge() -> None:
    """Our 3-DOF choice: same τ → yaw reaches 76 % (tanh 1) √10 × sooner than surge."""
    traj = np.array(_integrate(vessels.THREEDOF, (10.0, 0.0, 10.0), 200.0, 0.05))
    t = np.arange(len(traj)) * 0.05
    level = math.tanh(1.0)
    u_inf = vessels.terminal_speed(vessels.THREEDOF_A[0], vessels.THREEDOF_B[0], 10.0)
    r_inf = vessels.terminal_speed(vessels.THREEDOF_A[2], vessels.THREEDOF_B[2], 10.0)
    t_surge = np.interp(level * u_inf, traj[:, 3], t)
    t_yaw = np.interp(level * r_inf, traj[:, 5], t)
    assert t_surge / t_yaw == pytest.approx(math.sqrt(10.0), rel=1e-3)


def test_linearization_documented_operating_speed() -> None:
    """Thesis vessels: M = 1/b, D = 2|a|u0/b; the supply vessel returns M, D exactly."""
    lin = vessels.ONEDOF.linearize()
    assert lin.mass[0, 0] == pytest.approx(1 / 0.00068)
    assert lin.damping[0, 0] == pytest.approx(2 * 0.017 * 0.1 / 0.00068)
    assert lin.mass[0, 0] / lin.damping[0, 0] == pytest.approx(1 / (2 * 0.017 * 0.1))
    np.testing.assert_array_equal(vessels.SUPPLY.linearize().mass, vessels.SUPPLY_M)


def test_thrust_allocation_saturation_and_shaft_lag() -> None:
    """Allocation reproduces τ, RPM saturate at n_max, shafts follow with T_n = 1 s."""
    cfg = thrusters.ThrusterConfig()
    tau = np.array([2e5, 1e5, 3e6])
    n_c = thrusters.allocate(cfg, tau)
    np.testing.assert_allclose(thrusters.generalized_thrust(cfg, n_c), tau, rtol=1e-9)
    f_max = cfg.max_generalized_force()
    assert f_max[0] == pytest.approx(2 * 31.2 * 160**2)  # ≈ 1.6 MN (2 × 799 kN)
    big = thrusters.allocate(cfg, np.array([1e8, 0.0, 0.0]))
    np.testing.assert_allclose(np.abs(big[4:]), 160.0)
    n = thrusters.shaft_speed(np.zeros(6), n_c, np.array([1.0]), 1.0)
    np.testing.assert_allclose(n[0], n_c * (1 - math.exp(-1)), rtol=1e-12)
    sim = Simulator(Scenario(vessel='supply', sample_time=0.1, duration=100.0), seed=0)
    for _ in range(100):
        sample = sim.step(tau)
    np.testing.assert_allclose(sample.thrust, tau, rtol=1e-4)  # e^{-10} left of the lag
    for _ in range(50):
        sample = sim.step(np.array([1e8, -1e8, 1e10]))
    assert np.all(np.abs(sample.thrust) <= f_max * (1 + 1e-9))


@pytest.mark.parametrize('lf_speed', [0.0, 0.05, 0.6])
def test_wave_motion_free_decay_does_not_depend_on_lf_speed(lf_speed: float) -> None:
    """WF free decay: η_w(∞) = η_w(0) + ν_w(0) / (2|a| u_w), whatever the LF vessel does.

    M ν̇_w + D_w ν_w = 0 with D_w = 2|a| u_w / b: ν_w decays with time constant 1/(2|a| u_w)
    and η_w travels ν_w(0) / (2|a| u_w). With u_w = 0.1 m/s that is 0.5 / 0.0034 = 147 m for
    ν_w(0) = 0.5 m/s. A damping that followed |ν_LF| (the old model) gave 147 m at rest and
    24.5 m at 0.6 m/s: the WF mean would depend on how fast the vessel moved.
    """
    rates = vessels.ONEDOF.wave_rates_fn((0.1, 0.1, 0.02))
    lf = [0.0, 0.0, 0.0, lf_speed, 0.0, 0.0]
    inp = [0.0] * 11
    x = [0.0, 0.0, 0.0, 0.5, 0.0, 0.0]
    step = 1.0
    for _ in range(int(20 * 294 / step)):  # 20 time constants
        x = rk4_step(lambda s, i: rates(lf, s, i), x, step, inp, inp, inp)
    assert x[0] == pytest.approx(0.5 / (2 * 0.017 * 0.1), rel=1e-6)
    assert abs(x[3]) < 1e-8


def test_wave_operating_speed_floors_and_uses_relative_velocity() -> None:
    """u_w = max(|ν − R(ψ)ᵀ v_c|, u0): 0.1 m/s at rest, the current's speed through the water."""
    assert vessels.wave_operating_speed(0.0, (0.0, 0.0, 0.0)) == (0.1, 0.1, 0.02)
    # heading 90° (east), current 0.5 m/s towards north: all of it is sway through the water
    speed = vessels.wave_operating_speed(math.pi / 2, (0.0, 0.0, 0.05), (0.5, 0.0))
    assert speed == pytest.approx((0.1, 0.5, 0.05))
    with pytest.raises(ValueError, match='operating_speed'):
        vessels.ONEDOF.wave_rates_fn((0.1, 0.0, 0.02))


def test_force_superposition_wave_mean_does_not_random_walk() -> None:
    """1-DOF, waves only: the WF pose's 300 s means stay at the shaping filter's tail.

    The low-frequency part of η_w is (K_ω/(M ω0⁶)) e = (2λσb/ω0³) e between D_w/M and ω0:
    ≈ 0.006 m RMS below 0.25 ω0 at σ = 85 N, ω0 = 0.8 rad/s (its 300 s means: 0.003 m). With
    the RK4 mid stages on a linear interpolation of the force the step's impulse erred by O(h³)
    and the mean random-walked: 0.096 m RMS at h = 0.1 s (0.025 m at 0.05 s). Bound 0.01 m at
    h = 0.1 s, seeds 1–3.
    """
    scenario = replace(load_scenario('onedof_no_excitation'), internal_step=0.1)
    means = []
    for seed in (1, 2, 3):
        rec = simulate(scenario, seed=seed, duration=1800.0)
        wave = rec.truth_pose[:, 0] - rec.truth_lf_pose[:, 0]
        means += [wave[(rec.t >= a) & (rec.t < a + 300.0)].mean() for a in range(0, 1800, 300)]
    assert wave.std() == pytest.approx(0.5, rel=0.3)  # the wave motion itself is there
    assert float(np.sqrt(np.mean(np.square(means)))) < 0.01
