"""JONSWAP spectrum, cos-2s spreading and the random-phase discretization: analytic answers."""
from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.integrate

from sim_ros.physics.sea_spectrum import (
    bin_energies,
    cos2s_spreading,
    discretize_sea,
    elevation,
    jonswap,
    peak_frequency,
    spreading_normalization,
)


def _m0(hs: float, tp: float, gamma: float) -> float:
    """∫_0^∞ S dω by adaptive quadrature (split at ω_p and in the tail)."""
    wp = peak_frequency(tp)

    def spectrum(w: float) -> float:
        return float(jonswap(np.array([w]), hs, tp, gamma)[0])

    parts = [(0.0, wp), (wp, 4.0 * wp), (4.0 * wp, math.inf)]
    return sum(scipy.integrate.quad(spectrum, a, b, limit=400)[0] for a, b in parts)


@pytest.mark.parametrize(('gamma', 'tolerance'), [(1.0, 1e-6), (2.0, 0.01), (3.3, 0.01),
                                                  (5.0, 0.01), (7.0, 0.02)])
def test_jonswap_integrates_to_hs_squared_over_16(gamma: float, tolerance: float) -> None:
    """m0 = Hs²/16: exact for Pierson–Moskowitz, within DNV's A_γ fit otherwise."""
    hs, tp = 2.5, 9.0
    assert _m0(hs, tp, gamma) == pytest.approx(hs**2 / 16.0, rel=tolerance)


@pytest.mark.parametrize('gamma', [1.0, 3.3, 7.0])
def test_jonswap_peak_at_two_pi_over_tp(gamma: float) -> None:
    """The maximum of S is at ω_p = 2π/Tp; S scales with Hs²; S = 0 for ω <= 0."""
    tp = 8.0
    grid = np.linspace(0.2, 3.0, 280_001)
    spectrum = jonswap(grid, 3.0, tp, gamma)
    assert grid[np.argmax(spectrum)] == pytest.approx(2.0 * math.pi / tp, abs=2e-5)
    np.testing.assert_allclose(jonswap(grid, 6.0, tp, gamma), 4.0 * spectrum)
    np.testing.assert_array_equal(jonswap(np.array([-1.0, 0.0]), 3.0, tp, gamma), [0.0, 0.0])


def test_jonswap_rejects_bad_parameters() -> None:
    """γ outside DNV's range, Tp <= 0 and Hs < 0 are ValueErrors naming the parameter."""
    w = np.array([0.5])
    with pytest.raises(ValueError, match='γ'):
        jonswap(w, 2.0, 9.0, 0.5)
    with pytest.raises(ValueError, match='Tp'):
        jonswap(w, 2.0, 0.0)
    with pytest.raises(ValueError, match='Hs'):
        jonswap(w, -1.0, 9.0)


@pytest.mark.parametrize('s', [1.0, 2.0, 8.0, 25.0, 200.0])
def test_spreading_integrates_to_one(s: float) -> None:
    """∫D dθ = 1 over the circle, maximum at θ_m, symmetric about it."""
    mean = 0.7

    def density(t: float) -> float:
        return float(cos2s_spreading(np.array([t]), mean, s)[0])

    total = scipy.integrate.quad(density, mean - math.pi, mean + math.pi, limit=400,
                                 points=[mean])[0]
    assert total == pytest.approx(1.0, rel=1e-8)
    offsets = np.linspace(0.01, 3.0, 50)
    np.testing.assert_allclose(cos2s_spreading(mean + offsets, mean, s),
                               cos2s_spreading(mean - offsets, mean, s), rtol=1e-12)
    assert np.all(cos2s_spreading(mean + offsets, mean, s) < density(mean))


def test_spreading_closed_form_for_s_one() -> None:
    """Exponent s = 1: D(θ) = cos²(θ/2)/π = (1 + cos θ)/(2π), 2π-periodic."""
    assert spreading_normalization(1.0) == pytest.approx(1.0 / math.pi)
    theta = np.linspace(-math.pi, math.pi, 11)
    np.testing.assert_allclose(cos2s_spreading(theta, 0.0, 1.0),
                               (1.0 + np.cos(theta)) / (2.0 * math.pi), atol=1e-15)
    np.testing.assert_allclose(cos2s_spreading(theta + 2.0 * math.pi, 0.0, 3.0),
                               cos2s_spreading(theta, 0.0, 3.0), atol=1e-12)
    with pytest.raises(ValueError, match='spreading'):
        spreading_normalization(0.0)


def test_discretization_keeps_the_spectrum_energy() -> None:
    """ΣA²/2 = ∫S over [ω_lo, ω_hi]; frequencies random inside their bins, all distinct."""
    hs, tp, gamma = 3.0, 10.0, 3.3
    wp = peak_frequency(tp)
    sea = discretize_sea(hs, tp, gamma, 0.5, 8.0, 40, 8, np.random.default_rng(3))
    assert sea.frequency.shape == (320,) and sea.peak_freq == pytest.approx(wp)

    def spectrum(w: float) -> float:
        return float(jonswap(np.array([w]), hs, tp, gamma)[0])

    band = scipy.integrate.quad(spectrum, 0.5 * wp, 3.0 * wp, limit=400, points=[wp])[0]
    assert sea.variance == pytest.approx(band, rel=1e-8)
    assert sea.variance > 0.98 * hs**2 / 16.0  # the default range keeps > 98 % of m0
    edges = np.linspace(0.5 * wp, 3.0 * wp, 41)
    bins = np.repeat(np.arange(40), 8)
    assert np.all(sea.frequency >= edges[bins]) and np.all(sea.frequency <= edges[bins + 1])
    assert np.unique(sea.frequency).size == sea.frequency.size
    np.testing.assert_allclose(bin_energies(edges, hs, tp, gamma).sum(), band, rtol=1e-8)


def test_discretized_directions_follow_the_spreading() -> None:
    """Stratified directions: energy-weighted E[cos(θ − θ_m)] = s/(s + 1) for cos-2s."""
    s, mean = 6.0, -1.0
    sea = discretize_sea(2.0, 9.0, 3.3, mean, s, 4, 400, np.random.default_rng(5))
    weights = sea.amplitude**2 / np.sum(sea.amplitude**2)
    assert float(weights @ np.cos(sea.direction - mean)) == pytest.approx(s / (s + 1.0),
                                                                          rel=2e-3)
    assert float(weights @ np.sin(sea.direction - mean)) == pytest.approx(0.0, abs=5e-3)
    crested = discretize_sea(2.0, 9.0, 3.3, mean, None, 30, 1, np.random.default_rng(5))
    np.testing.assert_array_equal(crested.direction, np.full(30, mean))
    with pytest.raises(ValueError, match='long-crested'):
        discretize_sea(2.0, 9.0, 3.3, mean, None, 30, 4, np.random.default_rng(5))


def test_discretization_deterministic_per_seed() -> None:
    """The same seed gives the same sea; another seed other phases and frequencies."""
    args = (2.5, 9.0, 3.3, 0.3, 8.0, 20, 6)
    first = discretize_sea(*args, np.random.default_rng(11))
    again = discretize_sea(*args, np.random.default_rng(11))
    other = discretize_sea(*args, np.random.default_rng(12))
    for name in ('frequency', 'direction', 'amplitude', 'phase'):
        np.testing.assert_array_equal(getattr(first, name), getattr(again, name))
    assert not np.array_equal(first.phase, other.phase)
    assert not np.array_equal(first.frequency, other.frequency)
    np.testing.assert_array_equal(first.amplitude, other.amplitude)  # bin energies only


def test_elevation_variance_matches_components() -> None:
    """A long record of ζ(t) has the variance ΣA²/2 = Hs²/16 (≈ 2 % sampling error)."""
    sea = discretize_sea(2.0, 8.0, 3.3, 0.0, 10.0, 60, 4, np.random.default_rng(2))
    zeta = elevation(sea, np.arange(0.0, 40_000.0, 0.5))
    assert float(np.var(zeta)) == pytest.approx(sea.variance, rel=0.05)
    assert 4.0 * math.sqrt(sea.variance) == pytest.approx(2.0, rel=0.02)  # Hs
