"""Irregular short-crested sea: JONSWAP spectrum, cos-2s spreading, random-phase components.

- **JONSWAP** (DNV-RP-C205 (2010) §3.5.5; Fossen 2011 §8.1, in ω):
      S_J(ω) = A_γ S_PM(ω) γ^exp(−(ω − ω_p)² / (2 σ² ω_p²)),
      S_PM(ω) = (5/16) H_s² ω_p⁴ ω⁻⁵ exp(−(5/4) (ω/ω_p)⁻⁴),   ω_p = 2π/T_p,
      A_γ = 1 − 0.287 ln γ,   σ = 0.07 (ω ≤ ω_p), 0.09 (ω > ω_p).
  ∫S dω = H_s²/16 (= m0, the elevation variance) exactly for γ = 1 (Pierson–Moskowitz) and
  within 2 % for 1 ≤ γ ≤ 7 (A_γ is DNV's fit; measured: +0.24 % at γ = 3.3, −1.8 % at γ = 7).
  The peak is at ω_p for every γ (both factors peak there). Units: S in m²·s/rad.
- **Directional spreading**, cos-2s (Longuet-Higgins, Cartwright & Smith 1963; DNV-RP-C205
  §3.5 gives the related cos^n form):
      D(θ) = Γ(s + 1) / (2 √π Γ(s + ½)) · cos^{2s}((θ − θ_m)/2),   θ − θ_m in (−π, π],
  ∫D dθ = 1 over the circle. Larger s is narrower (s ≈ 2–5 wind sea, 10–25 swell); `None` is
  long-crested (all energy at θ_m).
- **Discretization** (random-phase model, Fossen 2011 §8.1; DNV-RP-C205 §3.5): N equal
  frequency bins on [ω_lo, ω_hi] × M directions, one component per pair with amplitude
  A = √(2 S_bin D_bin), S_bin the bin integral of S (Gauss–Legendre) and D_bin = 1/M, so that
  ΣA²/2 = ∫_{ω_lo}^{ω_hi} S dω exactly. Each component has its own frequency drawn uniformly in
  its bin (no common period: the record never repeats), a direction drawn by stratified
  inverse-CDF sampling of D (the j-th direction from the j-th of M equal-probability strata, so
  each stratum holds 1/M of the energy), and a uniform phase in [0, 2π).

Directions θ are the direction the waves come **from**, clockwise from north (map_ned), in rad.
Pure functions of their arguments; randomness only from the `numpy.random.Generator` passed in.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
import scipy.special

from sim_ros.physics.kinematics import FloatArray

GRAVITY = 9.81  # m/s², deep-water dispersion ω² = g k
JONSWAP_SIGMA_LOW = 0.07  # spectral width σ_a for ω ≤ ω_p (DNV-RP-C205 §3.5.5)
JONSWAP_SIGMA_HIGH = 0.09  # spectral width σ_b for ω > ω_p
GAMMA_RANGE = (1.0, 7.0)  # validity of A_γ = 1 − 0.287 ln γ (DNV-RP-C205 §3.5.5)
DEFAULT_FREQ_RANGE = (0.5, 3.0)  # ω_lo/ω_p, ω_hi/ω_p; keeps > 98 % of m0 for 1 ≤ γ ≤ 7
_GAUSS_POINTS = 16  # Gauss–Legendre nodes per frequency bin
_CDF_GRID = 8193  # grid of the spreading CDF over the circle


@dataclass(frozen=True)
class WaveComponents:
    """Random-phase components of a sea: elevation ζ(t) = Σ A_k cos(ω_k t + φ_k) at the origin.

    `frequency` [rad/s], `direction` [rad, coming from, clockwise from north], `amplitude` [m],
    `phase` [rad]; all shape (K,). `peak_freq` [rad/s] is ω_p of the spectrum they sample.
    """

    frequency: FloatArray
    direction: FloatArray
    amplitude: FloatArray
    phase: FloatArray
    peak_freq: float

    def __post_init__(self) -> None:
        """Check: equal 1-D shapes, finite, ω > 0, A >= 0."""
        shape = self.frequency.shape
        arrays = (self.frequency, self.direction, self.amplitude, self.phase)
        if len(shape) != 1 or any(a.shape != shape for a in arrays):
            raise ValueError('wave components need 1-D frequency, direction, amplitude and '
                             'phase arrays of the same length')
        if not all(np.all(np.isfinite(a)) for a in arrays):
            raise ValueError('wave components must be finite')
        if np.any(self.frequency <= 0.0) or np.any(self.amplitude < 0.0):
            raise ValueError('wave component frequencies must be > 0 rad/s, amplitudes >= 0 m')

    @property
    def variance(self) -> float:
        """Elevation variance ΣA²/2 [m²] (the discretized m0)."""
        return float(0.5 * np.sum(self.amplitude**2))


def peak_frequency(tp: float) -> float:
    """ω_p = 2π/T_p [rad/s] for the peak period `tp` [s]."""
    if not (tp > 0.0 and math.isfinite(tp)):
        raise ValueError(f'peak period Tp must be > 0 s, got {tp}')
    return 2.0 * math.pi / tp


def check_sea(hs: float, tp: float, gamma: float) -> None:
    """ValueError unless Hs >= 0 m, Tp > 0 s and 1 <= γ <= 7 (JONSWAP validity)."""
    if not (hs >= 0.0 and math.isfinite(hs)):
        raise ValueError(f'significant wave height Hs must be >= 0 m, got {hs}')
    peak_frequency(tp)
    if not (GAMMA_RANGE[0] <= gamma <= GAMMA_RANGE[1]):
        raise ValueError(f'JONSWAP peak enhancement γ must be in [{GAMMA_RANGE[0]:g}, '
                         f'{GAMMA_RANGE[1]:g}] (3.3 is the mean North Sea value), got {gamma}')


def jonswap(omega: FloatArray, hs: float, tp: float, gamma: float = 3.3) -> FloatArray:
    """JONSWAP S(ω) [m²·s/rad] at `omega` [rad/s] for Hs [m], Tp [s], γ (DNV-RP-C205 §3.5.5).

    S(ω) = 0 for ω <= 0. Returns a new array of the shape of `omega`.
    """
    check_sea(hs, tp, gamma)
    w = np.asarray(omega, dtype=np.float64)
    wp = peak_frequency(tp)
    positive = w > 0.0
    safe = np.where(positive, w, wp)
    s_pm = 5.0 / 16.0 * hs**2 * wp**4 * safe**-5 * np.exp(-1.25 * (safe / wp) ** -4)
    width = np.where(safe <= wp, JONSWAP_SIGMA_LOW, JONSWAP_SIGMA_HIGH)
    peak = gamma ** np.exp(-0.5 * ((safe - wp) / (width * wp)) ** 2)
    a_gamma = 1.0 - 0.287 * math.log(gamma)
    return np.asarray(np.where(positive, a_gamma * s_pm * peak, 0.0), dtype=np.float64)


def spreading_normalization(s: float) -> float:
    """C(s) = Γ(s + 1) / (2 √π Γ(s + ½)) of the cos-2s spreading function."""
    if not (s > 0.0 and math.isfinite(s)):
        raise ValueError(f'spreading exponent s must be > 0 (None for long-crested), got {s}')
    log_c = scipy.special.gammaln(s + 1.0) - scipy.special.gammaln(s + 0.5)
    return float(math.exp(log_c) / (2.0 * math.sqrt(math.pi)))


def cos2s_spreading(theta: FloatArray, mean_direction: float, s: float) -> FloatArray:
    """D(θ) [1/rad] = C(s) cos^{2s}((θ − θ_m)/2), ∫D dθ = 1 over any 2π interval."""
    c = spreading_normalization(s)
    half = 0.5 * (np.asarray(theta, dtype=np.float64) - mean_direction)
    # |cos| keeps the function 2π-periodic; cos² of the half angle is (1 + cos(θ − θ_m))/2
    return np.asarray(c * np.abs(np.cos(half)) ** (2.0 * s), dtype=np.float64)


def bin_energies(edges: FloatArray, hs: float, tp: float, gamma: float) -> FloatArray:
    """∫S dω over each bin [edges[i], edges[i+1]] [m²] (Gauss–Legendre, 16 nodes per bin)."""
    nodes, weights = np.polynomial.legendre.leggauss(_GAUSS_POINTS)
    lo, hi = np.asarray(edges[:-1]), np.asarray(edges[1:])
    half = 0.5 * (hi - lo)
    points = (0.5 * (hi + lo))[:, None] + half[:, None] * nodes[None, :]
    return np.asarray(half * (jonswap(points, hs, tp, gamma) @ weights), dtype=np.float64)


def spreading_quantiles(probabilities: FloatArray, mean_direction: float,
                        s: float | None) -> FloatArray:
    """Directions θ [rad] with ∫_{θ_m−π}^{θ} D = p (inverse CDF of cos-2s); θ_m if s is None."""
    p = np.asarray(probabilities, dtype=np.float64)
    if s is None:
        return np.full(p.shape, float(mean_direction))
    offset = np.linspace(-math.pi, math.pi, _CDF_GRID)
    density = cos2s_spreading(offset, 0.0, s)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(offset))])
    cdf /= cdf[-1]  # remove the (tiny) trapezoid error so the quantiles span exactly (−π, π]
    return np.asarray(mean_direction + np.interp(p, cdf, offset), dtype=np.float64)


def discretize_sea(hs: float, tp: float, gamma: float, mean_direction: float,
                   spreading: float | None, n_freq: int, n_dir: int, rng: np.random.Generator,
                   freq_range: tuple[float, float] = DEFAULT_FREQ_RANGE) -> WaveComponents:
    """N × M random-phase components of a JONSWAP sea with cos-2s spreading (module docstring).

    `freq_range` is (ω_lo, ω_hi) as multiples of ω_p. Draws, in this order, N·M uniform
    frequency offsets, N·M direction offsets and N·M phases from `rng`, so a seed reproduces
    the sea. Long-crested (`spreading` None) needs n_dir = 1.
    """
    check_sea(hs, tp, gamma)
    if n_freq < 1 or n_dir < 1:
        raise ValueError(f'need at least 1 frequency and 1 direction, got {n_freq} × {n_dir}')
    if spreading is None and n_dir != 1:
        raise ValueError('a long-crested sea (spreading None) has 1 direction; set components '
                         f'to [{n_freq}, 1] or give a spreading exponent s > 0')
    if spreading is not None:
        spreading_normalization(spreading)  # validates s
    lo_rel, hi_rel = freq_range
    if not (0.0 < lo_rel < 1.0 < hi_rel and math.isfinite(hi_rel)):
        raise ValueError(f'freq_range (ω_lo/ω_p, ω_hi/ω_p) must satisfy 0 < lo < 1 < hi, got '
                         f'{freq_range}')
    wp = peak_frequency(tp)
    edges = np.linspace(lo_rel * wp, hi_rel * wp, n_freq + 1)
    energy = bin_energies(edges, hs, tp, gamma)  # (N,) m²
    count = n_freq * n_dir
    freq_u = rng.random(count)
    dir_u = rng.random(count)
    phase = rng.uniform(0.0, 2.0 * math.pi, count)
    bins = np.repeat(np.arange(n_freq), n_dir)
    strata = np.tile(np.arange(n_dir), n_freq)
    frequency = edges[bins] + freq_u * (edges[1] - edges[0])
    direction = spreading_quantiles((strata + dir_u) / n_dir, mean_direction, spreading)
    amplitude = np.sqrt(2.0 * energy[bins] / n_dir)
    return WaveComponents(np.asarray(frequency, dtype=np.float64), direction,
                          np.asarray(amplitude, dtype=np.float64),
                          np.asarray(phase, dtype=np.float64), wp)


def elevation(components: WaveComponents, times: FloatArray) -> FloatArray:
    """Wave elevation ζ(t) [m] at the origin: Σ A_k cos(ω_k t + φ_k), shape of `times`."""
    t = np.asarray(times, dtype=np.float64)
    chi = t[..., None] * components.frequency + components.phase
    return np.asarray(np.cos(chi) @ components.amplitude, dtype=np.float64)


__all__ = ['DEFAULT_FREQ_RANGE', 'GRAVITY', 'WaveComponents', 'bin_energies', 'check_sea',
           'cos2s_spreading', 'discretize_sea', 'elevation', 'jonswap', 'peak_frequency',
           'spreading_normalization', 'spreading_quantiles']
