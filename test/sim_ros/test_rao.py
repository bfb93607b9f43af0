"""Parametric motion RAOs and the first-order wave motion they give (sim_ros.physics.rao)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from sim_ros.physics.rao import (
    RaoParams,
    motion_basis,
    motion_from_basis,
    motion_variance,
    rao,
    rao_amplitude_phase,
    wave_motion,
)
from sim_ros.physics.sea_spectrum import GRAVITY, WaveComponents, discretize_sea

PARAMS = RaoParams()


def _sea(seed: int = 4, spreading: float | None = 6.0, n_dir: int = 6) -> WaveComponents:
    return discretize_sea(2.5, 9.0, 3.3, math.radians(30.0), spreading, 30, n_dir,
                          np.random.default_rng(seed))


def test_rao_limits_head_and_beam_seas() -> None:
    """β = 0: surge only; β = 90°: sway only; long waves → gain 1 m/m; yaw zero in both."""
    long_wave = np.array([1e-4])
    amp, phase = rao_amplitude_phase(PARAMS, long_wave, np.array([0.0]))
    np.testing.assert_allclose(amp[:, 0], [1.0, 0.0, 0.0], atol=1e-5)
    assert phase[0, 0] == pytest.approx(math.pi / 2, abs=1e-3)  # −1 · e^{−iπ/2}
    amp, _ = rao_amplitude_phase(PARAMS, long_wave, np.array([math.pi / 2]))
    np.testing.assert_allclose(amp[:, 0], [0.0, 1.0, 0.0], atol=1e-5)
    # following sea: surge the same size with the opposite sign (motion continuous in β)
    ahead, astern = rao(PARAMS, long_wave, np.array([0.0])), rao(PARAMS, long_wave,
                                                                  np.array([math.pi]))
    np.testing.assert_allclose(astern[0], -ahead[0], atol=1e-15)


def test_rao_frequency_shape() -> None:
    """|G| = (1 + (ω/ω_c)²)^{−n/2}; yaw = K_ψ k |G| at β = 45°; → 0 for short waves."""
    params = RaoParams(yaw_gain=0.7, order=2)
    cutoff = params.cutoff_frequencies()
    assert cutoff[0] == pytest.approx(math.sqrt(2 * math.pi * GRAVITY / 76.2))  # λ = L
    omega = np.array([cutoff[0], 10.0 * cutoff[0]])
    amp, _ = rao_amplitude_phase(params, omega, np.zeros(2))
    np.testing.assert_allclose(amp[0], [0.5, 1.0 / 101.0], rtol=1e-12)
    amp, phase = rao_amplitude_phase(params, omega, np.full(2, math.pi / 4))
    k = omega**2 / GRAVITY
    expected = 0.7 * k / (1.0 + (omega / cutoff[2]) ** 2)
    np.testing.assert_allclose(amp[2], expected, rtol=1e-12)
    assert phase[2, 0] == pytest.approx(-math.pi / 2)  # two first-order lags at ω_c
    assert amp[0, 1] / math.cos(math.pi / 4) < 0.01


def test_rao_params_validated() -> None:
    """Bad parameters are ValueErrors naming the key."""
    with pytest.raises(ValueError, match='rao.length'):
        RaoParams(length=0.0)
    with pytest.raises(ValueError, match='rao.yaw_gain'):
        RaoParams(yaw_gain=-1.0)
    with pytest.raises(ValueError, match='rao.order'):
        RaoParams(order=0)


def test_motion_variance_matches_analytic_sum() -> None:
    """Fixed heading: variance of η_w (body) over a long record ≈ Σ A²|RAO|²/2 per DOF."""
    sea, heading = _sea(), 0.4
    times = np.arange(0.0, 30_000.0, 0.5)
    eta = wave_motion(sea, PARAMS, times, heading)
    c, s = math.cos(heading), math.sin(heading)
    body = np.stack([c * eta[:, 0] + s * eta[:, 1], -s * eta[:, 0] + c * eta[:, 1],
                     eta[:, 2]], axis=1)
    expected = motion_variance(sea, PARAMS, heading)
    np.testing.assert_allclose(np.var(body, axis=0), expected, rtol=0.06)
    assert np.all(expected > 0.0)


def test_wave_motion_equals_the_component_sum_with_turning() -> None:
    """η_w = R(ψ) Σ A Re[RAO(ω, θ − ψ) e^{i(ωt + φ)}] also while ψ(t) changes."""
    sea = _sea()
    times = np.linspace(0.0, 200.0, 801)
    heading = 0.2 + 0.01 * times  # a slow turn through 115°
    eta = wave_motion(sea, PARAMS, times, heading)
    value = rao(PARAMS, sea.frequency[None, :], sea.direction[None, :] - heading[:, None])
    body = np.real(value * sea.amplitude * np.exp(1j * (sea.frequency * times[:, None]
                                                         + sea.phase))).sum(axis=-1)
    c, s = np.cos(heading), np.sin(heading)
    np.testing.assert_allclose(eta[:, 0], c * body[0] - s * body[1], atol=1e-12)
    np.testing.assert_allclose(eta[:, 1], s * body[0] + c * body[1], atol=1e-12)
    np.testing.assert_allclose(eta[:, 2], body[2], atol=1e-14)
    basis = motion_basis(sea, PARAMS, times[100:101])[0].tolist()
    np.testing.assert_allclose(motion_from_basis(basis, float(heading[100])), eta[100],
                               atol=1e-12)


def test_rotation_when_the_heading_changes() -> None:
    """Long-crested sea from north: turning 90° puts the motion in sway (north unchanged axis).

    At ψ = 0 (head sea) the surge RAO moves the vessel north; at ψ = 90° (waves on the port beam)
    the sway RAO moves it north. So η_w,north(ψ = 90°) equals η_w,north(ψ = 0) of a vessel with
    the surge and sway RAOs swapped, and east and yaw stay zero in both.
    """
    sea = discretize_sea(2.0, 9.0, 3.3, 0.0, None, 40, 1, np.random.default_rng(9))
    times = np.arange(0.0, 300.0, 0.5)
    params = RaoParams(surge_gain=0.8, sway_gain=1.1, surge_cutoff=1.5, sway_cutoff=0.4)
    swapped = RaoParams(surge_gain=1.1, sway_gain=0.8, surge_cutoff=0.4, sway_cutoff=1.5)
    turned = wave_motion(sea, params, times, math.pi / 2)
    ahead = wave_motion(sea, swapped, times, 0.0)
    np.testing.assert_allclose(turned[:, 0], ahead[:, 0], atol=1e-12)
    np.testing.assert_allclose(turned[:, 1:], 0.0, atol=1e-12)
    np.testing.assert_allclose(ahead[:, 1:], 0.0, atol=1e-12)
    assert np.std(turned[:, 0]) > 0.1


def test_equal_surge_sway_raos_follow_the_particles_in_any_heading() -> None:
    """Surge and sway RAOs equal: the earth-frame motion does not depend on ψ; yaw does."""
    sea = _sea()
    params = RaoParams(sway_cutoff=1.0)
    times = np.arange(0.0, 200.0, 0.5)
    first = wave_motion(sea, params, times, 0.0)
    second = wave_motion(sea, params, times, 1.2)
    np.testing.assert_allclose(first[:, :2], second[:, :2], atol=1e-12)
    assert not np.allclose(first[:, 2], second[:, 2])


def test_pure_and_deterministic() -> None:
    """Inputs are not modified; the same sea and times give the same motion."""
    sea = _sea(seed=1)
    times = np.arange(0.0, 50.0, 0.1)
    heading = np.full(times.shape, 0.3)
    copies = [a.copy() for a in (sea.frequency, sea.direction, sea.amplitude, sea.phase,
                                 times, heading)]
    first = wave_motion(sea, PARAMS, times, heading)
    for before, after in zip(copies, (sea.frequency, sea.direction, sea.amplitude, sea.phase,
                                      times, heading), strict=True):
        np.testing.assert_array_equal(before, after)
    np.testing.assert_array_equal(first, wave_motion(_sea(seed=1), PARAMS, times, heading))
    assert not np.allclose(first, wave_motion(_sea(seed=2), PARAMS, times, heading))
