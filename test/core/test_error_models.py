"""Error models of the LF odometry (core.error_models): fits, references and the NEES."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lf_predictor_ros.core.error_models import (
    HOLD_FLOOR_FRACTION,
    attenuated_variance,
    calibrate,
    fit_error_model,
    fit_error_model_likelihood,
    fit_speed_gain,
    fit_twin_gain,
    low_passed,
    normalized_error_squared,
    reference_velocity,
)
from lf_predictor_ros.core.filters import design_wave_filter, frequency_response
from lf_predictor_ros.core.odometry_params import OdometryParams
from lf_predictor_ros.core.published_columns import Published

H = 1.0  # [s] sample time


def test_pose_error_model_recovers_lag_time_and_holding_std() -> None:
    """Errors T·w + σ·noise with T = (3 s, 2 s, 4 s), σ = (0.1 m, 0.05 m, 0.004 rad).

    Least squares of e² on w² recovers T² and σ² (20 000 samples: T within 5 %, σ within 10 %),
    with no prior and with a 1.2 s prior (a window full of motion overrules it).
    """
    rng = np.random.default_rng(3)
    m = 20000
    lag = np.array([3.0, 2.0, 4.0])
    sigma = np.array([0.1, 0.05, 0.004])
    rates = rng.uniform(-1.0, 1.0, size=(m, 3)) * np.array([0.1, 0.1, 0.003])
    errors = lag * rates + sigma * rng.normal(size=(m, 3))
    for prior in (0.0, 1.2):
        model = fit_error_model(errors, rates, prior)
        np.testing.assert_allclose(np.sqrt(model.gain), lag, rtol=0.05)
        np.testing.assert_allclose(np.sqrt(np.diag(model.hold)), sigma, rtol=0.1)
        np.testing.assert_allclose(model.moment, errors.T @ errors / m)
    # the published covariance at a rate w: σ² + T² w² (lag_scale 1), off-diagonals from hold
    cov = model.covariance(np.array([0.2, 0.0, 0.005]), 1.0)
    np.testing.assert_allclose(np.diag(cov), np.diag(model.hold) + model.gain *
                               np.array([0.04, 0.0, 2.5e-5]))


def test_heading_speed_lag_recovers_the_heading_error_a_move_makes() -> None:
    """Heading errors √(σ² + T² r² + K s²)·noise, s² = w_N² + w_E², K = 0.004 rad²·s²/m².

    With ``heading_speed`` the fit recovers K within 10 % and T_ψ, σ_ψ as before (σ² nets out
    K · mean s²); north and east are untouched; without it K is 0 and the heading's holding part
    absorbs the move; a given K is used as it is; 1 DOF never gets one.
    """
    rng = np.random.default_rng(5)
    m = 40000
    rates = rng.uniform(-1.0, 1.0, size=(m, 3)) * np.array([0.2, 0.2, 0.003])
    sigma2, lag2, speed_gain = 0.01 ** 2, 16.0, 0.004
    speed2 = rates[:, 0] ** 2 + rates[:, 1] ** 2
    errors = rng.normal(size=(m, 3)) * np.array([0.1, 0.05, 1.0])
    errors[:, 2] *= np.sqrt(sigma2 + lag2 * rates[:, 2] ** 2 + speed_gain * speed2)
    fitted = fit_error_model(errors, rates, heading_speed=True)
    plain = fit_error_model(errors, rates)
    assert math.isclose(fitted.speed_gain, speed_gain, rel_tol=0.1)
    assert math.isclose(fitted.gain[2], lag2, rel_tol=0.1)
    assert math.isclose(fitted.hold[2, 2], sigma2, rel_tol=0.15)
    np.testing.assert_array_equal(fitted.gain, plain.gain)
    np.testing.assert_array_equal(np.diag(fitted.hold)[:2], np.diag(plain.hold)[:2])
    assert plain.speed_gain == 0.0
    assert plain.hold[2, 2] > sigma2 + 0.5 * speed_gain * float(np.mean(speed2))
    # the published heading variance at a move of 0.3 m/s north: + K · 0.09 (not × lag_scale)
    w = np.array([0.3, 0.0, 0.0])
    cov = fitted.covariance(w, 8.0)
    assert math.isclose(cov[2, 2] - fitted.hold[2, 2], fitted.speed_gain * 0.09, rel_tol=1e-12)
    np.testing.assert_allclose(np.diag(cov)[:2], np.diag(fitted.hold)[:2] +
                               8.0 * fitted.gain[:2] * w[:2] ** 2)
    given = fit_error_model(errors[:500], rates[:500], gain=fitted.gain, heading_speed=True,
                            speed_gain=0.01)
    assert given.speed_gain == 0.01
    one = fit_error_model(errors[:, :1], rates[:, :1], heading_speed=True)
    assert one.speed_gain == 0.0


def test_speed_gain_is_a_clipped_slope() -> None:
    """e² = 1e-4 + 0.002 s² exactly: K = 0.002; an error that falls with s²: 0; no move: 0."""
    s2 = np.linspace(0.0, 0.1, 200)
    assert math.isclose(fit_speed_gain(1e-4 + 0.002 * s2, s2), 0.002, rel_tol=1e-9)
    assert fit_speed_gain(1e-3 - 0.002 * s2, s2) == 0.0
    assert fit_speed_gain(1e-4 + 0.002 * s2, np.full(200, 0.05)) == 0.0
    assert fit_speed_gain(np.ones(1), np.ones(1)) == 0.0
    with pytest.raises(ValueError, match='one length'):
        fit_speed_gain(s2, s2[:10])


def test_twin_gain_is_the_slope_of_the_squared_error_on_the_excess() -> None:
    """e² = 0.01 + 0.7 x exactly: C = 0.7; an error that shrinks with x: 0; too few x > 0: 0."""
    x = np.zeros((400, 3))
    x[100:300, 0] = np.linspace(0.0, 2.0, 200)
    x[100:300, 1] = np.linspace(0.0, 2.0, 200)
    x[:10, 2] = 1.0  # 10 samples with an excess: fewer than 60
    e = np.zeros((400, 3))
    e[:, 0] = np.sqrt(0.01 + 0.7 * x[:, 0])
    e[:, 1] = np.sqrt(np.maximum(1.0 - 0.4 * x[:, 1], 0.0))
    e[:, 2] = np.sqrt(0.01 + 5.0 * x[:, 2])
    np.testing.assert_allclose(fit_twin_gain(e, x, 60), [0.7, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(fit_twin_gain(e, x, 5)[2], 5.0, rtol=1e-12)
    with pytest.raises(ValueError, match='same shape'):
        fit_twin_gain(e, x[:, :2], 60)


def test_calibration_fits_the_twin_gain_on_the_estimates_that_carry_an_excess() -> None:
    """calibrate(..., twin_fit=True): north errors √(0.04 + 0.5 x) against the targets → C_N 0.5.

    East has an excess but a constant error (C 0), the heading no excess (C 0); estimates
    without an excess (None, before the first calibration) are left out of the fit; both
    sources get the pooled C; without twin_fit nothing is fitted.
    """
    n = 600
    times = np.arange(float(n))
    targets = np.zeros((n, 3))
    x = np.zeros((n, 3))
    x[200:400, 0] = x[200:400, 1] = np.linspace(0.0, 1.0, 200)
    history = []
    for k in range(n):
        error = np.array([math.sqrt(0.04 + 0.5 * x[k, 0]), 0.1, 0.001])
        excess = None if k < 100 else x[k].copy()
        if k < 100:  # far off, no excess: would pull C down if it counted
            error[0] = 3.0
        history.append(Published(float(k), targets[k] + error, np.zeros(3),
                                 'network' if k % 2 else 'fallback', np.zeros(3), np.zeros(3),
                                 excess))
    fitted = calibrate(history, times, targets, 3, H, 60, 0.0, twin_fit=True)
    plain = calibrate(history, times, targets, 3, H, 60, 0.0)
    assert fitted is not None and plain is not None
    for source in ('all', 'network', 'fallback'):
        twin = fitted[0][source].twin_gain
        assert twin is not None
        np.testing.assert_allclose(twin, [0.5, 0.0, 0.0], atol=1e-9)
        assert plain[0][source].twin_gain is None


def _ramp_with_wave(n: int, speed: float = 0.3, amplitude: float = 0.1,
                    omega: float = 0.8) -> np.ndarray:
    """Targets: north at ``speed`` m/s plus a wave of ``amplitude`` m at ``omega`` rad/s."""
    t = np.arange(float(n)) * H
    return np.column_stack([speed * t + amplitude * np.sin(omega * t), np.zeros(n),
                            np.zeros(n)])


def test_reference_velocity_low_pass_removes_the_targets_wave_motion() -> None:
    """0.3 m/s + 0.1 m at 0.8 rad/s, cut at 0.4 rad/s.

    The central difference at h = 1 s sees 0.1 · sin(0.8) / h = 0.0717 m/s of wave velocity.
    The order-4 Butterworth forward and backward passes |H(0.8)|² ≈ 0.004 of the wave: the
    velocity is 0.3 m/s within 1 mm/s away from the ends; cutoff 0, or at or above the Nyquist
    frequency (π rad/s at h = 1 s), gives `body_velocity` itself.
    """
    targets = _ramp_with_wave(600)
    kept = targets.copy()
    raw = reference_velocity(targets, H)
    assert np.max(np.abs(raw[50:-50, 0] - 0.3)) == pytest.approx(0.1 * math.sin(0.8), rel=1e-3)
    clean = reference_velocity(targets, H, 0.4)
    np.testing.assert_allclose(clean[50:-50, 0], 0.3, atol=1e-3)
    np.testing.assert_allclose(clean[:, 1:], 0.0, atol=1e-12)
    np.testing.assert_array_equal(reference_velocity(targets, H, math.pi), raw)
    np.testing.assert_array_equal(targets, kept)
    for bad in (-0.1, math.nan):
        with pytest.raises(ValueError, match='cutoff'):
            reference_velocity(targets, H, bad)


def test_twist_calibration_against_the_wave_free_reference() -> None:
    """A twist that is the true LF velocity: exact against the low-passed reference.

    Against the targets' velocity as it is, the targets' own wave velocity (central difference:
    0.1 · sin(0.8) m/s amplitude, mean square 0.00257 m²/s²) is counted as twist error; with
    ``twist_cutoff`` 0.4 rad/s it is not (what is left: the filter's ends and the 0.4 % it
    passes).
    """
    n = 600
    times = np.arange(float(n)) * H
    targets = _ramp_with_wave(n)
    history = [Published(float(k), targets[k], np.array([0.3, 0.0, 0.0]), 'network',
                         np.zeros(3), np.zeros(3)) for k in range(n)]
    as_is = calibrate(history, times, targets, 3, H, 60)
    clean = calibrate(history, times, targets, 3, H, 60, twist_cutoff=0.4)
    assert as_is is not None and clean is not None
    wave_square = (0.1 * math.sin(0.8)) ** 2 / 2
    assert as_is[1]['all'].moment[0, 0] == pytest.approx(wave_square, rel=0.02)
    assert clean[1]['all'].moment[0, 0] < 0.02 * wave_square
    # the pose models do not depend on the twist's reference
    np.testing.assert_array_equal(as_is[0]['all'].hold, clean[0]['all'].hold)
    # nor the twist's on the pose's; against the low-passed targets the pose is off by the
    # targets' wave: 0.1 m amplitude, mean square 0.005 m², where it was exact (the ramp's
    # line is kept: no end error)
    pose_clean = calibrate(history, times, targets, 3, H, 60, pose_cutoff=0.4)
    assert pose_clean is not None
    np.testing.assert_array_equal(as_is[1]['all'].hold, pose_clean[1]['all'].hold)
    assert as_is[0]['all'].moment[0, 0] == pytest.approx(0.0, abs=1e-20)
    assert pose_clean[0]['all'].moment[0, 0] == pytest.approx(0.005, rel=0.02)
    lagging = targets[:, 0] - low_passed(targets, H, 0.4)[:, 0]
    assert np.max(np.abs(lagging)) < 0.11  # the wave alone, also at the ends
    with pytest.raises(ValueError, match='twist_reference_cutoff'):
        OdometryParams(twist_reference_cutoff=-0.5)


def test_attenuated_variance_is_what_the_zero_phase_filter_took() -> None:
    """A sinusoid of amplitude 1 at ω below the edge, passed through G = |H(ω)|² already.

    The part taken is (1 − G) sin, mean square (1 − G)²/2: matched within 1 % by the Hann
    estimate at 0.1–0.25 rad/s, with the targets' broadband notch at ω0 0.63 rad/s (G 0.85 to
    0.40); a frequency above the edge or where G < ATTENUATION_MIN_POWER counts nothing, and
    the input is not modified.
    """
    h = 0.1
    sos = design_wave_filter(0.63, h, notch_zeta=1.3)
    t = np.arange(12000) * h
    for omega in (0.1, 0.15, 0.2, 0.25):
        power = abs(complex(frequency_response(sos, [omega], h)[0])) ** 2
        series = power * np.column_stack([np.sin(omega * t), np.zeros_like(t)])
        kept = series.copy()
        taken = attenuated_variance(series, h, sos, 0.315)
        assert taken[0] == pytest.approx((1.0 - power) ** 2 / 2, rel=0.01)
        assert taken[1] == 0.0
        np.testing.assert_array_equal(series, kept)
    above_edge = attenuated_variance(np.sin(0.25 * t)[:, None], h, sos, 0.2)
    assert above_edge[0] < 1e-4  # the Hann window's leakage only
    in_the_notch = attenuated_variance(np.sin(0.63 * t)[:, None], h, sos, 1.0)
    assert in_the_notch[0] < 1e-4
    assert attenuated_variance(np.ones((10, 2)), h, sos, 0.3).tolist() == [0.0, 0.0]
    with pytest.raises(ValueError, match='edge'):
        attenuated_variance(series, h, sos, -1.0)
    # calibrate adds it to every twist model's holding part, only with a cutoff
    n = 3000
    times = np.arange(float(n)) * h
    targets = np.column_stack([5.0 * np.sin(0.15 * times), np.zeros(n), np.zeros(n)])
    history = [Published(float(k * h), targets[k], np.zeros(3), 'network', np.zeros(3),
                         np.zeros(3)) for k in range(n)]
    plain = calibrate(history, times, targets, 3, h, 60, twist_cutoff=0.315)
    added = calibrate(history, times, targets, 3, h, 60, twist_cutoff=0.315,
                      reference_filter=sos)
    no_cutoff = calibrate(history, times, targets, 3, h, 60, reference_filter=sos)
    bare = calibrate(history, times, targets, 3, h, 60)
    assert plain is not None and added is not None and no_cutoff is not None
    assert bare is not None
    expected = attenuated_variance(reference_velocity(targets, h), h, sos, 0.315)
    assert expected[0] > 0.0
    for key in plain[1]:
        np.testing.assert_allclose(np.diag(added[1][key].hold - plain[1][key].hold), expected,
                                   rtol=1e-12)
    np.testing.assert_array_equal(no_cutoff[1]['all'].hold, bare[1]['all'].hold)
    with pytest.raises(ValueError, match='finite'):
        attenuated_variance(np.full((20, 1), math.nan), h, sos, 0.3)


def test_likelihood_fit_recovers_the_model_and_makes_the_mean_nees_one() -> None:
    """Errors N(0, 0.01 + 0.5 a²) with a = 0 most of the time and up to 1 in a few 'turns'.

    Gaussian maximum likelihood recovers σ²_hold 0.01 and T² 0.5 within 15 % (seeded), and its
    score equations make the window's mean e²/σ² 1 exactly (least squares on e² gives 0.97
    here).
    """
    rng = np.random.default_rng(7)
    m = 20000
    a = np.zeros((m, 1))
    for start in range(1000, m, 2000):  # ten turns of 100 samples
        a[start:start + 100, 0] = np.sin(np.linspace(0.0, np.pi, 100))
    sigma2 = 0.01 + 0.5 * a[:, 0] ** 2
    e = (np.sqrt(sigma2) * rng.standard_normal(m)).reshape(-1, 1)
    ml = fit_error_model_likelihood(e, a)
    ls = fit_error_model(e, a)
    assert ml.hold[0, 0] == pytest.approx(0.01, rel=0.15)
    assert ml.gain[0] == pytest.approx(0.5, rel=0.15)
    fitted = ml.hold[0, 0] + ml.gain[0] * a[:, 0] ** 2
    assert np.mean(e[:, 0] ** 2 / fitted) == pytest.approx(1.0, abs=1e-6)
    plain = ls.hold[0, 0] + ls.gain[0] * a[:, 0] ** 2
    assert abs(np.mean(e[:, 0] ** 2 / plain) - 1.0) > 0.01


def test_pose_error_model_of_a_still_window_is_the_prior() -> None:
    """No motion (w ≡ 0 or constant): T² = prior², σ²_hold = the mean e²; no prior: T = 0."""
    rng = np.random.default_rng(4)
    errors = rng.normal(size=(500, 3)) * np.array([0.1, 0.2, 0.01])
    for rates in (np.zeros((500, 3)), np.full((500, 3), 0.01)):
        model = fit_error_model(errors, rates, 1.5)
        np.testing.assert_allclose(model.gain, [2.25, 2.25, 2.25])
        expected = np.maximum(np.mean(errors ** 2, axis=0) - 2.25 * rates[0] ** 2,
                              HOLD_FLOOR_FRACTION * np.mean(errors ** 2, axis=0))
        np.testing.assert_allclose(np.diag(model.hold), expected)
        assert fit_error_model(errors, rates, 0.0).gain.tolist() == [0.0, 0.0, 0.0]
    # a given gain (the lag time fitted on every source): only σ²_hold is fitted
    rates = rng.uniform(-0.2, 0.2, size=(500, 3))
    model = fit_error_model(errors, rates, 1.5, gain=np.array([0.5, 1.0, 0.0]))
    np.testing.assert_allclose(model.gain, [0.5, 1.0, 0.0])
    mean_e2 = np.mean(errors ** 2, axis=0)
    np.testing.assert_allclose(np.diag(model.hold), np.maximum(
        mean_e2 - np.array([0.5, 1.0, 0.0]) * np.mean(rates ** 2, axis=0),
        HOLD_FLOOR_FRACTION * mean_e2))
    # errors that shrink with motion give no negative lag; σ² stays above its floor
    rates = rng.uniform(-0.5, 0.5, size=(500, 1))
    errors = 0.1 * rng.normal(size=(500, 1)) / (1.0 + 10.0 * np.abs(rates))
    model = fit_error_model(errors, rates, 0.0)
    assert model.gain[0] == 0.0
    assert model.hold[0, 0] == pytest.approx(np.mean(errors ** 2))


def test_nees_of_a_known_covariance() -> None:
    errors = np.array([[1.0, 0.0], [0.0, 2.0]])
    covs = np.array([np.eye(2), np.diag([1.0, 4.0])])
    np.testing.assert_allclose(normalized_error_squared(errors, covs), [1.0, 1.0])
    with pytest.raises(ValueError, match='covariance'):
        normalized_error_squared(errors, np.eye(2))
