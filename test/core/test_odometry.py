"""LF odometry (core.odometry): velocity, calibrated covariance, dead reckoning, reacquisition."""
from __future__ import annotations

import dataclasses
import math
from typing import cast

import numpy as np
import pytest

from lf_predictor_ros.core import odometry as odometry_module
from lf_predictor_ros.core.error_models import (
    ErrorModel,
    calibrate,
)
from lf_predictor_ros.core.filters import design_wave_filter
from lf_predictor_ros.core.lf_dynamics import DeadReckoner, DriftCurve, LfDynamics, VesselMemory
from lf_predictor_ros.core.odometry import (
    TWIN_LEVEL_FACTOR,
    TWIN_LEVEL_TIME,
    UNESTIMATED_VARIANCE,
    LfOdometry,
    OdometryEstimate,
    band_excess,
    excursion_covariance,
    thrust_statistics_step,
)
from lf_predictor_ros.core.odometry_params import OdometryParams
from lf_predictor_ros.core.published_columns import Published
from lf_predictor_ros.core.span_mean import SpanMean

H = 1.0


def _hold_memory(drift_std_at_60: float = 1.0) -> VesselMemory:
    horizons = np.arange(1.0, 61.0)
    ms = np.tile((drift_std_at_60 * horizons / 60.0) ** 2, (3, 1)).T
    return VesselMemory(None, 'hold', DriftCurve(horizons, ms, 1e-4 * ms, 10), {}, 'test',
                        np.full(3, 1e-3))


def _dp_memory(model: LfDynamics, reckoner: str = 'model') -> VesselMemory:
    """A DP-controlled 3-DOF vessel memory on ``model``, its drift std 1 m at 60 s."""
    horizons = np.arange(1.0, 61.0)
    ms = np.tile((horizons / 60.0) ** 2, (3, 1)).T
    return VesselMemory(model, cast(DeadReckoner, reckoner),
                        DriftCurve(horizons, ms, 1e-4 * ms, 10), {}, 'test', np.full(3, 1e-3),
                        dp_controlled=True)


def _track_line(odo: LfOdometry, speed: float, heading: float, seconds: int,
                rng: np.random.Generator | None = None, noise: float = 0.0) -> None:
    for k in range(seconds):
        t = float(k)
        pose = np.array([speed * t * math.cos(heading), speed * t * math.sin(heading), heading])
        if rng is not None:
            pose[:2] += noise * rng.normal(size=2)
        odo.track(t, pose, np.zeros(3))


def test_twist_is_the_body_velocity_of_a_straight_line() -> None:
    """Constant 0.5 m/s along a heading of 135°: twist → [0.5, 0, 0] in the body frame."""
    odo = LfOdometry(3, H)
    _track_line(odo, 0.5, math.radians(135.0), 600)
    out = odo.track(600.0, [0.5 * 600 * math.cos(math.radians(135)),
                            0.5 * 600 * math.sin(math.radians(135)), math.radians(135)],
                    np.zeros(3))
    assert out is not None
    np.testing.assert_allclose(out.twist, [0.5, 0.0, 0.0], atol=2e-3)
    assert out.mode == 'tracking' and not out.calibrated


def test_covariance_is_calibrated_from_target_comparison() -> None:
    """Published poses with a known ±0.2 m north error against the targets.

    The covariance is the error's second moment times the scale: the squared error is constant,
    so it does not grow with the velocity (no lag part) once no lag prior is assumed (with the
    default prior of 1.2 s, lag scale 8, the window's little motion leaves +6 %).
    """
    odo = LfOdometry(3, H, OdometryParams(pose_cov_scale=2.0, pose_lag_prior=0.0))
    times = np.arange(300.0)
    truth = np.column_stack([np.zeros(300), np.zeros(300), np.zeros(300)])
    rng = np.random.default_rng(0)
    err = 0.2 * rng.choice([-1.0, 1.0], size=300)
    for k in range(300):
        odo.track(times[k], truth[k] + [err[k], 0.0, 0.0], np.zeros(3))
    odo.learn(times, truth, None)
    out = odo.track(300.0, [0.0, 0.0, 0.0], np.zeros(3), 'fallback')
    assert out is not None and out.calibrated
    assert out.pose_cov[0, 0] == pytest.approx(2.0 * 0.04, rel=0.02)
    assert out.pose_cov[1, 1] == pytest.approx(0.0, abs=1e-12)


def test_the_published_columns_hold_the_published_records() -> None:
    """`published_columns` (the memory job's history) gives `published`'s records to the bit."""
    odo = LfOdometry(3, H, OdometryParams(pose_twin_gain=1.0, pose_lag_prior=0.0))
    rng = np.random.default_rng(5)
    times = np.arange(200.0)
    poses = np.column_stack([0.01 * times, -0.02 * times, 0.001 * times]) + \
        rng.normal(0.0, 0.1, (200, 3))
    for k in range(200):
        odo.track(times[k], poses[k], rng.normal(0.0, 1e4, 3),
                  'network' if k % 3 else 'fallback', twin_offset=rng.normal(0.0, 0.1, 3))
        if k == 120:  # calibrated from here on: the twin excess is kept with each record
            odo.learn(times[:100], poses[:100], None)
    records, columns = odo.published(), odo.published_columns()
    assert len(records) == len(columns) == 200
    assert sum(r.twin_excess is not None for r in records) == 79
    back = columns.records()
    for a, b in zip(back, records, strict=True):
        assert (a.stamp, a.source) == (b.stamp, b.source)
        for name in ('pose', 'twist', 'accel', 'lag'):
            assert np.array_equal(getattr(a, name), getattr(b, name))
        assert (a.twin_excess is None) == (b.twin_excess is None)
        assert a.twin_excess is None or np.array_equal(a.twin_excess, b.twin_excess)


def test_learn_uses_every_calibration_setting() -> None:
    """`LfOdometry.learn` equals `calibrate` with the odometry's own settings.

    A 0.05 m north wave at 0.8 rad/s on a 0.01 m/s ramp, published as the ramp itself: the
    likelihood fit, the reference cutoffs (× ω0 0.8 rad/s: 0.5 ω0 = 0.4 rad/s) and the
    attenuation term with the targets' filter reach the calibration; without ω0 the cutoffs
    are off, as on the worker (`lf_state._learn`).
    """
    n = 400
    times = np.arange(float(n)) * H
    ramp = np.column_stack([0.01 * times, np.zeros(n), np.zeros(n)])
    targets = ramp + np.column_stack([0.05 * np.sin(0.8 * times), np.zeros(n), np.zeros(n)])
    sos = design_wave_filter(0.8, H, notch_zeta=1.3)
    params = OdometryParams(twist_likelihood_fit=True, twist_reference_cutoff=0.5,
                            pose_reference_cutoff=0.5, twist_attenuation=True)
    holds = []
    for omega in (0.8, None):
        odo, twin = LfOdometry(3, H, params), LfOdometry(3, H, params)
        for k in range(n):
            odo.track(times[k], ramp[k], np.zeros(3))
            twin.track(times[k], ramp[k], np.zeros(3))
        history = odo.published()
        odo.learn(times, targets, None, omega, sos)
        edge = 0.0 if omega is None else 0.4
        expected = calibrate(history, times, targets, 3, H, params.min_calibration_samples,
                             params.pose_lag_prior, params.pose_twin_fit, edge, edge, True, sos)
        assert expected is not None
        twin.apply_learned(None, expected)
        got, want = odo.track(float(n), ramp[-1], np.zeros(3)), \
            twin.track(float(n), ramp[-1], np.zeros(3))
        assert got is not None and want is not None and got.calibrated
        np.testing.assert_array_equal(got.pose_cov, want.pose_cov)
        np.testing.assert_array_equal(got.twist_cov, want.twist_cov)
        holds.append((expected[0]['all'].hold[0, 0], expected[1]['all'].hold[0, 0]))
    # the settings matter here: with ω0 the pose is fitted against the wave-free ramp
    # (its error 0, the floor) and the twist's holding part carries the attenuation term
    assert holds[0][0] < 0.1 * holds[1][0]
    assert holds[0][1] != holds[1][1]


def test_calibration_fits_the_heading_speed_gain_on_every_source() -> None:
    """calibrate(..., heading_speed=True): heading errors √(1e-4 + 0.01 s²) against the targets.

    The pooled K ≈ 0.01 is shared by both sources (each keeps its own holding part); without
    the option K is 0; the odometry's learn() passes pose_heading_speed_lag.
    """
    n = 800
    times = np.arange(float(n))
    targets = np.zeros((n, 3))
    speed = np.zeros(n)
    speed[200:500] = np.linspace(0.0, 0.4, 300)
    history = []
    for k in range(n):
        error = np.array([0.1, 0.1, math.sqrt(1e-4 + 0.01 * speed[k] ** 2)])
        history.append(Published(float(k), targets[k] + error, np.zeros(3),
                                 'network' if k % 2 else 'fallback', np.zeros(3),
                                 np.array([speed[k], 0.0, 0.0])))
    fitted = calibrate(history, times, targets, 3, H, 60, 0.0, heading_speed=True)
    plain = calibrate(history, times, targets, 3, H, 60, 0.0)
    assert fitted is not None and plain is not None
    for source in ('all', 'network', 'fallback'):
        assert math.isclose(fitted[0][source].speed_gain, 0.01, rel_tol=1e-6)
        assert math.isclose(fitted[0][source].hold[2, 2], 1e-4, rel_tol=1e-6)
        assert plain[0][source].speed_gain == 0.0
    odo = LfOdometry(3, H, OdometryParams(pose_heading_speed_lag=True))
    odo._history.extend(history)
    odo.learn(times, targets, None)
    assert odo._pose_cov is not None
    assert math.isclose(odo._pose_cov['all'].speed_gain, 0.01, rel_tol=1e-6)


def test_published_pose_covariance_adds_the_untaken_twin_offsets_excess() -> None:
    """P = pose_cov_scale · Σ_hold + pose_twin_gain · diag(max(0, m² − 2 L)), L the level of m².

    L starts at the first offset (here zeros, a vessel holding station), then low-passes m²
    over TWIN_LEVEL_TIME: a new offset m counts fully once, then less as L grows; gain 0 (the
    default) adds nothing; no offset given: no term.
    """
    hold = np.diag([0.01, 0.04, 1e-4])
    model = ErrorModel(moment=hold, hold=hold, gain=np.zeros(3))
    twist_model = ErrorModel(moment=np.eye(3), hold=np.eye(3), gain=np.zeros(3))
    m2 = np.square([0.5, -0.2, 0.01])
    a = H / TWIN_LEVEL_TIME
    for gain in (0.0, 3.0):
        odo = LfOdometry(3, H, OdometryParams(pose_cov_scale=2.0, pose_twin_gain=gain,
                                              pose_twin_fit=False))  # C = 1
        odo.apply_learned(None, ({'all': model}, {'all': twist_model}))
        for k in range(3):  # the level starts at 0
            plain = odo.track(float(k), [0.0, 0.0, 0.0], np.zeros(3), 'network', np.zeros(3))
            assert plain is not None
            np.testing.assert_allclose(np.diag(plain.pose_cov), 2.0 * np.diag(hold))
        first = odo.track(3.0, [0.0, 0.0, 0.0], np.zeros(3), 'network', np.sqrt(m2))
        second = odo.track(4.0, [0.0, 0.0, 0.0], np.zeros(3), 'network', np.sqrt(m2))
        assert first is not None and second is not None
        np.testing.assert_allclose(np.diag(first.pose_cov), 2.0 * np.diag(hold) + gain * m2)
        level = a * m2  # after the first offset
        np.testing.assert_allclose(np.diag(second.pose_cov),
                                   2.0 * np.diag(hold) + gain * (m2 - TWIN_LEVEL_FACTOR * level))
        np.testing.assert_array_equal(second.pose_cov - np.diag(np.diag(second.pose_cov)), 0.0)
        without = odo.track(5.0, [0.0, 0.0, 0.0], np.zeros(3))  # no offset given: no term
        assert without is not None
        np.testing.assert_allclose(np.diag(without.pose_cov), 2.0 * np.diag(hold))
        with pytest.raises(ValueError, match='twin_offset'):
            odo.track(6.0, [0.0, 0.0, 0.0], np.zeros(3), 'network', [0.5, 0.0])
    with pytest.raises(ValueError, match='pose_twin_gain must be a finite number >= 0'):
        OdometryParams(pose_twin_gain=-1.0)


def test_fitted_twin_gain_scales_the_published_excess() -> None:
    """pose_twin_fit: P = scale · Σ_hold + pose_twin_gain · C ∘ x; no C fitted: no term."""
    hold = np.diag([0.01, 0.04, 1e-4])
    twist_model = ErrorModel(moment=np.eye(3), hold=np.eye(3), gain=np.zeros(3))
    m2 = np.square([0.5, -0.2, 0.01])
    params = OdometryParams(pose_cov_scale=2.0, pose_twin_gain=3.0, pose_twin_fit=True)
    for twin_gain in (np.array([0.5, 0.0, 2.0]), None):
        model = ErrorModel(moment=hold, hold=hold, gain=np.zeros(3), twin_gain=twin_gain)
        odo = LfOdometry(3, H, params)
        odo.apply_learned(None, ({'all': model}, {'all': twist_model}))
        odo.track(0.0, [0.0, 0.0, 0.0], np.zeros(3), 'network', np.zeros(3))  # the level: 0
        out = odo.track(1.0, [0.0, 0.0, 0.0], np.zeros(3), 'network', np.sqrt(m2))
        assert out is not None
        c = np.zeros(3) if twin_gain is None else twin_gain
        np.testing.assert_allclose(np.diag(out.pose_cov), 2.0 * np.diag(hold) + 3.0 * c * m2)
        assert odo.published()[-1].twin_excess is not None


def test_published_pose_covariance_grows_with_the_lf_velocity() -> None:
    """Known error model: P = pose_cov_scale · (Σ_hold + pose_lag_scale · T² w²), w = R(ψ) ν."""
    params = OdometryParams(pose_cov_scale=2.0, pose_lag_scale=3.0)
    odo = LfOdometry(3, H, params)
    hold = np.diag([0.01, 0.04, 1e-4])
    model = ErrorModel(moment=hold, hold=hold, gain=np.array([9.0, 4.0, 16.0]))
    cal = {'all': model, 'network': model}
    twist_model = ErrorModel(moment=np.eye(3), hold=np.eye(3), gain=np.zeros(3))
    odo.apply_learned(None, (cal, {'all': twist_model}))
    heading = math.radians(30.0)
    _track_line(odo, 0.4, heading, 300)
    out = odo.track(300.0, [0.4 * 300 * math.cos(heading), 0.4 * 300 * math.sin(heading),
                            heading], np.zeros(3))
    assert out is not None and out.calibrated
    c, s = math.cos(out.pose[2]), math.sin(out.pose[2])  # w = [R(ψ) [u, v], r]
    rates = np.array([c * out.twist[0] - s * out.twist[1], s * out.twist[0] + c * out.twist[1],
                      out.twist[2]])
    np.testing.assert_allclose(rates[:2], [0.4 * math.cos(heading), 0.4 * math.sin(heading)],
                               atol=2e-3)
    expected = 2.0 * (hold + 3.0 * np.diag(model.gain * rates ** 2))
    np.testing.assert_allclose(out.pose_cov, expected, rtol=1e-12, atol=1e-15)
    assert out.pose_cov[0, 0] == pytest.approx(2.0 * (0.01 + 27.0 * 0.12), rel=0.01)


def test_pose_lag_memory_holds_the_peak_rate_and_lets_it_decay() -> None:
    """pose_lag_memory T: after the motion stops, w² is the peak decayed by exp(−Δt / T)."""
    params = OdometryParams(pose_cov_scale=2.0, pose_lag_scale=3.0, pose_lag_memory=100.0)
    odo = LfOdometry(3, H, params)
    hold = np.diag([0.01, 0.04, 1e-4])
    model = ErrorModel(moment=hold, hold=hold, gain=np.array([9.0, 4.0, 16.0]))
    twist_model = ErrorModel(moment=np.eye(3), hold=np.eye(3), gain=np.zeros(3))
    odo.apply_learned(None, ({'all': model}, {'all': twist_model}))
    _track_line(odo, 0.4, 0.0, 300)  # north at 0.4 m/s, then still at the last pose
    stop = 0.4 * 299
    outs = [odo.track(float(t), [stop, 0.0, 0.0], np.zeros(3)) for t in range(300, 361)]
    last = outs[-1]
    assert last is not None and abs(last.twist[0]) < 1e-3  # the velocity itself is gone
    held = 0.4 ** 2 * math.exp(-60.0 / 100.0)  # the peak (≈ at t = 299) decayed over 60 s
    assert last.pose_cov[0, 0] == pytest.approx(2.0 * (0.01 + 27.0 * held), rel=0.02)
    lags = [p.lag[0] for p in odo.published()]
    assert lags[-1] == pytest.approx(math.sqrt(held), rel=0.01)
    assert all(b <= a for a, b in zip(lags[300:], lags[301:], strict=False))  # decaying
    # without the memory the same track publishes the holding variance again
    plain = LfOdometry(3, H, OdometryParams(pose_cov_scale=2.0, pose_lag_scale=3.0))
    plain.apply_learned(None, ({'all': model}, {'all': twist_model}))
    _track_line(plain, 0.4, 0.0, 300)
    out = [plain.track(float(t), [stop, 0.0, 0.0], np.zeros(3)) for t in range(300, 361)][-1]
    assert out is not None and out.pose_cov[0, 0] == pytest.approx(0.02, rel=1e-3)


def test_published_twist_covariance_grows_with_the_acceleration() -> None:
    """Known twist model: P = twist_cov_scale · (Σ_hold + K² a²), a the low-passed twist change.

    North motion with a constant acceleration of 0.002 m/s² from rest: after 200 s a → 0.002
    (twist_accel_time 10 s), so P_uu = 0.5 · (1e-4 + 100 · 4e-6) = 2.5e-4; at constant speed
    (a → 0) it is 0.5e-4.
    """
    params = OdometryParams(twist_cov_scale=0.5, twist_accel_time=10.0)
    hold = 1e-4 * np.eye(3)
    pose_model = ErrorModel(moment=hold, hold=hold, gain=np.zeros(3))
    twist_model = ErrorModel(moment=hold, hold=hold, gain=np.full(3, 100.0))
    for accel, expected in ((0.002, 2.5e-4), (0.0, 0.5e-4)):
        odo = LfOdometry(3, H, params)
        odo.apply_learned(None, ({'all': pose_model}, {'all': twist_model}))
        out = None
        for k in range(201):
            north = 0.5 * accel * k ** 2 + (0.0 if accel else 0.1 * k)
            out = odo.track(float(k), [north, 0.0, 0.0], np.zeros(3))
        assert out is not None and out.calibrated
        assert out.twist_cov[0, 0] == pytest.approx(expected, rel=0.03)
        assert out.twist_cov[1, 1] == pytest.approx(0.5e-4, rel=1e-6)


def test_one_dof_marks_the_other_entries_unestimated() -> None:
    odo = LfOdometry(1, H)
    out = odo.track(0.0, [1.0, 7.0, 3.0], np.zeros(3))
    assert out is not None
    np.testing.assert_array_equal(out.pose, [1.0, 7.0, 3.0])
    assert out.pose_cov[1, 1] == UNESTIMATED_VARIANCE == out.twist_cov[2, 2]
    assert out.twist[1] == 0.0 and out.twist[2] == 0.0


def test_dead_reckoning_grows_covariance_then_stops_at_the_timeout() -> None:
    odo = LfOdometry(3, H, OdometryParams(dead_reckoning_timeout=60.0))
    _track_line(odo, 0.0, 0.0, 100)
    odo._memory = _hold_memory()  # noqa: SLF001 - a known drift curve
    last = odo.track(100.0, [0.0, 0.0, 0.0], np.zeros(3))
    assert last is not None
    variances = []
    for k in range(1, 61):
        out = odo.coast(100.0 + k, np.zeros(3))
        assert out is not None and out.mode == 'dead_reckoning'
        assert out.dead_reckoning_time == pytest.approx(k)
        variances.append(out.pose_cov[0, 0])
        np.testing.assert_allclose(out.pose, last.pose)  # hold
    assert np.all(np.diff(variances) > 0.0)
    assert variances[-1] == pytest.approx(last.pose_cov[0, 0] + 1.0, rel=1e-6)
    assert odo.coast(161.0, np.zeros(3)) is None
    assert odo.mode == 'lost' and odo.counters['lost'] == 1


def test_constant_velocity_dead_reckoning_continues_the_motion_without_a_step() -> None:
    odo = LfOdometry(3, H)
    _track_line(odo, 0.3, 0.0, 400)
    last = odo.track(400.0, [120.0, 0.0, 0.0], np.zeros(3))
    assert last is not None
    out = odo.coast(430.0, np.zeros(3))
    assert out is not None
    assert out.pose[0] == pytest.approx(120.0 + 0.3 * 30.0, abs=0.05)
    assert out.mode == 'dead_reckoning' and out.reckoner == 'constant_velocity'


def test_forced_model_dead_reckoner_follows_the_thrust() -> None:
    """dead_reckoner 'model' uses the learned model even where the drift test chose 'hold'.

    Surge model u̇ = −u/T + τ/m (T = 100 s, m = 1e6 kg), at rest, 1e4 N: semi-implicit Euler
    at h = 1 s gives u_k = (1 − (1 − h/T)^k) τ T/m and x_k = h Σ u_j; the covariance grows with
    the model's own drift curve (4 × the hold curve here), not the chosen reckoner's.
    """
    horizons = np.arange(1.0, 61.0)
    hold_ms = np.tile((horizons / 60.0) ** 2, (3, 1)).T
    model = LfDynamics(np.diag([-0.01, -0.01, -0.01]), np.diag([1e-6, 1e-6, 1e-9]),
                       np.zeros((3, 3)), np.full(3, 1e-4))
    curves = {'hold': DriftCurve(horizons, hold_ms, 1e-4 * hold_ms, 10),
              'model': DriftCurve(horizons, 4.0 * hold_ms, 1e-4 * hold_ms, 10)}
    memory = VesselMemory(model, 'hold', curves['hold'], {}, 'test', np.full(3, 1e-3),
                          drift_curves=curves)  # type: ignore[arg-type]
    force = np.array([1e4, 0.0, 0.0])
    outs = {}
    for choice in ('auto', 'model'):  # the drift curve alone (no manoeuvre term)
        odo = LfOdometry(3, H, OdometryParams(dead_reckoner=choice,
                                              dead_reckoning_excursion_std=0.0))
        _track_line(odo, 0.0, 0.0, 100)
        odo._memory = memory  # noqa: SLF001 - a known vessel memory
        last = odo.track(100.0, [0.0, 0.0, 0.0], np.zeros(3))
        assert last is not None
        for k in range(1, 61):
            out = odo.coast(100.0 + k, force)
            assert out is not None
        outs[choice] = (out, last)
    held, last = outs['auto']
    assert held.reckoner == 'hold' and held.pose[0] == pytest.approx(last.pose[0])
    reckoned, last = outs['model']
    assert reckoned.reckoner == 'model'
    u = (1.0 - 0.99 ** np.arange(1, 61)) * 1e4 * 100.0 / 1e6
    assert reckoned.pose[0] - last.pose[0] == pytest.approx(u.sum(), rel=0.02)
    assert reckoned.twist[0] == pytest.approx(u[-1], rel=0.02)
    # + the start-velocity uncertainty carried over 60 s (not for 'hold'), heading 0
    expected = 4.0 + 60.0**2 * last.twist_cov[1, 1]
    assert reckoned.pose_cov[1, 1] - last.pose_cov[1, 1] == pytest.approx(expected, rel=1e-6)
    # without a fitted model 'model' falls back to the memory's choice
    odo = LfOdometry(3, H, OdometryParams(dead_reckoner='model'))
    _track_line(odo, 0.0, 0.0, 10)
    odo._memory = _hold_memory()  # noqa: SLF001
    out = odo.coast(11.0, force)
    assert out is not None and out.reckoner == 'hold'
    with pytest.raises(ValueError, match='dead_reckoner'):
        OdometryParams(dead_reckoner='kalman')
    # a thrust gain that was given or implied by the controller (the memory's known_gain) makes
    # 'auto' dead reckon on the model although the memory chose hold; a fitted one does not
    for known, expected_reckoner in (('vessel_inertia', 'model'), ('controller', 'model'),
                                     ('', 'hold')):
        odo = LfOdometry(3, H, OdometryParams(vessel_inertia=(1e6, 1e6, 1e9)))
        _track_line(odo, 0.0, 0.0, 10)
        odo._memory = dataclasses.replace(memory, known_gain=known)  # noqa: SLF001
        out = odo.coast(11.0, force)
        assert out is not None and out.reckoner == expected_reckoner
    for bad in ((1e6, 0.0, 1e9), (1e6, 1e6), (1e6, -1e6, 1e9), (math.inf, 1e6, 1e9)):
        with pytest.raises(ValueError, match='vessel_inertia'):
            OdometryParams(vessel_inertia=bad)
    for bad_time in (-1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match='controller_read_block_time must be a finite'):
            OdometryParams(controller_read_block_time=bad_time)
    assert OdometryParams(controller_read_block_time=300.0).controller_read_block_time == 300.0


def test_reacquisition_inside_the_gate_is_immediate_and_outside_waits() -> None:
    params = OdometryParams(reacquire_time=10.0, reacquire_blend_time=0.0)
    odo = LfOdometry(3, H, params)
    _track_line(odo, 0.0, 0.0, 100)
    odo._memory = _hold_memory(0.5)  # noqa: SLF001
    for k in range(100, 130):
        odo.coast(float(k), np.zeros(3))
    near = odo.track(130.0, [0.1, 0.0, 0.0], np.zeros(3))
    assert near is not None and near.mode == 'tracking'
    assert odo.counters['reacquired'] == 1
    for k in range(131, 160):
        odo.coast(float(k), np.zeros(3))
    held = [odo.track(160.0 + k, [50.0, 0.0, 0.0], np.zeros(3)) for k in range(10)]
    assert all(h is not None and h.mode == 'dead_reckoning' for h in held)
    accepted = odo.track(170.0, [50.0, 0.0, 0.0], np.zeros(3))
    assert accepted is not None and accepted.mode == 'tracking'
    assert accepted.pose[0] == pytest.approx(50.0)
    assert odo.counters['reacquired_outside_gate'] == 1
    assert odo.counters['fixes_held_back'] == 10


def test_reacquisition_blend_has_no_step() -> None:
    odo = LfOdometry(3, H, OdometryParams(reacquire_blend_time=20.0, reacquire_time=0.0))
    _track_line(odo, 0.0, 0.0, 100)
    odo._memory = _hold_memory()  # noqa: SLF001
    for k in range(100, 120):
        odo.coast(float(k), np.zeros(3))
    outputs = [odo.track(120.0 + k, [2.0, 0.0, 0.0], np.zeros(3)) for k in range(25)]
    north = np.array([o.pose[0] for o in outputs if o is not None])
    assert north[0] == pytest.approx(0.0, abs=1e-9)  # starts at the dead-reckoned pose
    assert north[-1] == pytest.approx(2.0)
    assert np.max(np.abs(np.diff(north))) < 2.0 * 1.5 / 20.0 + 1e-9  # smoothstep slope ≤ 1.5


def test_heading_wraps_across_pi_in_outputs_and_innovations() -> None:
    odo = LfOdometry(3, H)
    for k in range(50):
        heading = math.pi - 0.01 + 0.0004 * k  # crosses +π
        out = odo.track(float(k), [0.0, 0.0, math.atan2(math.sin(heading), math.cos(heading))],
                        np.zeros(3))
        assert out is not None and -math.pi < out.pose[2] <= math.pi
    assert out.twist[2] == pytest.approx(0.0004, abs=2e-4)


def test_bad_input_is_refused_with_a_message() -> None:
    odo = LfOdometry(3, H)
    with pytest.raises(ValueError, match='lf_pose'):
        odo.track(0.0, [np.nan, 0.0, 0.0], np.zeros(3))
    with pytest.raises(ValueError, match='force'):
        odo.track(0.0, np.zeros(3), np.zeros(2))
    odo.track(5.0, np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match='older'):
        odo.track(1.0, np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match='dead_reckoning_timeout'):
        OdometryParams(dead_reckoning_timeout=0.0)
    with pytest.raises(ValueError, match='prior_pose_std'):
        OdometryParams(prior_pose_std=(1.0, 1.0))
    with pytest.raises(ValueError, match='pose_lag_memory'):
        OdometryParams(pose_lag_memory=-1.0)
    assert odo.coast(6.0, np.zeros(3)) is not None
    assert LfOdometry(3, H).coast(0.0, np.zeros(3)) is None  # never fixed: nothing to publish


ABSURD_THRUST = np.array([1e308, -1e308, 1e308])  # [N, N, N·m] finite, absurd


def _odometry_on_a_model(force_limit: np.ndarray | None,
                         dp_controlled: bool = False) -> tuple[LfOdometry, LfDynamics]:
    """An odometry tracked 50 s on a line, then given a memory with a simple model."""
    odo = LfOdometry(3, H)
    _track_line(odo, 0.0, 0.0, 50)
    model = LfDynamics(damping=-0.01 * np.eye(3), input_gain=1e-6 * np.eye(3),
                       bias=np.zeros((3, 3)), residual_std=np.full(3, 1e-4))
    memory = _hold_memory()
    limit = np.full(3, np.inf) if force_limit is None else force_limit
    odo._memory = VesselMemory(model, 'model', memory.drift, {}, 'test',  # noqa: SLF001
                               memory.accel_std, limit, dp_controlled=dp_controlled)
    return odo, model


def test_absurd_thrust_never_makes_the_state_non_finite() -> None:
    """A finite but absurd force (1e308 N) through a learned model: counted, state stays finite."""
    odo, model = _odometry_on_a_model(np.array([2e5, 2e5, 2e7]))
    memory = _hold_memory()
    absurd = ABSURD_THRUST
    out = odo.track(50.0, np.zeros(3), absurd)
    assert out is not None and np.all(np.isfinite(out.twist))
    for k in range(51, 60):
        out = odo.coast(float(k), absurd)
        assert out is not None and np.all(np.isfinite(out.pose))
        assert np.all(np.isfinite(out.pose_cov))
    # clipped to the force limit: at most 1e-6 · 2e5 = 0.2 m/s² for 10 s
    assert abs(out.twist[0]) <= 2.0 + 1e-9 and abs(out.pose[0]) <= 20.0
    assert odo.counters['implausible_thrust'] == 10
    # with no limit the model overflows: the state falls back to the last finite pose
    odo._memory = VesselMemory(model, 'model', memory.drift, {}, 'test',  # noqa: SLF001
                               memory.accel_std)
    huge_gain = LfDynamics(damping=-0.01 * np.eye(3), input_gain=1e300 * np.eye(3),
                           bias=np.zeros((3, 3)), residual_std=np.full(3, 1e-4))
    odo._memory = VesselMemory(huge_gain, 'model', memory.drift, {}, 'test',  # noqa: SLF001
                               memory.accel_std)
    out = odo.coast(61.0, absurd)
    assert out is not None and np.all(np.isfinite(out.pose))
    assert odo.counters['numeric_failures'] == 1
    assert odo.is_late(50.0) and not odo.is_late(70.0)


def test_absurd_thrust_without_a_clip_keeps_every_output_finite() -> None:
    """No force limit (the default ``dead_reckoning_force_margin: 0``): outputs stay finite.

    An absurd thrust while tracking and then while dead reckoning leaves every published value
    finite.
    """
    odo, _ = _odometry_on_a_model(None, dp_controlled=True)
    absurd = ABSURD_THRUST
    for k in range(50, 55):
        out = odo.track(float(k), np.zeros(3), absurd)
        assert out is not None and np.all(np.isfinite(out.pose))
        assert np.all(np.isfinite(out.twist)) and np.all(np.isfinite(out.twist_cov))
    for k in range(55, 70):
        out = odo.coast(float(k), absurd)
        assert out is not None and np.all(np.isfinite(out.pose))
        assert np.all(np.isfinite(out.pose_cov)) and np.all(np.isfinite(out.twist))
    assert odo.counters['implausible_thrust'] == 0  # nothing clipped


def test_dead_reckoning_starts_from_the_balance_the_thrust_held() -> None:
    """Under a DP controller the window's mean environment is replaced by the balanced one.

    The memory's model pushes 1e-3 m/s² in surge (its fitted mean environment); while tracking,
    the vessel sat still with 2e3 N of surge thrust (gain 1e-6/kg: 2e-3 m/s²), so the force
    acting then was −2e3 N. Coasting on the same thrust the dead-reckoned pose stays put (the
    window's mean would have moved it 1.7 m in 60 s); 1e3 N more thrust moves it like the
    model's surge response to 1e3 N alone, u_k = (1 − 0.99^k) · 1e3 · 1e-6 · 100 m/s.
    """
    model = LfDynamics(np.diag([-0.01, -0.01, -0.01]), np.diag([1e-6, 1e-6, 1e-9]),
                       np.array([[1e-3, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]),
                       np.full(3, 1e-4))
    horizons = np.arange(1.0, 61.0)
    ms = np.tile((horizons / 60.0) ** 2, (3, 1)).T
    # (chosen 'hold', forced 'model': the tracking twist filter does not use the model, so the
    # twist at rest is 0 and the balance is the thrust's alone)
    memory = VesselMemory(model, 'hold', DriftCurve(horizons, ms, 1e-4 * ms, 10), {}, 'test',
                          np.full(3, 1e-3), dp_controlled=True)
    held = np.array([2e3, 0.0, 0.0])
    for extra, expected in ((0.0, 0.0), (1e3, None)):
        odo = LfOdometry(3, H, OdometryParams(dead_reckoner='model'))
        odo._memory = memory  # noqa: SLF001 - a known vessel memory
        for k in range(200):
            odo.track(float(k), np.zeros(3), held)
        for k in range(1, 61):
            out = odo.coast(200.0 + k, held + np.array([extra, 0.0, 0.0]))
            assert out is not None
        if expected is not None:
            assert abs(out.pose[0]) < 1e-9 and abs(out.pose[1]) < 1e-9
        else:
            # 61 steps of h from the last fix at 199 s (semi-implicit Euler, u_k as above)
            u = (1.0 - 0.99 ** np.arange(1, 62)) * 1e3 * 1e-6 * 100.0
            assert out.pose[0] == pytest.approx(u.sum(), rel=1e-6)
    # without a DP controller (an excited vessel: its thrust accelerates it) the fitted model:
    # 2e3 N + the mean 1e-3 m/s², u_k = (1 − 0.99^k) · 3e-3 · 100 m/s
    odo = LfOdometry(3, H, OdometryParams(dead_reckoner='model'))
    odo._memory = dataclasses.replace(memory, dp_controlled=False)  # noqa: SLF001
    for k in range(200):
        odo.track(float(k), np.zeros(3), held)
    for k in range(1, 61):
        out = odo.coast(200.0 + k, held)
    assert out is not None
    u = (1.0 - 0.99 ** np.arange(1, 62)) * 3e-3 * 100.0
    assert out.pose[0] == pytest.approx(u.sum(), rel=1e-6)


def _surge_memory(damping: float, gain: float) -> VesselMemory:
    """A DP-controlled vessel memory with the surge model u̇ = −d u + g τ (no environment)."""
    model = LfDynamics(np.diag([-damping, -0.01, -0.01]), np.diag([gain, 1e-6, 1e-9]),
                       np.zeros((3, 3)), np.full(3, 1e-4))
    return _dp_memory(model)


def _track_surge(odo: LfOdometry, times: np.ndarray, north: np.ndarray,
                 thrust: np.ndarray) -> None:
    """Fixes of a surge-only run at ``times`` (heading 0), with its thrust."""
    for k in range(times.size):
        odo.track(float(times[k]), np.array([north[k], 0.0, 0.0]), np.array([thrust[k], 0, 0]))


def _track_then_coast(odo: LfOdometry, times: np.ndarray, north: np.ndarray,
                      thrust: np.ndarray, stop: int) -> OdometryEstimate:
    """Fixes of a surge-only run up to sample ``stop``, then dead reckoning to its end."""
    _track_surge(odo, times[:stop + 1], north, thrust)
    for k in range(stop + 1, times.size):
        out = odo.coast(float(times[k]), np.array([thrust[k], 0.0, 0.0]))
        assert out is not None and out.mode == 'dead_reckoning'
    return out


def _surge_move(times: np.ndarray, thrust: np.ndarray, damping: float, gain: float,
                environment: float) -> tuple[np.ndarray, np.ndarray]:
    """North position and surge speed of u̇ = −d u + g (τ + b) at heading 0 (exact, τ held)."""
    north, speed = np.zeros(times.size), np.zeros(times.size)
    for k in range(1, times.size):
        dt = times[k] - times[k - 1]
        target = gain * (thrust[k - 1] + environment) / damping  # the speed it tends to
        decay = math.exp(-damping * dt)
        speed[k] = target + (speed[k - 1] - target) * decay
        north[k] = north[k - 1] + target * dt + (speed[k - 1] - target) * (1 - decay) / damping
    return north, speed


@pytest.mark.parametrize('balance', ['rest', 'motion', 'holding'])
def test_dead_reckoning_in_a_move_with_the_motion_balance(balance: str) -> None:
    """The motion and holding balances: the thrust that accelerates a move is not environment.

    A vessel u̇ = −0.01 u + 1e-6 (τ + b), b = −1 kN, holds station on τ = 1 kN; at 100 s a move
    adds 3 kN. The fixes stop 60 s into the move (u ≈ 0.135 m/s, still accelerating) and the
    thrust stays. Balanced at rest, the 30 s low-passed thrust (≈ 3.6 kN) is taken for the
    environment: the dead reckoning sees 0.4 kN of net force instead of 3 kN and falls 3.8 m
    behind the vessel's 10.6 m in 60 s. Balanced against the motion (two low-passes of thrust
    and twist), the environment comes out near the true −1 kN and the dead reckoning follows the
    vessel to 0.10 m (measured). Held from before the move (``dead_reckoning_holding_balance``,
    10 s before the motion gate opened), the environment is the −1 kN the vessel held station
    against: 0.16 m (measured).
    """
    damping, gain, environment = 0.01, 1e-6, -1e3
    times = np.arange(0.0, 221.0)
    thrust = np.where(times < 100.0, 1e3, 4e3)
    north, _ = _surge_move(times, thrust, damping, gain, environment)
    memory = _surge_memory(damping, gain)  # fitted environment: none
    # the DR starts from the twist itself (no start low-pass): the balance alone is compared
    odo = LfOdometry(3, H, OdometryParams(dead_reckoner='model', dead_reckoning_velocity_time=H,
                                          dead_reckoning_motion_balance=balance == 'motion',
                                          dead_reckoning_holding_balance=balance == 'holding',
                                          prior_pose_std=(1e-3, 1e-3, 1e-4)))
    odo._memory = memory  # noqa: SLF001 - a known vessel memory
    stop = 160
    out = _track_then_coast(odo, times, north, thrust, stop)
    error = abs(out.pose[0] - north[-1])
    travelled = north[-1] - north[stop]
    print(f'balance {balance}: {travelled:.2f} m travelled in the dropout, dead '
          f'reckoning {error:.3f} m off')
    assert travelled > 8.0
    if balance != 'rest':
        assert error < 0.05 * travelled  # measured 0.10 m of 10.6 m
    else:
        assert error > 0.25 * travelled  # balanced at rest: measured 3.8 m


@pytest.mark.parametrize('moving_twist', [False, True])
def test_dead_reckoning_in_a_move_starts_from_the_current_twist(moving_twist: bool) -> None:
    """``dead_reckoning_moving_twist``: a move's dead reckoning starts from its current speed.

    The vessel of the motion-balance test, fixes stopping 60 s into the move (true speed
    0.137 m/s one step later, still accelerating). Its twist low-passed over the default 30 s
    lags the speed (measured 0.086 m/s); the Kalman filter's current twist is within 10 % of it
    (measured 0.137 m/s).
    """
    damping, gain, environment = 0.01, 1e-6, -1e3
    times = np.arange(0.0, 162.0)
    thrust = np.where(times < 100.0, 1e3, 4e3)
    north, speed = _surge_move(times, thrust, damping, gain, environment)
    memory = _surge_memory(damping, gain)  # fitted environment: none
    odo = LfOdometry(3, H, OdometryParams(dead_reckoner='model',
                                          dead_reckoning_moving_twist=moving_twist,
                                          prior_pose_std=(1e-3, 1e-3, 1e-4)))
    odo._memory = memory  # noqa: SLF001 - a known vessel memory
    stop = 160
    _track_surge(odo, times[:stop + 1], north, thrust)
    out = odo.coast(float(times[stop + 1]), np.array([thrust[stop + 1], 0.0, 0.0]))
    assert out is not None and out.mode == 'dead_reckoning'
    start = out.twist[0]
    print(f'moving twist {moving_twist}: true speed {speed[stop + 1]:.3f} m/s, dead reckoning '
          f'from {start:.3f} m/s')
    assert speed[stop + 1] > 0.12
    if moving_twist:
        assert abs(start - speed[stop + 1]) < 0.1 * speed[stop + 1]
    else:
        assert start < 0.7 * speed[stop + 1]


@pytest.mark.parametrize('option', ['dead_reckoning_motion_balance',
                                    'dead_reckoning_moving_twist'])
def test_the_motion_options_leave_a_vessel_at_rest_as_it_was(option: str) -> None:
    """Holding station (slow twist below 2 holding std) either motion option changes nothing.

    Poses with a 0.05 m, 0.6 rad/s wave wiggle and a steady thrust: the twist filter sees the
    wave-band velocity, the slow twist stays near 0, so no DOF counts as moving and the dead
    reckoning is the one balanced at rest, from the low-passed twist, to the last bit.
    """
    model = LfDynamics(np.diag([-0.01, -0.01, -0.01]), np.diag([1e-6, 1e-6, 1e-9]),
                       np.zeros((3, 3)), np.full(3, 1e-4))
    memory = _dp_memory(model, 'model')
    held = np.array([2e3, -1e3, 0.0])
    poses = []
    for enabled in (False, True):
        odo = LfOdometry(3, H, OdometryParams(dead_reckoner='model', **{option: enabled}))
        odo._memory = memory  # noqa: SLF001 - a known vessel memory
        for k in range(300):
            wiggle = 0.05 * math.sin(0.6 * k)
            odo.track(float(k), np.array([wiggle, -wiggle, 0.0]), held)
        for k in range(1, 61):
            out = odo.coast(300.0 + k, held)
            assert out is not None
        poses.append(out.pose)
    np.testing.assert_array_equal(poses[0], poses[1])


def test_twist_model_option_uses_a_given_or_implied_gain() -> None:
    """twist_model: the twist filter predicts with the model when its gain is known."""
    model = LfDynamics(np.diag([-0.01, -0.01, -0.01]), np.diag([1e-6, 1e-6, 1e-9]),
                       np.zeros((3, 3)), np.full(3, 1e-4))
    memory = dataclasses.replace(_hold_memory(), model=model, known_gain='controller')
    x, tau = np.zeros(6), np.array([1e3, 0.0, 0.0])
    drives = {}
    for option in (False, True):
        odo = LfOdometry(3, H, OdometryParams(twist_model=option))
        odo._memory = memory  # noqa: SLF001 - a known vessel memory
        _a, b = odo._transition(x, tau, 1.0)  # noqa: SLF001
        drives[option] = b[3]
    assert drives[False] == 0.0  # the drift test chose hold: constant velocity
    assert drives[True] == pytest.approx(1e-3)  # h G τ
    odo = LfOdometry(3, H, OdometryParams(twist_model=True))
    odo._memory = dataclasses.replace(memory, known_gain='')  # noqa: SLF001 - fitted gain
    assert odo._transition(x, tau, 1.0)[1][3] == 0.0  # noqa: SLF001


def test_excursion_covariance_is_the_spread_of_the_models_displacement_and_the_miss() -> None:
    """k² |d_NE|² on north and east, k² d_ψ² on heading, plus the reckoner's miss m mᵀ."""
    model = np.array([3.0, 4.0, 0.5])
    pose, twist = excursion_covariance(np.zeros(3), model, np.zeros(3), np.zeros(3), 0.5)
    miss = -model
    expected = np.outer(miss, miss) + np.diag([6.25, 6.25, 0.0625])
    np.testing.assert_allclose(pose, expected, rtol=1e-12)
    np.testing.assert_allclose(twist, np.zeros((3, 3)), atol=0.0)
    assert np.all(np.linalg.eigvalsh(pose) >= -1e-12)
    # the reckoner is the model: no miss, only the spread; rotation invariant horizontally
    same, _ = excursion_covariance(model, model, model, model, 0.5)
    np.testing.assert_allclose(same, np.diag([6.25, 6.25, 0.0625]), rtol=1e-12)
    turned, _ = excursion_covariance([5.0, 0.0, 0.5], [5.0, 0.0, 0.5], np.zeros(3), np.zeros(3),
                                     0.5)
    np.testing.assert_allclose(turned, same, rtol=1e-12)
    one, one_twist = excursion_covariance([1.0], [3.0], [0.2], [0.1], 0.5)
    np.testing.assert_allclose(one, [[4.0 + 2.25]], rtol=1e-12)
    np.testing.assert_allclose(one_twist, [[0.01 + 0.0025]], rtol=1e-12)


def _coast_push(params: OdometryParams, push: float = 1e3, swing: float = 0.0,
                dp_controlled: bool = True) -> tuple[LfOdometry, OdometryEstimate]:
    """Hold station on a known model, then coast 60 s with ``push`` N more surge thrust.

    While tracking (200 s) the surge thrust alternates ± ``swing`` about 2e3 N. Returns the
    odometry and its last dead-reckoned estimate.
    """
    model = LfDynamics(np.diag([-0.01, -0.01, -0.01]), np.diag([1e-6, 1e-6, 1e-9]),
                       np.zeros((3, 3)), np.full(3, 1e-4))
    odo = LfOdometry(3, H, params)
    odo._memory = dataclasses.replace(  # noqa: SLF001 - a known vessel memory
        _dp_memory(model, 'hold'), dp_controlled=dp_controlled)
    for k in range(200):
        odo.track(float(k), np.zeros(3), np.array([2e3 + swing * (-1) ** k, 0.0, 0.0]))
    for k in range(1, 61):
        out = odo.coast(200.0 + k, np.array([2e3 + push, 0.0, 0.0]))
        assert out is not None
    return odo, out


def _coast_a_surge_push(reckoner: str, excursion_std: float) -> tuple[np.ndarray, np.ndarray]:
    """`_coast_push` of 1e3 N on the whole thrust (no band): (pose, pose covariance)."""
    _, out = _coast_push(OdometryParams(dead_reckoner=reckoner,
                                        dead_reckoning_excursion_std=excursion_std,
                                        dead_reckoning_excursion_band=0.0))
    return out.pose, out.pose_cov


def test_dead_reckoning_excursion_std_spreads_the_models_displacement() -> None:
    """``dead_reckoning_excursion_std``: the covariance holds what the model says a push does.

    The model dead-reckons the push d north: 61 steps of 1 s (the last fix was at 199 s) of
    u_k = 0.1 (1 − 0.99^k) m/s, d = Σ u_k = 1.563 m. On the model, k = 0.5 adds
    0.25 d² to north and east; holding, the held pose misses all of d, so north gets d² + 0.25
    d² more. k = 0 leaves the covariance as it was.
    """
    pose_model, cov_model = _coast_a_surge_push('model', 0.0)
    d = float(pose_model[0])
    expected = sum(0.1 * (1.0 - 0.99 ** k) for k in range(1, 62))
    assert d == pytest.approx(expected, rel=1e-9)
    pose_spread, cov_spread = _coast_a_surge_push('model', 0.5)
    np.testing.assert_allclose(pose_spread, pose_model, atol=1e-12)  # only the covariance
    added = np.diag(cov_spread - cov_model)
    np.testing.assert_allclose(added, [0.25 * d ** 2, 0.25 * d ** 2, 0.0], rtol=1e-6, atol=1e-9)
    pose_hold, cov_hold = _coast_a_surge_push('hold', 0.0)
    assert abs(pose_hold[0]) < 1e-9
    _, cov_hold_spread = _coast_a_surge_push('hold', 0.5)
    added = np.diag(cov_hold_spread - cov_hold)
    np.testing.assert_allclose(added, [1.25 * d ** 2, 0.25 * d ** 2, 0.0], rtol=1e-6, atol=1e-9)


def test_excursion_covariance_stays_finite_for_an_absurd_displacement() -> None:
    """Displacements beyond ``MAX_EXCURSION`` count as that much: finite, no overflow."""
    big = odometry_module.MAX_EXCURSION
    pose, twist = odometry_module.excursion_covariance(
        [1e300, 0.0, 0.0], [-1e300, 0.0, 0.0], [math.inf, 0.0, 0.0], [0.0, 0.0, 0.0], 2.0)
    assert np.all(np.isfinite(pose)) and np.all(np.isfinite(twist))
    assert pose[0, 0] == pytest.approx((2.0 * big) ** 2 + 4.0 * big ** 2)  # miss² + k² d²
    assert twist[0, 0] == pytest.approx(big ** 2)  # miss² only: the model's twist is 0
    small, _ = odometry_module.excursion_covariance([3.0, 4.0, 0.0], [3.0, 4.0, 0.0],
                                                    np.zeros(3), np.zeros(3), 2.0)
    np.testing.assert_allclose(np.diag(small), [100.0, 100.0, 0.0])  # k² |d_NE|² = 4 · 25


@pytest.mark.parametrize('bad', [0.0, -0.5, math.nan, math.inf])
def test_a_wave_peak_freq_that_is_no_frequency_is_refused(bad: float) -> None:
    odo = LfOdometry(3, H)
    odo.set_wave_peak_freq(0.6)
    with pytest.raises(ValueError, match='wave_peak_freq'):
        odo.set_wave_peak_freq(bad)
    assert odo.wave_peak_freq == 0.6
    odo.set_wave_peak_freq(None)
    assert odo.wave_peak_freq is None


def test_thrust_statistics_step_is_the_weighted_mean_and_variance() -> None:
    """Two samples: weights 1 − w and w, variance w (1 − w) Δ²; a long white series: σ²."""
    first = np.array([1.0, -2.0])
    mean, var = thrust_statistics_step(None, first, 0.1)
    np.testing.assert_array_equal(mean, first)
    np.testing.assert_array_equal(var, [0.0, 0.0])
    second = np.array([3.0, 2.0])
    mean2, var2 = thrust_statistics_step((mean, var), second, 0.1)
    np.testing.assert_allclose(mean2, 0.9 * first + 0.1 * second, rtol=1e-12)
    np.testing.assert_allclose(var2, 0.1 * 0.9 * (second - first) ** 2, rtol=1e-12)
    np.testing.assert_array_equal(mean, first)  # the inputs are not modified
    rng = np.random.default_rng(5)
    stats = None
    for f in rng.normal(10.0, 2.0, size=(20000, 1)):
        stats = thrust_statistics_step(stats, f, 0.01)
    assert stats is not None
    assert stats[0][0] == pytest.approx(10.0, abs=0.5)  # the mean's std: 2 √(w/2) = 0.14
    assert stats[1][0] == pytest.approx(4.0, rel=0.25)  # its relative std: about √(w) = 0.1
    absurd = thrust_statistics_step(stats, [1e300], 0.01)  # d² overflows: the sample is left out
    np.testing.assert_array_equal(absurd[0], stats[0])
    np.testing.assert_array_equal(absurd[1], stats[1])


def test_band_excess_is_a_continuous_dead_zone() -> None:
    centre, half = np.array([100.0, 0.0, 5.0]), np.array([10.0, 10.0, 0.0])
    np.testing.assert_allclose(band_excess([105.0, -9.9, 5.0], centre, half), centre)
    np.testing.assert_allclose(band_excess([125.0, -30.0, 7.0], centre, half),
                               [115.0, -20.0, 7.0])
    np.testing.assert_allclose(band_excess([110.0, 10.0, 5.0], centre, half), centre)  # edges


def _band_added(push: float, swing: float, dp_controlled: bool = True
                ) -> tuple[LfOdometry, np.ndarray]:
    """Hold reckoner, k = 0.5, band 2: the odometry and what k added to its pose variances."""
    def params(k: float) -> OdometryParams:
        return OdometryParams(dead_reckoner='hold', dead_reckoning_excursion_std=k,
                              dead_reckoning_excursion_band=2.0)

    odo, out = _coast_push(params(0.5), push, swing, dp_controlled)
    _, base = _coast_push(params(0.0), push, swing, dp_controlled)
    return odo, np.diag(out.pose_cov - base.pose_cov)


def test_dead_reckoning_excursion_band_scales_the_thrust_beyond_the_band() -> None:
    """The band: the model's answer to the thrust beyond centre ± 2 std, not to all of it.

    The model is linear and starts at rest, so its displacement is proportional to the excess
    force; `_coast_a_surge_push`'s push of 1e3 N moves it d = 1.563 m. A steady held thrust
    (std 0): the band is the centre, the whole push counts, as without the band (hold misses
    all of d: north + 1.25 d², east + 0.25 d²). A held thrust alternating ±600 N: a push of
    1e3 N stays inside the band (half-width ≈ 1200 N) and adds nothing; one of 3e3 N counts
    only beyond the edge. Without a DP controller's thrust the band adds nothing.
    """
    d = sum(0.1 * (1.0 - 0.99 ** k) for k in range(1, 62))
    _, added = _band_added(1e3, 0.0)
    np.testing.assert_allclose(added, [1.25 * d ** 2, 0.25 * d ** 2, 0.0], rtol=1e-6, atol=1e-9)
    odo, added = _band_added(1e3, 600.0)
    band = odo._dr_band  # noqa: SLF001 - the band frozen at the DR start
    assert band is not None
    assert band[1][0] == pytest.approx(1200.0, rel=0.02)  # 2 × the alternating thrust's std
    np.testing.assert_allclose(added, np.zeros(3), atol=1e-9)
    odo, added = _band_added(3e3, 600.0)
    band = odo._dr_band  # noqa: SLF001
    assert band is not None
    d_beyond = d * (2e3 + 3e3 - (band[0][0] + band[1][0])) / 1e3  # the push beyond the edge
    np.testing.assert_allclose(added, [1.25 * d_beyond ** 2, 0.25 * d_beyond ** 2, 0.0],
                               rtol=1e-3)
    _, added = _band_added(3e3, 600.0, dp_controlled=False)
    np.testing.assert_allclose(added, np.zeros(3), atol=1e-12)


def test_holding_balance_in_one_dof_follows_the_move() -> None:
    """``dead_reckoning_holding_balance`` with ``ndof`` 1: the surge move of the balance test.

    Balanced on the thrust held 10 s before the gate opened, the dead reckoning ends within 5 %
    of the 10.6 m the vessel travels in the 60 s dropout (as in 3 DOF).
    """
    damping, gain, environment = 0.01, 1e-6, -1e3
    times = np.arange(0.0, 221.0)
    thrust = np.where(times < 100.0, 1e3, 4e3)
    north, _ = _surge_move(times, thrust, damping, gain, environment)
    model = LfDynamics(np.array([[-damping]]), np.array([[gain]]), np.zeros((1, 1)),
                       np.full(1, 1e-4))
    horizons = np.arange(1.0, 61.0)
    ms = ((horizons / 60.0) ** 2)[:, None]
    memory = VesselMemory(model, 'model', DriftCurve(horizons, ms, 1e-4 * ms, 10), {}, 'test',
                          np.full(1, 1e-3), dp_controlled=True)
    odo = LfOdometry(1, H, OdometryParams(dead_reckoner='model', dead_reckoning_velocity_time=H,
                                          dead_reckoning_holding_balance=True,
                                          prior_pose_std=(1e-3, 1e-3, 1e-4)))
    odo._memory = memory  # noqa: SLF001 - a known vessel memory
    stop = 160
    out = _track_then_coast(odo, times, north, thrust, stop)
    assert abs(out.pose[0] - north[-1]) < 0.05 * (north[-1] - north[stop])


def test_force_frame_turns_are_inverse_and_right_handed() -> None:
    """R(ψ) f and R(ψ)ᵀ f for the holding balance: surge thrust at ψ = 90° pushes east."""
    def turn(heading: float) -> np.ndarray:
        return odometry_module._rotation_block(heading, 3)[:2, :2]  # noqa: SLF001

    np.testing.assert_allclose(turn(math.pi / 2) @ np.array([2.0, 0.0]), [0.0, 2.0], atol=1e-12)
    force = np.array([1.5, -0.7])
    back = turn(0.8).T @ (turn(0.8) @ force)
    np.testing.assert_allclose(back, force, rtol=1e-12)


def test_holding_balance_is_not_used_after_a_turn_beyond_the_limit() -> None:
    """``dead_reckoning_holding_max_turn``: a thrust held at another heading is not believed.

    The surge move of the balance test, its heading turned by 0.5 rad 40 s into the move (after
    the last holding sample; the fixes turn, the thrust is the same): with a limit of 0.3 rad
    the dead reckoning is exactly the one balanced on the current thrust; with no limit it is
    the holding balance's (a different pose).
    """
    damping, gain, environment = 0.01, 1e-6, -1e3
    times = np.arange(0.0, 221.0)
    thrust = np.where(times < 100.0, 1e3, 4e3)
    north, _ = _surge_move(times, thrust, damping, gain, environment)
    heading = np.where(times < 140.0, 0.0, 0.5)
    poses = {}
    for label, holding, max_turn in (('rest', False, math.inf), ('limited', True, 0.3),
                                     ('unlimited', True, math.inf)):
        odo = LfOdometry(3, H, OdometryParams(
            dead_reckoner='model', dead_reckoning_velocity_time=H,
            dead_reckoning_holding_balance=holding, dead_reckoning_holding_max_turn=max_turn,
            prior_pose_std=(1e-3, 1e-3, 1e-4)))
        odo._memory = _surge_memory(damping, gain)  # noqa: SLF001 - a known vessel memory
        stop = 160
        for k in range(stop + 1):
            odo.track(float(times[k]), np.array([north[k], 0.0, heading[k]]),
                      np.array([thrust[k], 0.0, 0.0]))
        for k in range(stop + 1, times.size):
            out = odo.coast(float(times[k]), np.array([thrust[k], 0.0, 0.0]))
            assert out is not None
        poses[label] = out.pose
    np.testing.assert_array_equal(poses['limited'], poses['rest'])
    assert np.linalg.norm(poses['unlimited'][:2] - poses['rest'][:2]) > 1.0
    with pytest.raises(ValueError, match='dead_reckoning_holding_max_turn'):
        OdometryParams(dead_reckoning_holding_max_turn=math.nan)


def _holding_coast(max_age: float, stop: int = 160) -> tuple[np.ndarray, float]:
    """The surge move of the balance test dead-reckoned from ``stop`` with the holding balance.

    Returns (final pose, age [s] of the newest holding sample when the dead reckoning began).
    """
    damping, gain, environment = 0.01, 1e-6, -1e3
    times = np.arange(0.0, 221.0)
    thrust = np.where(times < 100.0, 1e3, 4e3)
    north, _ = _surge_move(times, thrust, damping, gain, environment)
    holding = max_age >= 0.0
    odo = LfOdometry(3, H, OdometryParams(
        dead_reckoner='model', dead_reckoning_velocity_time=H,
        dead_reckoning_holding_balance=holding,
        dead_reckoning_holding_max_age=max_age if holding else math.inf,
        prior_pose_std=(1e-3, 1e-3, 1e-4)))
    odo._memory = _surge_memory(damping, gain)  # noqa: SLF001 - a known vessel memory
    for k in range(stop + 1):
        odo.track(float(times[k]), np.array([north[k], 0.0, 0.0]),
                  np.array([thrust[k], 0.0, 0.0]))
    history = odo._holding['horizontal']  # noqa: SLF001
    age = float(times[stop] - history[-1][0]) if history else math.nan
    for k in range(stop + 1, times.size):
        out = odo.coast(float(times[k]), np.array([thrust[k], 0.0, 0.0]))
        assert out is not None
    return out.pose, age


def test_holding_balance_is_not_used_when_the_move_is_old() -> None:
    """``dead_reckoning_holding_max_age``: a move seen longer ago keeps the current thrust.

    The gate opens some seconds into the surge move (after t = 100 s), so the newest holding
    sample is that old at the dropout (t = 160 s): a limit 1 s below that age gives exactly the
    dead reckoning balanced on the current thrust; 1 s above it, exactly the holding balance's
    with no limit (which differs from the current thrust's by more than 1 m).
    """
    rest, _ = _holding_coast(-1.0)
    unlimited, age = _holding_coast(math.inf)
    assert 20.0 < age < 60.0  # the gate opened 0–40 s into the move
    below, _ = _holding_coast(age - 1.0)
    above, _ = _holding_coast(age + 1.0)
    np.testing.assert_array_equal(below, rest)
    np.testing.assert_array_equal(above, unlimited)
    assert np.linalg.norm(unlimited[:2] - rest[:2]) > 1.0
    with pytest.raises(ValueError, match='dead_reckoning_holding_max_age'):
        OdometryParams(dead_reckoning_holding_max_age=math.nan)
    with pytest.raises(ValueError, match='dead_reckoning_holding_max_age'):
        OdometryParams(dead_reckoning_holding_max_age=-1.0)


@pytest.mark.parametrize('still', [False, True])
def test_holding_still_keeps_no_group_while_another_moves(still: bool) -> None:
    """``dead_reckoning_holding_still``: no group's thrust counts as held while any DOF moves.

    The surge move of the balance test (from t = 100 s; the heading never moves): each group on
    its own, yaw keeps holding through the move (its newest sample is the last fix, t = 160 s);
    with the option, yaw stops holding when the horizontal gate opens, at the same instant as
    the horizontal group.
    """
    damping, gain, environment = 0.01, 1e-6, -1e3
    times = np.arange(0.0, 161.0)
    thrust = np.where(times < 100.0, 1e3, 4e3)
    north, _ = _surge_move(times, thrust, damping, gain, environment)
    odo = LfOdometry(3, H, OdometryParams(
        dead_reckoner='model', dead_reckoning_velocity_time=H,
        dead_reckoning_holding_balance=True, dead_reckoning_holding_still=still,
        prior_pose_std=(1e-3, 1e-3, 1e-4)))
    odo._memory = _surge_memory(damping, gain)  # noqa: SLF001 - a known vessel memory
    _track_surge(odo, times, north, thrust)
    horizontal = odo._holding['horizontal'][-1][0]  # noqa: SLF001
    yaw = odo._holding['yaw'][-1][0]  # noqa: SLF001
    assert 100.0 < horizontal < 150.0  # the gate opened some seconds into the move
    assert yaw == (horizontal if still else 160.0)


@pytest.mark.parametrize('keep', [False, True])
def test_a_memory_without_a_model_keeps_the_one_with_a_model_when_asked(keep: bool) -> None:
    """``dead_reckoning_keep_model``: a refused fit does not take the model away.

    Off (default), the newest memory is used: its reckoner ('hold') reckons the dropout. On, the
    memory with a model stays in use and is counted in ``memories_kept``; a memory with a model
    still replaces it.
    """
    odo = LfOdometry(3, H, OdometryParams(dead_reckoning_keep_model=keep))
    with_model = _surge_memory(0.01, 1e-6)
    refused = dataclasses.replace(_dp_memory(with_model.model, reckoner='hold'), model=None)
    odo.apply_learned(with_model, None)
    assert odo.reckoner == 'model'
    odo.apply_learned(refused, None)
    assert odo.memory is (with_model if keep else refused)
    assert odo.reckoner == ('model' if keep else 'hold')
    assert odo.counters['memories_kept'] == int(keep)
    assert odo.counters['memory_updates'] == 2 - int(keep)
    newer = _surge_memory(0.02, 2e-6)
    odo.apply_learned(newer, None)
    assert odo.memory is newer


def _set_gate_inputs(odo: LfOdometry, twist: list[float], slow_twist: list[float]) -> None:
    """Three fixes at rest, then the motion gate's inputs set by hand.

    The last published twist ``twist``, its std 0.1 m/s, 0.1 m/s, 0.01 rad/s (the holding std
    before a calibration), and the low-passed twist ``slow_twist``.
    """
    for k in range(3):
        odo.track(float(k), np.zeros(3), np.zeros(3))
    last = odo._last_output  # noqa: SLF001 - the gate's inputs set by hand
    assert last is not None
    odo._last_output = dataclasses.replace(  # noqa: SLF001
        last, twist=np.array(twist), twist_cov=np.diag([0.01, 0.01, 1e-4]))
    odo._twist_once = np.array(slow_twist)  # noqa: SLF001


@pytest.mark.parametrize('gate', [0.0, 4.0])
def test_the_moving_gate_on_the_current_twist_sees_a_move_the_low_pass_lags(gate: float
                                                                           ) -> None:
    """``dead_reckoning_moving_gate``: the current twist opens the motion gate as well.

    Holding std 0.1 m/s, 0.1 m/s, 0.01 rad/s (before a calibration: the published twist std).
    Early in a move the low-passed twist is 0.1 m/s in surge (below 2 std) while the current
    twist is 0.7 m/s: only with the gate (4 std = 0.4 m/s) are surge and sway moving (one
    earth-fixed force); yaw, 0.02 rad/s now (2 std), stays at rest either way.
    """
    odo = LfOdometry(3, H, OdometryParams(dead_reckoning_moving_gate=gate))
    _set_gate_inputs(odo, [0.7, 0.05, 0.02], [0.1, 0.05, 0.0])
    moving = odo._moving_dofs(np.ones(3, dtype=bool))  # noqa: SLF001
    if gate == 0.0:
        assert moving is None
    else:
        assert moving is not None and moving.tolist() == [True, True, False]
    # the low-passed twist alone above 2 std opens it with or without the gate
    odo._twist_once = np.array([0.25, 0.0, 0.0])  # noqa: SLF001
    moving = odo._moving_dofs(np.ones(3, dtype=bool))  # noqa: SLF001
    assert moving is not None and moving.tolist() == [True, True, False]


def _surge_in_waves(periods: float, wave_peak_freq: float | None, seconds: int,
                    start: str = 'average', accel: float = 0.0, clamp: float = 0.0,
                    wave: float = 2.0) -> LfOdometry:
    """Fixes of a 0.5 m/s surge with a 2 m wave motion at ω0 = 2π/20 rad/s, H = 1 s.

    The wave velocity (0.63 m/s amplitude) is below the twist filter's bandwidth (1 rad/s), so
    the current twist carries most of it. ``accel`` [m/s²]: the surge speed is accel · t instead
    of 0.5 m/s. ``periods`` 0: the start 'current'. ``clamp``:
    ``dead_reckoning_moving_twist_clamp`` (with the start 'current'); ``wave``: the wave
    motion's amplitude [m].
    """
    odo = LfOdometry(3, H, OdometryParams(
        dead_reckoning_twist_average_periods=periods,
        dead_reckoning_moving_twist_start=start if periods > 0.0 else 'current',
        dead_reckoning_moving_twist_clamp=clamp,
        dead_reckoning_moving_gate_averaged=0.0,
        prior_pose_std=(1e-3, 1e-3, 1e-4)))
    odo.set_wave_peak_freq(wave_peak_freq)
    times = np.arange(float(seconds))
    drift = 0.5 * accel * times ** 2 if accel else 0.5 * times
    north = drift + wave * np.sin(2.0 * math.pi / 20.0 * times)
    _track_surge(odo, times, north, np.zeros(seconds))
    return odo


def test_a_move_starts_from_the_twist_averaged_over_a_wave_period() -> None:
    """``dead_reckoning_moving_twist_start`` 'average': the wave velocity stays out of the start.

    At t = 199 s the wave velocity is near its crest: the current twist is 0.5 + 0.49 m/s
    (measured); averaged over one period of ω0 (20 samples) it is the surge speed within
    0.02 m/s. Sway and yaw, at rest, keep the low-passed twist (0). Without ω0, or with a
    history shorter than the period, the current twist.
    """
    freq = 2.0 * math.pi / 20.0
    odo = _surge_in_waves(1.0, freq, 200)
    state = odo._require_state()  # noqa: SLF001 - the start of a dead reckoning
    moving = odo._moving_dofs(np.ones(3, dtype=bool))  # noqa: SLF001
    assert moving is not None and moving.tolist() == [True, True, False]
    current = state[3:]
    start = odo._start_twist(state)  # noqa: SLF001
    print(f'current twist {current}, start {start}')
    assert abs(current[0] - 0.5) > 0.3
    assert abs(start[0] - 0.5) < 0.02
    assert abs(start[1]) < 1e-6 and start[2] == 0.0
    for other in (_surge_in_waves(1.0, None, 200),  # no ω0
                  _surge_in_waves(1.0, 2.0 * math.pi / 300.0, 200),  # a period beyond the run
                  _surge_in_waves(0.0, freq, 200)):  # off
        assert other._wave_averaged_twist() is None  # noqa: SLF001
        other_state = other._require_state()  # noqa: SLF001
        assert other._start_twist(other_state).tolist() == \
            current[:2].tolist() + [start[2]]  # noqa: SLF001


def test_the_extrapolated_average_starts_an_accelerating_move_without_the_lag() -> None:
    """'extrapolated': 2 mean(T) − mean(2T) is the speed now on a ramp, with the wave removed.

    Surge speed 0.002 t m/s (0.398 m/s at t = 199 s) and the 2 m wave at ω0 = 2π/20 rad/s:
    the average over one period (20 samples) lags by 9.5 s (0.379 m/s; measured 0.377); the
    extrapolated one is within 0.005 m/s of the speed (measured 0.397) while the current twist
    is 0.49 m/s off.
    """
    freq = 2.0 * math.pi / 20.0
    speed = 0.002 * 199.0
    average = _surge_in_waves(1.0, freq, 200, 'average', accel=0.002)
    extrapolated = _surge_in_waves(1.0, freq, 200, 'extrapolated', accel=0.002)
    state = extrapolated._require_state()  # noqa: SLF001 - the start of a dead reckoning
    lagged = average._start_twist(average._require_state())[0]  # noqa: SLF001
    start = extrapolated._start_twist(state)[0]  # noqa: SLF001
    print(f'current {state[3]:.3f}, average {lagged:.3f}, extrapolated {start:.3f} m/s')
    assert abs(state[3] - speed) > 0.3
    assert lagged == pytest.approx(speed - 0.002 * 9.5, abs=0.005)
    assert start == pytest.approx(speed, abs=0.005)


@pytest.mark.parametrize('clamp', [0.0, 2.0, 40.0])
def test_the_clamp_keeps_a_spike_of_the_current_twist_out_of_the_start(clamp: float) -> None:
    """``dead_reckoning_moving_twist_clamp``: the current start kept near the averages.

    At t = 199 s of the 0.5 m/s surge in the 2 m wave the current twist is 0.99 m/s (the wave's
    crest); the average over one period and its extrapolation are 0.5 m/s. The holding std
    before a calibration is the published one (measured 0.0013 m/s): with k = 2 the start is
    0.5 + 2 std, with k = 40 it is 0.5 + 40 std (0.55 m/s), without the clamp the current
    twist. Sway and yaw, at rest, keep the low-passed twist (0).
    """
    odo = _surge_in_waves(1.0, 2.0 * math.pi / 20.0, 200, 'current', clamp=clamp)
    state = odo._require_state()  # noqa: SLF001 - the start of a dead reckoning
    std = odo._holding_twist_std()[0]  # noqa: SLF001
    start = odo._start_twist(state)  # noqa: SLF001
    print(f'current {state[3]:.4f}, std {std:.5f}, start {start[0]:.4f} m/s')
    assert state[3] == pytest.approx(0.987, abs=0.01)
    assert 5e-4 < std < 5e-3
    expected = state[3] if clamp == 0.0 else 0.5 + clamp * std
    assert start[0] == pytest.approx(expected, abs=1e-3)
    assert abs(start[1]) < 1e-6 and start[2] == 0.0


def test_the_clamp_acts_on_its_dofs_only() -> None:
    """``dead_reckoning_moving_twist_clamp_dofs``: 'horizontal' leaves the yaw rate as it is.

    The surge run in waves (averages 0.5 m/s, 0, 0 rad/s; holding std 0.0013 m/s, 0.0013 m/s,
    0.00013 rad/s): a current twist of 0.99 m/s, 0.3 m/s, 0.05 rad/s is cut to the averages
    + 2 std in every DOF with 'all', in surge and sway only with 'horizontal'.
    """
    odo = _surge_in_waves(1.0, 2.0 * math.pi / 20.0, 200, 'current', clamp=2.0)
    std = odo._holding_twist_std()  # noqa: SLF001
    current = np.array([0.99, 0.3, 0.05])
    every = odo._clamped_current(current)  # noqa: SLF001
    np.testing.assert_allclose(every, [0.5, 0.0, 0.0] + 2.0 * std, atol=1e-3)
    odo.params = dataclasses.replace(odo.params,
                                     dead_reckoning_moving_twist_clamp_dofs='horizontal')
    horizontal = odo._clamped_current(current)  # noqa: SLF001
    np.testing.assert_allclose(horizontal[:2], every[:2], atol=1e-12)
    assert horizontal[2] == 0.05
    assert current.tolist() == [0.99, 0.3, 0.05]  # the input is not modified


@pytest.mark.parametrize(('start', 'clamp', 'kept'), [('current', 2.0, True),
                                                   ('current', 0.0, False),
                                                   ('average', 2.0, False),
                                                   ('extrapolated', 0.0, True)])
def test_the_double_span_average_is_kept_only_where_it_is_read(start: str, clamp: float,
                                                               kept: bool) -> None:
    """mean(2T) is kept for the extrapolated start and for the clamp of the current start.

    With an averaged start the clamp has nothing to clamp (no error), and mean(2T) is not kept.
    """
    odo = _surge_in_waves(1.0, 2.0 * math.pi / 20.0, 200, start, clamp=clamp)
    double = odo._wave_twist_double.mean()  # noqa: SLF001
    assert (double is not None) == kept
    if kept:
        assert double[0] == pytest.approx(0.5, abs=0.01)


def test_the_clamp_keeps_an_accelerating_move_s_current_twist() -> None:
    """Without waves, on a ramp 0.002 t m/s, the current twist lies on the extrapolation.

    The average over one period lags by 9.5 s (0.019 m/s below); the extrapolation is the
    speed now. The clamp at 2 holding std leaves the current start as it is (0.396 m/s: the
    twist filter's own lag), where the average alone ± 2 std would have cut it by 0.016 m/s.
    """
    odo = _surge_in_waves(1.0, 2.0 * math.pi / 20.0, 200, 'current', accel=0.002, clamp=2.0,
                          wave=0.0)
    state = odo._require_state()  # noqa: SLF001 - the start of a dead reckoning
    std = odo._holding_twist_std()[0]  # noqa: SLF001
    average = odo._wave_averaged_twist()  # noqa: SLF001
    assert average is not None
    start = odo._start_twist(state)[0]  # noqa: SLF001
    print(f'current {state[3]:.4f}, average {average[0]:.4f}, std {std:.5f}, '
          f'start {start:.4f} m/s')
    assert state[3] - (average[0] + 2.0 * std) > 0.01
    assert start == pytest.approx(state[3], abs=1e-9)
    assert start == pytest.approx(0.002 * 199.0, abs=0.005)


@pytest.mark.parametrize(('gate', 'averaged', 'opens'), [(0.0, 0.35, False), (3.0, 0.35, True),
                                                       (3.0, 0.25, False)])
def test_the_averaged_gate_sees_a_move_the_low_pass_lags(gate: float, averaged: float,
                                                         opens: bool) -> None:
    """``dead_reckoning_moving_gate_averaged``: the twist over a wave period opens the gate.

    Holding std 0.1 m/s, 0.1 m/s, 0.01 rad/s; the low-passed twist 0.1 m/s in surge (below 2
    std). The twist averaged over the wave period, 0.35 m/s in surge (3.5 std) and 0.005 rad/s
    in yaw, opens surge and sway with a gate of 3 std, not yaw; 0.25 m/s (2.5 std) does not,
    nor does any average without the gate.
    """
    odo = LfOdometry(3, H, OdometryParams(dead_reckoning_twist_average_periods=1.0,
                                          dead_reckoning_moving_gate_averaged=gate))
    _set_gate_inputs(odo, [0.0, 0.0, 0.0], [0.1, 0.0, 0.0])
    window = SpanMean(H)
    for k in range(4):
        window.add(float(k), np.array([averaged, 0.0, 0.005]), 2.0)
    odo._wave_twist = window  # noqa: SLF001
    moving = odo._moving_dofs(np.ones(3, dtype=bool))  # noqa: SLF001
    if opens:
        assert moving is not None and moving.tolist() == [True, True, False]
    else:
        assert moving is None


@pytest.mark.parametrize('slow_twist, opens', [([0.05, 0.11, 0.0], True),
                                               ([0.09, 0.05, 0.0], False)])
def test_the_moving_gate_with_a_slow_gate_waits_for_the_move_to_begin(
        slow_twist: list[float], opens: bool) -> None:
    """``dead_reckoning_moving_gate_slow``: the current twist counts once the low pass moves.

    Holding std 0.1 m/s, 0.1 m/s, 0.01 rad/s; current twist 0.7 m/s in surge (7 std, above the
    gate of 4). With a slow gate of 1 std the horizontal group opens when the low-passed twist
    of surge *or* sway is above 0.1 m/s (sway 0.11: a move that has begun), and stays shut when
    both are below (0.09, 0.05: a spike of the current twist while holding station); a yaw rate
    of 5 std now with a low-passed one of 0 stays shut.
    """
    odo = LfOdometry(3, H, OdometryParams(dead_reckoning_moving_gate=4.0,
                                          dead_reckoning_moving_gate_slow=1.0))
    _set_gate_inputs(odo, [0.7, 0.0, 0.05], slow_twist)
    moving = odo._moving_dofs(np.ones(3, dtype=bool))  # noqa: SLF001
    if opens:
        assert moving is not None and moving.tolist() == [True, True, False]
    else:
        assert moving is None
