"""Tests of the output notch of `core.predictor.AdaptivePredictor` (``output_notch_zeta``).

Issue 13: the learned filter lets part of the wave peak through, which a DP loop turns into
wave-band thrust. With ``output_notch_zeta`` ζ > 0 the published estimate runs through a causal
notch at the current ω0 estimate (depth ``notch_depth``). Small Algorithm 4.1 windows at h = 1 s
as in test_bumpless.py; the first ω0 estimate comes after 60 samples, the first training after
120, both inline.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
import pytest
from scipy import signal

from lf_predictor_ros.core.filters import design_wave_filter
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.predictor import AdaptivePredictor

pytestmark = pytest.mark.filterwarnings(
    'ignore:`torch.jit.script` is deprecated:DeprecationWarning'
)

FloatArray = NDArray[np.float64]
WAVE_PEAK_FREQ = 0.8  # [rad/s]
SMALL = PredictorParams(ndof=3, sample_time=1.0, retrain_period=20.0, training_window=200.0,
                        transient_length=10.0, filter_window=60.0, append_length=40.0,
                        estimation_window=480.0, max_epochs=3, nu=4, ny=12,
                        initial_wave_peak_freq=WAVE_PEAK_FREQ)


def poses(n: int, seed: int = 0) -> tuple[FloatArray, FloatArray]:
    """(t, pose) with a wave at ω0 in north and east on a slow drift, heading across ±π."""
    rng = np.random.default_rng(seed)
    t = np.arange(float(n))
    pose = np.column_stack([
        0.5 * np.sin(WAVE_PEAK_FREQ * t) + 0.01 * t,
        0.3 * np.cos(WAVE_PEAK_FREQ * t + 0.4) - 2.0,
        math.pi - 0.3 + 0.002 * t + 0.01 * np.sin(WAVE_PEAK_FREQ * t),
    ]) + rng.normal(0.0, 0.01, (n, 3))
    pose[:, 2] = np.angle(np.exp(1j * pose[:, 2]))  # wrapped, as a compass gives it
    return t, pose


def outputs(params: PredictorParams, t: FloatArray, pose: FloatArray) -> FloatArray:
    predictor = AdaptivePredictor(params, background=False)
    force = np.zeros(3)
    return np.array([predictor.update(t[k], pose[k], force) for k in range(len(t))])


def test_the_published_estimate_is_the_notch_of_the_estimate_without_it() -> None:
    """Before the first ω0 estimate the notch sits at the prior: scipy's sosfilt on the output."""
    t, pose = poses(55)
    plain = outputs(SMALL, t, pose)
    notched = outputs(SMALL.replace(output_notch_zeta=0.5), t, pose)
    sos = design_wave_filter(WAVE_PEAK_FREQ, 1.0, notch_zeta=0.5, notch_depth=SMALL.notch_depth,
                             lowpass_offset=None)
    channels = plain.copy()
    channels[:, 2] = np.unwrap(channels[:, 2])
    expected = np.column_stack([
        signal.sosfilt(sos, channels[:, i], zi=signal.sosfilt_zi(sos) * channels[0, i])[0]
        for i in range(3)])
    expected[:, 2] = np.angle(np.exp(1j * expected[:, 2]))
    np.testing.assert_allclose(notched, expected, rtol=0.0, atol=1e-12)
    assert np.all(np.abs(notched[:, 2]) <= math.pi)


def sea(n: int, seed: int = 0) -> tuple[FloatArray, FloatArray]:
    """(t, pose): three wave lines (the peak at ω0) on a ramp in north and east, heading drift."""
    rng = np.random.default_rng(seed)
    t = np.arange(float(n))

    def waves(phase: float) -> FloatArray:
        return np.asarray(0.5 * np.sin(WAVE_PEAK_FREQ * t + phase)
                          + 0.3 * np.sin(0.65 * t + 1.0 + phase)
                          + 0.3 * np.sin(0.95 * t + 2.0 + phase), dtype=np.float64)

    pose = np.column_stack([waves(0.0) + RAMP[0] * t, 0.6 * waves(0.4) + RAMP[1] * t - 2.0,
                            0.3 + 0.02 * waves(1.0)]) + rng.normal(0.0, 0.01, (n, 3))
    return t, pose


RAMP = (0.01, -0.02)  # [m/s] north, east


def test_the_notch_follows_omega0_takes_out_the_peak_and_delays_a_ramp_analytically() -> None:
    """Prior ω0 0.6 rad/s, the sea's peak at 0.8 rad/s; trainings and ω0 estimates inline.

    - the notch is retuned to every new ω0 estimate;
    - the ω0 line of the published north estimate drops to a fraction (gain notch_depth at ω0);
    - a ramp of rate r comes out delayed by the notch's DC group delay τ = 2ζ(1 − d)/ω0
      (H(s) = (s² + 2dζω0 s + ω0²)/(s² + 2ζω0 s + ω0²), τ = −H′(0)), so the notched estimate
      lies r·τ behind the plain one.
    """
    zeta = 0.5
    params = SMALL.replace(initial_wave_peak_freq=0.6)
    t, pose = sea(400)
    plain = outputs(params, t, pose)
    predictor = AdaptivePredictor(params.replace(output_notch_zeta=zeta), background=False)
    notched = np.array([predictor.update(t[k], pose[k], np.zeros(3)) for k in range(len(t))])
    omega0 = predictor.wave_peak_freq
    assert omega0 is not None and abs(omega0 - WAVE_PEAK_FREQ) < 0.05, omega0
    assert predictor._output_notch is not None
    assert predictor._output_notch.wave_peak_freq == omega0

    late = slice(250, 400)
    tt = t[late]
    basis = np.column_stack([np.sin(WAVE_PEAK_FREQ * tt), np.cos(WAVE_PEAK_FREQ * tt),
                             np.sin(0.65 * tt), np.cos(0.65 * tt), np.sin(0.95 * tt),
                             np.cos(0.95 * tt), np.ones(tt.size), tt])
    fit_plain = np.linalg.lstsq(basis, plain[late, :2], rcond=None)[0]
    fit_notched = np.linalg.lstsq(basis, notched[late, :2], rcond=None)[0]
    line_plain = np.hypot(fit_plain[0, 0], fit_plain[1, 0])
    line_notched = np.hypot(fit_notched[0, 0], fit_notched[1, 0])
    assert line_plain > 1e-3, line_plain  # the learned filter lets a little of the peak through
    assert line_notched < 0.3 * line_plain, (line_notched, line_plain)
    delay = 2.0 * zeta * (1.0 - SMALL.notch_depth) / omega0  # [s]
    for dof in (0, 1):
        assert fit_notched[7, dof] == pytest.approx(fit_plain[7, dof], abs=2e-4)  # same rate
        lag = fit_plain[6, dof] - fit_notched[6, dof]  # at equal rates: r·τ
        assert lag == pytest.approx(RAMP[dof] * delay, rel=0.15), (dof, lag, RAMP[dof] * delay)


def test_one_dof_passes_east_and_heading_through() -> None:
    t, pose = poses(80)
    params = SMALL.replace(ndof=1, output_notch_zeta=0.3)
    notched = outputs(params, t, pose)
    np.testing.assert_array_equal(notched[:, 1:], pose[:, 1:])
    assert not np.allclose(notched[:, 0], outputs(SMALL.replace(ndof=1), t, pose)[:, 0])


def test_a_non_finite_output_passes_and_the_notch_restarts_without_a_step() -> None:
    predictor = AdaptivePredictor(SMALL.replace(output_notch_zeta=0.5), background=False)
    first = predictor._notched(0.0, np.array([1.0, 2.0, 0.1]))
    np.testing.assert_allclose(first, [1.0, 2.0, 0.1], atol=1e-12)  # starts in steady state
    hole = predictor._notched(1.0, np.array([np.nan, 2.0, 0.1]))
    assert np.isnan(hole[0]) and hole[1] == 2.0
    after = predictor._notched(2.0, np.array([5.0, -1.0, -0.2]))
    np.testing.assert_allclose(after, [5.0, -1.0, -0.2], atol=1e-12)  # restarted: no transient


def test_a_negative_width_is_refused() -> None:
    with pytest.raises(ValueError, match='output_notch_zeta'):
        SMALL.replace(output_notch_zeta=-0.1)
