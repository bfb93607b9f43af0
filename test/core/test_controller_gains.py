"""The DP controller's gains read from its thrust; the inertia they imply."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import lfilter

from lf_predictor_ros.core.controller_gains import (
    DIFFERENCE_TIMES,
    MIN_R_SQUARED,
    ControllerGains,
    believed_medians,
    block_bounds,
    damping_corrected_inertia,
    difference_velocity,
    fit_controller_gains,
    fitted_damping_scale,
    identity_gated,
    median_implied_inertia,
    median_natural_freq,
    read_controller_gains,
)
from lf_predictor_ros.core.lf_dynamics import body_velocity, earth_to_body
from sim_ros.control.pid import PidState, gains_from_bandwidth, pid_step

H = 1.0  # s
MASS = np.array([6.7644e6, 1.13412e7, 4.4524e9])  # supply vessel M_ii [kg, kg, kg·m²]
BANDWIDTH = np.array([0.1, 0.1, 0.15])  # rad/s


def _lf_track(seed: int, m: int = 1500, heading: float = 0.0) -> np.ndarray:
    """A smooth random LF pose series around (0, 0, heading): 0.5 m / 0.01 rad."""
    rng = np.random.default_rng(seed)
    a = np.exp(-H / 30.0)
    smooth = lfilter([1 - a], [1, -a], lfilter([1 - a], [1, -a], rng.standard_normal((m, 3)),
                                               axis=0), axis=0)
    smooth /= np.std(smooth, axis=0)
    return np.array([0.0, 0.0, heading]) + smooth * np.array([0.5, 0.5, 0.01])


def _pid_thrust(eta: np.ndarray, nu: np.ndarray | None, zeta: float, lag: int = 0
                ) -> np.ndarray:
    """The MSS PID's thrust on ``eta``, its D term on ``nu`` (None: its own difference)."""
    gains = gains_from_bandwidth(MASS, BANDWIDTH, zeta)
    state = PidState()
    tau = np.zeros_like(eta)
    for k in range(eta.shape[0]):
        tau[k], state = pid_step(state, gains, eta[k], np.array([0.0, 0.0, eta[0, 2]]), H,
                                 velocity_body=None if nu is None else nu[k])
    # the thrust at k computed from the estimate at k − lag
    return np.concatenate([np.repeat(tau[:1], lag, axis=0), tau[:tau.shape[0] - lag]])


@pytest.mark.parametrize('zeta', [1.0, 0.7])
def test_gains_and_implied_inertia_of_the_mss_pid(zeta: float) -> None:
    eta = _lf_track(1)
    nu = body_velocity(eta, H)
    gains = fit_controller_gains(eta, nu, _pid_thrust(eta, nu, zeta), H)
    design = gains_from_bandwidth(MASS, BANDWIDTH, zeta)
    np.testing.assert_allclose(gains.stiffness, design.kp, rtol=0.05)
    np.testing.assert_allclose(gains.damping, design.kd, rtol=0.05)
    assert np.all(gains.r_squared > 0.95)
    assert gains.shift == 0
    # Kd² / (4 Kp) = (2 ζ ω M)² / (4 ω² M) = ζ² M
    inertia = gains.implied_inertia()
    assert inertia is not None
    np.testing.assert_allclose(inertia, zeta ** 2 * MASS, rtol=0.1)


def test_heading_turned_body_frame_and_a_lagging_thrust() -> None:
    eta = _lf_track(2, heading=2.0)
    nu = body_velocity(eta, H)
    gains = fit_controller_gains(eta, nu, _pid_thrust(eta, nu, 1.0, lag=1), H)
    assert gains.shift == 1
    # the MSS PID applies Kp in the earth frame: at ψ = 2 rad body surge sees
    # cos²ψ Kp_N + sin²ψ Kp_E, sway sin²ψ Kp_N + cos²ψ Kp_E (cross terms average out)
    design = gains_from_bandwidth(MASS, BANDWIDTH, 1.0)
    c2, s2 = np.cos(2.0) ** 2, np.sin(2.0) ** 2
    mixed = np.array([c2 * design.kp[0] + s2 * design.kp[1], s2 * design.kp[0] +
                      c2 * design.kp[1], design.kp[2]])
    np.testing.assert_allclose(gains.stiffness, mixed, rtol=0.1)
    np.testing.assert_allclose(gains.damping, design.kd, rtol=0.08)
    assert gains.implied_inertia() is not None


@pytest.mark.parametrize('earth_highpass', [False, True])
def test_the_earth_frame_stiffness_reads_the_mss_pid_at_any_heading(earth_highpass: bool
                                                                      ) -> None:
    """τ = −R(ψ)ᵀ Kp e − Kd ν at ψ = 2 rad: Kp_N, Kp_E and the inertia M_ii, not their mix.

    The body-frame read pairs Kd_u = 2 ω M_11 with cos²ψ Kp_N + sin²ψ Kp_E, so Kd² / (4 Kp)
    is M_11² / (cos²ψ M_11 + sin²ψ M_22) (ω the same in surge and sway).
    """
    eta = _lf_track(2, heading=2.0)
    nu = body_velocity(eta, H)
    tau = _pid_thrust(eta, nu, 1.0, lag=1)
    design = gains_from_bandwidth(MASS, BANDWIDTH, 1.0)
    body = fit_controller_gains(eta, nu, tau, H, earth_highpass=earth_highpass)
    earth = fit_controller_gains(eta, nu, tau, H, earth_highpass=earth_highpass,
                                 stiffness_frame='earth')
    auto = fit_controller_gains(eta, nu, tau, H, earth_highpass=earth_highpass,
                                stiffness_frame='auto')
    assert (body.stiffness_frame, earth.stiffness_frame) == ('body', 'earth')
    assert earth.shift == 1
    np.testing.assert_allclose(earth.stiffness, design.kp, rtol=0.05)
    np.testing.assert_allclose(earth.damping, design.kd, rtol=0.08)  # yaw as the body read's
    assert np.all(earth.r_squared > 0.95)
    assert np.all(earth.r_squared[:2] > body.r_squared[:2])
    inertia = earth.implied_inertia()
    assert inertia is not None
    np.testing.assert_allclose(inertia[:2], MASS[:2], rtol=0.1)
    c2, s2 = np.cos(2.0) ** 2, np.sin(2.0) ** 2
    mixed = np.array([MASS[0] ** 2 / (c2 * MASS[0] + s2 * MASS[1]),
                      MASS[1] ** 2 / (s2 * MASS[0] + c2 * MASS[1])])
    np.testing.assert_allclose(body.inertia_per_dof()[:2], mixed, rtol=0.12)
    assert auto.stiffness_frame == 'earth'
    np.testing.assert_array_equal(auto.stiffness, earth.stiffness)
    # the yaw row is the same regression in either frame
    assert earth.stiffness[2] == pytest.approx(body.stiffness[2], rel=1e-9)


def test_auto_keeps_the_body_frame_for_a_pd_law_on_the_body_frame_error() -> None:
    """τ = −Kp R(ψ)ᵀ e − Kd ν (Fossen 2011 §12.2.6): 'auto' reads it in the body frame."""
    eta = _lf_track(4, heading=0.8)
    nu = body_velocity(eta, H)
    kp, kd = np.array([4e4, 9e4, 6e7]), np.array([9e5, 2e6, 1.2e9])
    error = eta - np.array([0.0, 0.0, 0.8])
    tau = -earth_to_body(eta, error, 3) * kp - kd * nu
    auto = fit_controller_gains(eta, nu, tau, H, stiffness_frame='auto')
    assert auto.stiffness_frame == 'body'
    np.testing.assert_allclose(auto.stiffness, kp, rtol=0.02)
    np.testing.assert_allclose(auto.damping, kd, rtol=0.02)
    earth = fit_controller_gains(eta, nu, tau, H, stiffness_frame='earth')
    assert float(np.sum(earth.r_squared)) < float(np.sum(auto.r_squared))
    # near heading 0 (±0.01 rad) the two frames are one: the same gains to 0.5 %
    eta0 = _lf_track(4)
    nu0 = body_velocity(eta0, H)
    tau0 = -eta0 * kp - kd * nu0
    zero_body = fit_controller_gains(eta0, nu0, tau0, H)
    zero_earth = fit_controller_gains(eta0, nu0, tau0, H, stiffness_frame='earth')
    np.testing.assert_allclose(zero_earth.stiffness, zero_body.stiffness, rtol=5e-3)
    np.testing.assert_allclose(zero_earth.damping, zero_body.damping, rtol=5e-3)
    # 1 DOF: the frame does not apply
    one = fit_controller_gains(eta0[:, :1], nu0[:, :1], tau0[:, :1], H, stiffness_frame='earth')
    assert one.stiffness_frame == 'body'
    with pytest.raises(ValueError, match='stiffness_frame'):
        fit_controller_gains(eta0, nu0, tau0, H, stiffness_frame='north')


def test_unrelated_thrust_gives_no_inertia() -> None:
    eta = _lf_track(3)
    nu = body_velocity(eta, H)
    noise = np.random.default_rng(4).standard_normal(eta.shape) * np.array([1e5, 1e5, 1e7])
    gains = fit_controller_gains(eta, nu, noise, H)
    assert np.all(gains.r_squared < MIN_R_SQUARED)
    assert gains.implied_inertia() is None


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_controller_acting_on_another_estimate_explains_less_and_a_bound_refuses_it(
        seed: int) -> None:
    """A PID on the true LF pose, read on an estimate 0.8 × another LF track off it.

    It explains 0.60-0.76 of the thrust (the PID on the estimate itself > 0.95, above): every
    block believes it (R² ≥ 0.5), but alone it is not believed with ``lone_r_squared`` 0.9
    (`controller_read_lone_r_squared`); among three blocks the lone bound does not apply.
    """
    eta = _lf_track(1 + seed)
    estimate = eta + 0.8 * _lf_track(20 + seed)
    gains = fit_controller_gains(estimate, body_velocity(estimate, H),
                                 _pid_thrust(eta, body_velocity(eta, H), 1.0), H)
    assert np.all((gains.r_squared > MIN_R_SQUARED) & (gains.r_squared < 0.8))
    assert gains.believed().all()
    assert not gains.believed(min_r_squared=0.9).any()
    assert gains.implied_inertia(min_r_squared=0.9) is None
    inertia, counts = median_implied_inertia([gains], lone_r_squared=0.9)
    assert inertia is None and counts.tolist() == [0, 0, 0]
    assert median_implied_inertia([gains])[0] is not None
    inertia, counts = median_implied_inertia([gains, gains, gains], lone_r_squared=0.9)
    assert inertia is not None and counts.tolist() == [3, 3, 3]


def test_a_dof_one_block_alone_believes_needs_the_lone_r_squared() -> None:
    """Per DOF: surge's lone block (R² 0.7) is refused at 0.9, sway's (0.95) kept; yaw has 2."""
    def block(r2: list[float]) -> ControllerGains:
        return ControllerGains(np.ones(3), np.full(3, 2.0), np.array(r2), 0)  # M 1 each

    blocks = [block([0.7, 0.95, 0.6]), block([0.1, 0.2, 0.6])]
    _, counts = median_implied_inertia(blocks)
    assert counts.tolist() == [1, 1, 2]
    inertia, counts = median_implied_inertia(blocks, lone_r_squared=0.9)
    assert inertia is None and counts.tolist() == [0, 1, 2]


def test_negative_gain_is_not_believed() -> None:
    gains = ControllerGains(np.array([1.0, -1.0, 1.0]), np.ones(3), np.ones(3), 0)
    assert gains.believed().tolist() == [True, False, True]
    assert gains.implied_inertia() is None


def test_one_dof() -> None:
    eta = _lf_track(5)[:, :1]
    nu = np.gradient(eta, H, axis=0)
    tau = -2.0e4 * eta - 3.0e5 * nu
    gains = fit_controller_gains(eta, nu, tau, H)
    np.testing.assert_allclose([gains.stiffness[0], gains.damping[0]], [2.0e4, 3.0e5], rtol=1e-6)
    inertia = gains.implied_inertia()
    assert inertia is not None
    np.testing.assert_allclose(inertia, [3.0e5 ** 2 / 8.0e4], rtol=1e-6)


def test_runs_are_pooled_without_crossing_a_break() -> None:
    """Two runs (the second 20 m further) of a PD with a 1-sample lag, pooled into one fit."""
    runs = [_lf_track(10, m=200)[:, :1] * 4.0, 20.0 + _lf_track(11, m=200)[:, :1] * 4.0]
    taus = []
    for run in runs:
        pd = -2.0e4 * run - 3.0e5 * np.gradient(run, H, axis=0)
        taus.append(np.concatenate([pd[:1], pd[:-1]]))  # thrust at k from the estimate at k − 1
    eta, tau = np.concatenate(runs), np.concatenate(taus)
    nu = np.concatenate([np.gradient(run, H, axis=0) for run in runs])
    gains = fit_controller_gains(eta, nu, tau, H, run_starts=[200])
    assert gains.shift == 1 and gains.r_squared[0] > 0.99
    # measured 0.973 / 0.998 of the design gains (the high-pass edges of 200-sample runs)
    np.testing.assert_allclose([gains.stiffness[0], gains.damping[0]], [2.0e4, 3.0e5], rtol=0.05)
    # read as one run, the high-pass and the shift cross the 20 m break: Kd measured 0.85 ×
    joined = fit_controller_gains(eta, nu, tau, H)
    assert abs(joined.damping[0] / 3.0e5 - 1.0) > 0.1
    for starts in ([0], [200, 150], [400], [50]):  # not increasing in (0, m), or a short run
        with pytest.raises(ValueError, match='run_starts|too few'):
            fit_controller_gains(eta, nu, tau, H, run_starts=starts)


def test_a_turn_away_from_the_origin_is_read_in_the_earth_frame() -> None:
    """Held 15 m N / 10 m E of the origin, a 45° turn: the body-frame pose swings with ψ.

    High-passed in the body frame the sway inertia comes out 2.6× (measured); high-passed in
    the earth frame, where the setpoint is constant, surge and sway are within 20 % of M_ii
    (0.84 / 1.08 measured; surge sees cos²ψ Kp_N + sin²ψ Kp_E after the turn). The heading's
    read is the same either way (the setpoint ramp through the PID's setpoint filter corrupts
    it in both: what the median over blocks is for).
    """
    m = 600
    turn = np.clip((np.arange(m) - 250) / 100.0, 0.0, 1.0) * np.pi / 4
    eta = _lf_track(12, m=m) + np.column_stack([np.full(m, 15.0), np.full(m, 10.0), turn])
    nu = body_velocity(eta, H)
    design = gains_from_bandwidth(MASS, BANDWIDTH, 1.0)
    state = PidState()
    tau = np.zeros_like(eta)
    for k in range(m):
        tau[k], state = pid_step(state, design, eta[k], np.array([15.0, 10.0, turn[k]]), H,
                                 velocity_body=nu[k])
    body = fit_controller_gains(eta, nu, tau, H)
    earth = fit_controller_gains(eta, nu, tau, H, earth_highpass=True)

    def ratio(gains: ControllerGains) -> np.ndarray:
        return gains.damping ** 2 / (4.0 * gains.stiffness) / MASS

    assert ratio(body)[1] > 2.0
    np.testing.assert_allclose(ratio(earth)[:2], 1.0, rtol=0.2)
    assert np.all(earth.r_squared[:2] > 0.98)
    assert ratio(earth)[2] == pytest.approx(ratio(body)[2], rel=1e-9)
    # 1 DOF: the earth frame is the body frame
    one = fit_controller_gains(eta[:, :1], nu[:, :1], tau[:, :1], H)
    same = fit_controller_gains(eta[:, :1], nu[:, :1], tau[:, :1], H, earth_highpass=True)
    np.testing.assert_array_equal(one.damping, same.damping)


@pytest.mark.parametrize(('length', 'expected'), [
    (1000, [(0, 300), (300, 600), (600, 1000)]),  # a short remainder joins the last block
    (1024, [(0, 300), (300, 600), (600, 900), (900, 1024)]),  # one of the minimum is a block
    (400, [(0, 400)]), (200, [(0, 200)]), (124, [(0, 124)]), (123, []),
])
def test_block_bounds(length: int, expected: list[tuple[int, int]]) -> None:
    assert block_bounds(length, 300, 124) == expected
    assert block_bounds(length, 50, 124) == block_bounds(length, 124, 124)  # never < minimum


def test_median_over_believed_blocks() -> None:
    """Per DOF the median of Kd²/(4 Kp) over the believed blocks; a spoilt block is outvoted."""
    def block(kp: list[float], kd: list[float], r2: list[float]) -> ControllerGains:
        return ControllerGains(np.array(kp), np.array(kd), np.array(r2), 0)

    good = block([1.0, 4.0, 1.0], [2.0, 8.0, 4.0], [0.99, 0.99, 0.99])  # M 1, 4, 4
    spoilt = block([0.01, 4.0, 1.0], [2.0, 80.0, 4.0], [0.9, 0.9, 0.3])  # 100, 400, (not)
    inertia, counts = median_implied_inertia([good, spoilt, good])
    assert inertia is not None and counts.tolist() == [3, 3, 2]
    np.testing.assert_allclose(inertia, [1.0, 4.0, 4.0])
    # two blocks: the median is their mean (the spoilt one is not outvoted)
    inertia, _ = median_implied_inertia([good, spoilt])
    assert inertia is not None and inertia[0] == pytest.approx(50.5)
    # a DOF believed in no block: no inertia, the counts say which
    inertia, counts = median_implied_inertia([spoilt, spoilt])
    assert inertia is None and counts.tolist() == [2, 2, 0]
    inertia, counts = median_implied_inertia([])
    assert inertia is None and counts.size == 0


def test_the_identity_gate_refuses_every_dof_when_no_dof_has_a_high_median() -> None:
    """`identity_gated`: the best DOF's median R² over the blocks against the gate.

    Own controller: two good blocks and one spoilt (R² 0.6 in surge and yaw), and turns that
    spoil yaw in every block (0.3): the best median is 0.99, nothing is gated, and each block's
    own R² still decides where it is believed. Foreign: medians 0.85 / 0.85 / 0.75: every DOF
    gated (R² 0 in every block), so no inertia, though each block alone would be believed.
    """
    def block(r2: list[float]) -> ControllerGains:
        return ControllerGains(np.ones(3), np.full(3, 2.0), np.array(r2), 0)  # M 1 each

    good, spoilt, turning = block([0.99, 0.99, 0.99]), block([0.6, 0.99, 0.6]), \
        block([0.99, 0.98, 0.3])
    for own in ([good, spoilt, good], [turning, turning, good]):
        blocks, gated = identity_gated(own, 0.95)
        assert gated is False and blocks == own
    assert median_implied_inertia([turning, turning, good])[1].tolist() == [3, 3, 1]
    foreign = [block([0.85, 0.8, 0.7]), block([0.9, 0.85, 0.75]), block([0.8, 0.87, 0.96])]
    blocks, gated = identity_gated(foreign, 0.95)
    assert gated is True
    np.testing.assert_array_equal([b.r_squared for b in blocks], np.zeros((3, 3)))
    inertia, counts = median_implied_inertia(blocks)
    assert inertia is None and counts.tolist() == [0, 0, 0]
    assert median_implied_inertia(foreign)[1].tolist() == [3, 3, 3]  # ungated: all believed
    assert identity_gated(foreign, 0.85)[1] is False  # 0.85 reaches
    # off, or nothing to judge
    assert identity_gated(foreign, 0.0)[0] == foreign
    assert identity_gated([], 0.95) == ([], False)
    assert identity_gated(foreign[:2], 0.95)[1] is False  # no majority
    # a NaN R² counts as 0 (median of 0, 0.99, 0.99 is 0.99; of NaN, NaN, 0.99 is 0)
    nan = block([math.nan, math.nan, math.nan])
    assert identity_gated([nan, good, good], 0.95)[1] is False
    assert identity_gated([nan, nan, good], 0.95)[1] is True


def test_two_blocks_far_apart_are_not_believed_with_a_pair_ratio() -> None:
    """``pair_ratio``: a DOF exactly two blocks believe, inertias further apart, is not read.

    good: M = 1, 4, 4; spoilt: 100, 400 (not believed in yaw). With pair_ratio 3, surge and sway
    (100× apart) are believed by neither of the two blocks, so no inertia, and the medians are
    NaN there; yaw (one block) stands. Two blocks 1.5× apart are read as before (their mean),
    and with three blocks the median outvotes the spoilt one whatever the ratio.
    """
    def block(kp: list[float], kd: list[float], r2: list[float]) -> ControllerGains:
        return ControllerGains(np.array(kp), np.array(kd), np.array(r2), 0)

    good = block([1.0, 4.0, 1.0], [2.0, 8.0, 4.0], [0.99, 0.99, 0.99])  # M 1, 4, 4
    spoilt = block([0.01, 4.0, 1.0], [2.0, 80.0, 4.0], [0.9, 0.9, 0.3])  # 100, 400, (not)
    near = block([1.0, 4.0, 1.0], [2.0 * math.sqrt(1.5), 8.0, 4.0], [0.99, 0.99, 0.99])
    inertia, counts = median_implied_inertia([good, spoilt], pair_ratio=3.0)
    assert inertia is None and counts.tolist() == [0, 0, 1]
    partial, freq = believed_medians([good, spoilt], pair_ratio=3.0)
    assert math.isnan(partial[0]) and math.isnan(partial[1]) and partial[2] == 4.0
    assert math.isnan(freq[0]) and freq[2] == pytest.approx(0.5)
    assert median_natural_freq([good, spoilt], pair_ratio=3.0) is None
    inertia, counts = median_implied_inertia([good, near], pair_ratio=3.0)
    assert inertia is not None and counts.tolist() == [2, 2, 2]
    np.testing.assert_allclose(inertia, [1.25, 4.0, 4.0])  # mean of 1 and 1.5 in surge
    inertia, counts = median_implied_inertia([good, spoilt, good], pair_ratio=3.0)
    assert inertia is not None and counts.tolist() == [3, 3, 2]
    np.testing.assert_allclose(inertia, [1.0, 4.0, 4.0])


def test_a_pd_law_faster_than_the_wave_band_is_not_believed() -> None:
    """ω_n = 2 Kp / Kd (= √(Kp / M), M = Kd² / (4 Kp)) at or above the bound: not believed.

    The MSS PID's ω_n = 0.1 / 0.1 / 0.15 rad/s (ζ = 1) passes a bound of 0.8 rad/s (ω0 of
    onedof_feedback × ``MAX_NATURAL_FREQ_RATIO``) and fails one of 0.12 in yaw only.
    """
    eta = _lf_track(1)
    nu = body_velocity(eta, H)
    gains = fit_controller_gains(eta, nu, _pid_thrust(eta, nu, 1.0), H)
    np.testing.assert_allclose(2.0 * gains.stiffness / gains.damping, BANDWIDTH, rtol=0.05)
    assert gains.believed(0.8).tolist() == [True, True, True]
    assert gains.believed(0.12).tolist() == [True, True, False]
    assert gains.implied_inertia(0.12) is None
    assert gains.implied_inertia(0.8) is not None
    block = ControllerGains(np.array([4.0]), np.array([1.0]), np.array([0.9]), 0)  # ω_n 8
    assert median_implied_inertia([block], 8.0)[0] is None  # at the bound: not believed
    inertia, counts = median_implied_inertia([block], 8.01)
    assert inertia is not None and counts.tolist() == [1]
    np.testing.assert_allclose(inertia, [1.0 / 16.0])  # Kd² / (4 Kp)


@pytest.mark.parametrize('bad', ['nan', 'shape', 'short', 'sample_time'])
def test_bad_input_is_refused_with_a_message(bad: str) -> None:
    eta = _lf_track(6)
    nu, tau = body_velocity(eta, H), np.zeros_like(eta)
    h = H
    if bad == 'nan':
        eta[5, 0] = np.nan
    elif bad == 'shape':
        tau = tau[:, :2]
    elif bad == 'short':
        eta, nu, tau = eta[:50], nu[:50], tau[:50]
    else:
        h = 0.0
    with pytest.raises(ValueError, match='must|too few'):
        fit_controller_gains(eta, nu, tau, h)


def test_difference_velocity_of_a_ramp_is_the_first_order_response() -> None:
    """η = V t: v_k = V (1 − (1 − α)^k), α = 1 − e^{−h/T_v}; ν = R(ψ)ᵀ v."""
    h, filter_time, heading = 0.5, 2.0, 0.7
    rate = np.array([0.3, -0.2, 0.0])  # m/s, m/s, rad/s
    k = np.arange(40)
    eta = np.array([1.0, 2.0, heading]) + k[:, None] * h * rate
    alpha = 1.0 - math.exp(-h / filter_time)
    earth = rate * (1.0 - (1.0 - alpha) ** k)[:, None]
    c, s = math.cos(heading), math.sin(heading)
    body = np.column_stack([c * earth[:, 0] + s * earth[:, 1], -s * earth[:, 0] + c * earth[:, 1],
                            earth[:, 2]])
    np.testing.assert_allclose(difference_velocity(eta, h, filter_time), body, atol=1e-12)
    np.testing.assert_allclose(difference_velocity(eta[:, :1], h, filter_time), earth[:, :1],
                               atol=1e-12)
    for bad in ((0.0, 1.0), (h, 0.0), (h, math.nan)):
        with pytest.raises(ValueError, match='must be finite and > 0'):
            difference_velocity(eta, *bad)


def test_difference_velocity_is_the_simulators_pid_velocity() -> None:
    eta = _lf_track(9, m=200, heading=1.0)
    gains = gains_from_bandwidth(MASS, BANDWIDTH)
    state = PidState()
    velocity = np.zeros_like(eta)
    for k in range(eta.shape[0]):
        _, state = pid_step(state, gains, eta[k], np.zeros(3), H)
        velocity[k] = earth_to_body(eta[k:k + 1], state.velocity_earth[None, :], 3)[0]
    np.testing.assert_allclose(difference_velocity(eta, H, gains.velocity_filter_time),
                               velocity, atol=1e-12)


@pytest.mark.parametrize('filter_time', [1.0, 3.0, 0.4])
def test_a_pid_that_differentiates_the_pose_is_read_on_its_own_difference(filter_time: float
                                                                          ) -> None:
    """The PID's D term on its own difference of a pose with wave leftovers, T_v found.

    On the twist the PD law explains little and reads the inertia wrong; on the difference
    with the grid and the search over T_v (1 s on the grid, 3 s and 0.4 s between its points)
    it explains everything and reads T_v and the inertia.
    """
    eta = _lf_track(10)
    leftover = np.random.default_rng(10).standard_normal(eta.shape) * np.array([0.05, 0.05,
                                                                                   0.001])
    pose = eta + leftover  # what the controller is given
    twist = body_velocity(eta, H)  # a smooth twist published with it
    design = gains_from_bandwidth(MASS, BANDWIDTH, 1.0, velocity_filter_time=filter_time)
    state = PidState()
    tau = np.zeros_like(pose)
    for k in range(pose.shape[0]):
        tau[k], state = pid_step(state, design, pose[k], np.array([0.0, 0.0, pose[0, 2]]), H)
    on_twist = read_controller_gains(pose, twist, tau, H)
    assert on_twist.difference_time == 0.0 and np.all(on_twist.r_squared < 0.9)
    either = read_controller_gains(pose, twist, tau, H, difference_times=DIFFERENCE_TIMES)
    assert either.difference_time == pytest.approx(filter_time, rel=0.02)
    assert np.all(either.r_squared > 0.999)
    np.testing.assert_allclose(either.damping, design.kd, rtol=0.03)
    inertia = either.implied_inertia()
    assert inertia is not None
    np.testing.assert_allclose(inertia, MASS, rtol=0.05)
    # a PID on the published twist is still read on the twist, to the bit
    on_published = _pid_thrust(pose, twist, 1.0)
    kept = read_controller_gains(pose, twist, on_published, H, difference_times=DIFFERENCE_TIMES)
    plain = fit_controller_gains(pose, twist, on_published, H)
    assert kept.difference_time == 0.0 and kept.shift == plain.shift
    for name in ('stiffness', 'damping', 'r_squared'):
        np.testing.assert_array_equal(getattr(kept, name), getattr(plain, name))


def test_the_difference_filter_is_warmed_up_on_the_lead() -> None:
    """``lead`` rows before the stretch read only warm the difference's filter.

    A read from the middle of a run then matches the controller, whose filter was running.
    """
    eta = _lf_track(11) + np.random.default_rng(11).standard_normal((1500, 3)) * \
        np.array([0.05, 0.05, 0.001])
    twist = body_velocity(eta, H)
    tau = _pid_thrust(eta, None, 1.0)
    cold = read_controller_gains(eta[600:], twist[600:], tau[600:], H, difference_times=(1.0,))
    warm = read_controller_gains(eta[400:], twist[600:], tau[600:], H, difference_times=(1.0,),
                                 lead=200)
    assert warm.r_squared.min() > 0.9999 > cold.r_squared.min()
    inertia = warm.implied_inertia()
    assert inertia is not None
    np.testing.assert_allclose(inertia, MASS, rtol=0.03)
    for bad in ({'difference_times': (2.0, 1.0)}, {'difference_times': (0.0,)},
                {'lead': -1}, {'lead': 1500}):
        with pytest.raises(ValueError, match='difference_times|lead'):
            read_controller_gains(eta, twist, tau, H, **bad)  # type: ignore[arg-type]


def test_inputs_are_not_modified() -> None:
    eta = _lf_track(7)
    nu = body_velocity(eta, H)
    tau = _pid_thrust(eta, nu, 1.0)
    copies = eta.copy(), nu.copy(), tau.copy()
    fit_controller_gains(eta, nu, tau, H)
    for before, after in zip(copies, (eta, nu, tau), strict=True):
        np.testing.assert_array_equal(before, after)


def test_the_damping_correction_recovers_the_inertia_of_a_pid_that_takes_the_damping_off() -> None:
    """Kd = 2 ω M − D (the MSS PID): Kd²/(4 Kp) is M (1 − D/(2 ω M))²; corrected, M exactly.

    The supply vessel's yaw (M 4.45e9 kg·m², D/M = 1/11.6 s, ω_n 0.2 rad/s) reads 0.61 M.
    """
    mass = np.array([6.7644e6, 1.13412e7, 4.4524e9])
    rate = np.array([1 / 87.8, 1 / 44.5, 1 / 11.6])  # D_ii / M_ii [1/s]
    omega = np.array([0.1, 0.1, 0.2])
    gains = gains_from_bandwidth(mass, omega, 1.0, rate * mass)
    block = ControllerGains(gains.kp, gains.kd, np.ones(3), 0)
    read = block.inertia_per_dof()
    np.testing.assert_allclose(read / mass, (1.0 - rate / (2.0 * omega)) ** 2, rtol=1e-12)
    assert read[2] / mass[2] == pytest.approx(0.61, abs=0.01)
    np.testing.assert_allclose(block.natural_freq(), 2.0 * gains.kp / gains.kd)
    np.testing.assert_allclose(damping_corrected_inertia(read, block.natural_freq(), rate), mass,
                               rtol=1e-12)
    # no damping (or none known): the read as it is
    np.testing.assert_array_equal(damping_corrected_inertia(read, block.natural_freq(),
                                                            [0.0, -1.0, np.nan]), read)
    # a rate above half the read's ω_n: no inertia makes the loop critical; clipped (× 4)
    np.testing.assert_allclose(damping_corrected_inertia([1.0], [0.2], [0.5]), [4.0])
    with pytest.raises(ValueError, match='one entry per DOF'):
        damping_corrected_inertia(read, block.natural_freq()[:2], rate)


def test_the_fitted_damping_scale_recovers_the_inertia_of_a_pid_that_takes_the_damping_off(
        ) -> None:
    """Kd = 2 ω M − D: a fit with the read gain 1/M_r finds f = D / M_r; the scale is M / M_r.

    (1 + f / (2 ω_r))² = (1 + D / Kd)² = M / M_r exactly (Kd = 2 ω_r M_r), and f / scale = D / M,
    the vessel's own rate: the supply vessel's yaw read at 0.51 M_33 (ω_n 0.15 rad/s here) comes
    back to M_33.
    """
    damping = np.array([7.7e4, 2.55e5, 3.85e8])  # D_ii of the supply vessel [N·s/m, N·m·s]
    design = gains_from_bandwidth(MASS, BANDWIDTH, 1.0, damping)
    read = ControllerGains(design.kp, design.kd, np.ones(3), 0)
    m_r = read.inertia_per_dof()
    fitted_rate = damping / m_r  # what a fit with the read gain finds for the damping force D
    scale = fitted_damping_scale(read.natural_freq(), fitted_rate)
    np.testing.assert_allclose(m_r * scale, MASS, rtol=1e-12)
    np.testing.assert_allclose(fitted_rate / scale, damping / MASS, rtol=1e-12)
    np.testing.assert_allclose(m_r / MASS, (1.0 - damping / (2.0 * BANDWIDTH * MASS)) ** 2,
                               rtol=1e-12)  # the read's M (1 − D / (2 ω M))²: yaw 0.51 here
    # a read of a PID that keeps Kd = 2 ω M finds f = D / M and is scaled by (1 + D/(2ωM))²
    plain = gains_from_bandwidth(MASS, BANDWIDTH, 1.0)
    scale = fitted_damping_scale(2.0 * plain.kp / plain.kd, damping / MASS)
    np.testing.assert_allclose(scale, (1.0 + damping / (2.0 * BANDWIDTH * MASS)) ** 2)
    # no damping, a negative or non-finite rate or frequency: no correction
    np.testing.assert_array_equal(
        fitted_damping_scale([0.1, np.nan, 0.1, -0.1], [0.0, 0.05, -0.02, 0.05]), np.ones(4))
    with pytest.raises(ValueError, match='one entry per DOF'):
        fitted_damping_scale([0.1, 0.1], [0.01])


def test_the_median_natural_frequency_is_over_the_believed_blocks_only() -> None:
    good = ControllerGains(np.array([1.0, 4.0]), np.array([10.0, 20.0]), np.ones(2), 0)
    other = ControllerGains(np.array([2.0, 4.0]), np.array([10.0, 40.0]), np.ones(2), 0)
    spoilt = ControllerGains(np.array([9.0, 9.0]), np.array([1.0, 1.0]), np.zeros(2), 0)
    freq = median_natural_freq([good, other, spoilt])
    assert freq is not None
    np.testing.assert_allclose(freq, [0.3, 0.3])  # medians of (0.2, 0.4) and (0.4, 0.2)
    assert median_natural_freq([spoilt]) is None
    assert median_natural_freq([]) is None


def test_believed_medians_are_nan_in_a_dof_no_block_believes() -> None:
    """The medians per believed DOF even where `median_implied_inertia` gives None."""
    good = ControllerGains(np.array([1.0, 4.0, 1.0]), np.array([2.0, 8.0, 4.0]),
                           np.array([0.99, 0.99, 0.2]), 0)
    other = ControllerGains(np.array([1.0, 2.0, 1.0]), np.array([4.0, 8.0, 4.0]),
                            np.array([0.99, 0.99, 0.1]), 0)
    assert median_implied_inertia([good, other])[0] is None
    inertia, freq = believed_medians([good, other])
    np.testing.assert_allclose(inertia[:2], [2.5, 6.0])  # means of (1, 4) and (4, 8)
    np.testing.assert_allclose(freq[:2], [0.75, 0.75])  # of (1, 0.5) and (1, 0.5)
    assert math.isnan(inertia[2]) and math.isnan(freq[2])
    empty = believed_medians([])
    assert empty[0].size == 0 and empty[1].size == 0
