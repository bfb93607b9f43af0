"""First-order (wave-frequency) disturbance: shaping filters driven by white noise.

Two models, both earth-fixed per DOF (north, east, yaw) with independent noise per DOF (an MSS
demo reuses one seed for all DOFs; we don't):

- **force superposition** (thesis eq. 5.2–5.4): τ_wave = H_HO(s) e with
  H_HO(s) = K_ω s² / (s² + 2λω0 s + ω0²)³, K_ω = 2 ω0³ λ σ. Realized as three cascaded
  second-order sections, state [x1, ẋ1, x2, ẋ2, x3, ẋ3]: ẍ1 = −ω0² x1 − 2λω0 ẋ1 + e,
  ẍ2 = … + x1, ẍ3 = … + x2, τ = K_ω ẍ3 = K_ω (x2 − ω0² x3 − 2λω0 ẋ3).
- **motion superposition** (Fossen 2011 §8.2.1; MSS wave library): η_w = H(s) w with
  H(s) = 2λω0σ s / (s² + 2λω0 s + ω0²); state ẋ1 = x2, ẋ2 = −ω0² x1 − 2λω0 x2 + 2λω0σ w,
  η_w = x2. Stationary variance λ ω0 σ².

e and w are continuous-time white noise of unit intensity, E[e(t) e(t')] = δ(t − t'). The
filters are discretized exactly (zero-order hold is not needed: the input is noise) with Van
Loan's method (Van Loan 1978, "Computing integrals involving the matrix exponential"): the
sampled state has exactly the covariance of the continuous process whatever the step, so
statistics do not depend on the step size. The filter is realized with σ = 1 and the output is
scaled by σ per DOF; when ω0 changes the discretization switches (ω0 is rounded to
`peak_freq_resolution`, each value discretized once and cached) and the state is carried over
whitened (`rescale_state`), so a step in ω0 gives no transient.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
import math

import numpy as np
import scipy.linalg

from sim_ros.physics.kinematics import FloatArray
from sim_ros.physics.schedule import PeakFreqSchedule

WAVE_MODELS = ('force', 'motion', 'none')
NDOF_WAVES = 3  # north, east, yaw


@dataclass(frozen=True)
class ShapingFilter:
    """Continuous LTI shaping filter ẋ = A x + G e, y = C x (σ = 1)."""

    a: FloatArray
    g: FloatArray
    c: FloatArray
    c_integrals: FloatArray  # (2, n): rows give ∫y dt and ∫∫y dt (force model; zeros else)


@dataclass(frozen=True)
class DiscreteShapingFilter:
    """Exact discretization x[k+1] = Ad x[k] + L z[k], z ~ N(0, I); y = C x."""

    ad: FloatArray
    noise_factor: FloatArray  # L with L Lᵀ = Qd
    c: FloatArray
    stationary_cov: FloatArray  # P, A P + P Aᵀ + G Gᵀ = 0
    c_integrals: FloatArray  # (2, n), see ShapingFilter


def _check(peak_freq: float, damping: float) -> None:
    if not (peak_freq > 0.0 and math.isfinite(peak_freq)):
        raise ValueError(f'wave peak frequency must be > 0 rad/s, got {peak_freq}')
    if not (0.0 < damping < 1.0):
        raise ValueError(f'wave damping λ must be in (0, 1) (typical 0.1), got {damping}')


def force_filter(peak_freq: float, damping: float, sigma: float = 1.0) -> ShapingFilter:
    """H_HO(s) = K_ω s²/(s² + 2λω0 s + ω0²)³, K_ω = 2ω0³λσ (thesis eq. 5.2–5.3)."""
    _check(peak_freq, damping)
    w2, d = peak_freq**2, 2.0 * damping * peak_freq
    a = np.zeros((6, 6))
    for section in range(3):
        i = 2 * section
        a[i, i + 1] = 1.0
        a[i + 1, i] = -w2
        a[i + 1, i + 1] = -d
        if section > 0:
            a[i + 1, i - 2] = 1.0  # driven by the previous section's position
    g = np.zeros((6, 1))
    g[1, 0] = 1.0
    gain = 2.0 * peak_freq**3 * damping * sigma  # K_ω, eq. 5.3
    c = gain * np.array([[0.0, 0.0, 1.0, 0.0, -w2, -d]])  # K_ω ẍ3
    # τ = K_ω ẍ3 has zero mean and zero-mean integrals: ∫τ = K_ω ẋ3, ∫∫τ = K_ω x3
    integrals = gain * np.array([[0.0, 0.0, 0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0, 1.0, 0.0]])
    return ShapingFilter(a, g, c, integrals)


def motion_filter(peak_freq: float, damping: float, sigma: float = 1.0) -> ShapingFilter:
    """H(s) = 2λω0σ s / (s² + 2λω0 s + ω0²) (anchors §3, Fossen 2011 eq. 8.118)."""
    _check(peak_freq, damping)
    a = np.array([[0.0, 1.0], [-peak_freq**2, -2.0 * damping * peak_freq]])
    g = np.array([[0.0], [2.0 * damping * peak_freq * sigma]])
    c = np.array([[0.0, 1.0]])
    return ShapingFilter(a, g, c, np.zeros((2, 2)))


def make_filter(model: str, peak_freq: float, damping: float, sigma: float = 1.0) -> ShapingFilter:
    """The shaping filter of `model` ('force' or 'motion')."""
    if model == 'force':
        return force_filter(peak_freq, damping, sigma)
    if model == 'motion':
        return motion_filter(peak_freq, damping, sigma)
    raise ValueError(f"wave model must be 'force' or 'motion', got {model!r}")


def stationary_covariance(shaping: ShapingFilter) -> FloatArray:
    """P solving the Lyapunov equation A P + P Aᵀ + G Gᵀ = 0."""
    p = scipy.linalg.solve_continuous_lyapunov(shaping.a, -shaping.g @ shaping.g.T)
    return np.asarray(0.5 * (p + p.T), dtype=np.float64)


def analytic_variance(model: str, peak_freq: float, damping: float, sigma: float) -> float:
    """Stationary output variance C P Cᵀ of the continuous filter (unit-intensity noise)."""
    shaping = make_filter(model, peak_freq, damping, sigma)
    return float((shaping.c @ stationary_covariance(shaping) @ shaping.c.T)[0, 0])


def van_loan(a: FloatArray, g: FloatArray, step: float) -> tuple[FloatArray, FloatArray]:
    """Exact (Ad, Qd) for ẋ = A x + G e, unit-intensity e, over `step` [s] (Van Loan 1978)."""
    n = a.shape[0]
    block = np.zeros((2 * n, 2 * n))
    block[:n, :n] = -a
    block[:n, n:] = g @ g.T
    block[n:, n:] = a.T
    expo = scipy.linalg.expm(block * step)
    ad = expo[n:, n:].T
    qd = ad @ expo[:n, n:]
    return np.asarray(ad, dtype=np.float64), np.asarray(0.5 * (qd + qd.T), dtype=np.float64)


def _factor(cov: FloatArray) -> FloatArray:
    """A square root L with L Lᵀ = cov for a PSD matrix (eigen-decomposition, robust)."""
    vals, vecs = np.linalg.eigh(cov)
    return np.asarray(vecs * np.sqrt(np.clip(vals, 0.0, None)), dtype=np.float64)


@lru_cache(maxsize=4096)
def discretize(model: str, peak_freq: float, damping: float, step: float) -> DiscreteShapingFilter:
    """Exact discretization of the unit-σ filter; cached per (model, ω0, λ, step)."""
    if not (step > 0.0):
        raise ValueError(f'wave filter step must be > 0 s, got {step}')
    shaping = make_filter(model, peak_freq, damping)
    ad, qd = van_loan(shaping.a, shaping.g, step)
    disc = DiscreteShapingFilter(ad, _factor(qd), shaping.c[0].copy(),
                                 stationary_covariance(shaping), shaping.c_integrals.copy())
    for arr in (disc.ad, disc.noise_factor, disc.c, disc.stationary_cov, disc.c_integrals):
        arr.setflags(write=False)
    return disc


def shaping_step(state: FloatArray, disc: DiscreteShapingFilter, noise: FloatArray) -> FloatArray:
    """Pure step: x[k+1] = Ad x[k] + L z[k] for a (ndof, n) stack of states."""
    return np.asarray(state @ disc.ad.T + noise @ disc.noise_factor.T, dtype=np.float64)


def rescale_state(state: FloatArray, old: DiscreteShapingFilter,
                  new: DiscreteShapingFilter) -> FloatArray:
    """Carry a (ndof, n) state stack across a change of ω0: x_new = L_new L_old⁻¹ x_old.

    L is the square root (``_factor``) of the filter's stationary covariance, so the whitened state
    L⁻¹ x is kept and a state that was typical for the old sea is typical for the new one. Keeping
    x itself is wrong for the force model: its states scale like ω0⁻⁶ (x3 of three cascaded
    sections with DC gain 1/ω0² each), so a step 0.3 → 1.25 rad/s multiplied the force by ~10³
    for a few wave periods and, integrated twice by a vessel without a position spring, left a
    permanent WF offset of kilometres. Pure: returns a new array.
    """
    whitened = np.linalg.pinv(_factor(old.stationary_cov)) @ state.T
    return np.asarray((_factor(new.stationary_cov) @ whitened).T, dtype=np.float64)


class WaveGenerator:
    """Wave-frequency signal per DOF (north, east, yaw), produced in blocks for speed.

    `next_block(count)` advances `count` steps of `step` [s] and returns the outputs at the end
    of each step (shape (count, 3)) and the ω0 used for each step. The state starts in the
    stationary distribution of ω0(0), so there is no warm-up transient. Randomness comes only from
    `rng`; the same generator seed reproduces the same signal.
    """

    def __init__(self, model: str, damping: float, sigma: FloatArray,
                 schedule: PeakFreqSchedule, step: float, rng: np.random.Generator,
                 peak_freq_resolution: float = 1e-3) -> None:
        """Set up the generator; see the class docstring."""
        if model not in ('force', 'motion'):
            raise ValueError(f"WaveGenerator model must be 'force' or 'motion', got {model!r}")
        sigma = np.asarray(sigma, dtype=np.float64)
        if sigma.shape != (NDOF_WAVES,) or np.any(sigma < 0.0):
            raise ValueError(f'wave sigma must be 3 values >= 0 (north, east, yaw), got {sigma}')
        if not (peak_freq_resolution > 0.0):
            raise ValueError('peak_freq_resolution must be > 0 rad/s (e.g. 1e-3)')
        self.model = model
        self.damping = float(damping)
        self.sigma = sigma
        self.schedule = schedule
        self.step = float(step)
        self.rng = rng
        self.resolution = float(peak_freq_resolution)
        self.steps_done = 0
        disc = self._disc(self.schedule(0.0))
        self._key = int(round(self.schedule(0.0) / self.resolution))
        self.state = rng.standard_normal((NDOF_WAVES, disc.ad.shape[0])) @ _factor(
            disc.stationary_cov).T
        self.output = (self.state @ disc.c) * self.sigma

    def continuous_filter(self) -> ShapingFilter:
        """The unit-σ continuous filter at the current (rounded) ω0."""
        peak = self.schedule(self.steps_done * self.step)
        quantized = round(round(peak / self.resolution) * self.resolution, 12)
        return make_filter(self.model, quantized, self.damping)

    def _disc(self, peak_freq: float) -> DiscreteShapingFilter:
        quantized = round(peak_freq / self.resolution) * self.resolution
        return discretize(self.model, round(quantized, 12), self.damping, self.step)

    def next_block(self, count: int) -> tuple[FloatArray, FloatArray]:
        """Advance `count` steps; return (outputs (count, 3), ω0 per step (count,))."""
        outputs, _, peak = self.next_block_with_impulses(count)
        return outputs, peak

    def next_block_with_impulses(self, count: int) -> tuple[FloatArray, FloatArray, FloatArray]:
        """As `next_block`, plus each step's exact integral ∫y dt of the output (count, 3).

        The force model's antiderivative is a state: ∫τ dt = K_ω ẋ3 (`ShapingFilter.c_integrals`
        row 0), so the impulse of step k is that row times (x[k] − x[k−1]) (x[k−1] carried
        across an ω0 change by `rescale_state` first). A quadrature of the sampled outputs
        (trapezoid) misses it by O(h³) per step, a zero-mean error that a vessel without a
        position spring integrates into a random walk of its WF mean (measured on the 1-DOF
        vessel: 0.10 / 0.025 / 0.007 m RMS of 300 s means at h = 0.1 / 0.05 / 0.025 s). Zeros
        for the motion model (its `c_integrals` are zero).
        """
        times = (self.steps_done + np.arange(count, dtype=np.float64)) * self.step
        peak = self.schedule.sample(times)
        keys = np.round(peak / self.resolution).astype(np.int64)
        dim = self.state.shape[1]
        noise = self.rng.standard_normal((count, NDOF_WAVES, dim))
        outputs = np.empty((count, NDOF_WAVES))
        impulses = np.empty((count, NDOF_WAVES))
        state = self.state
        start = 0
        while start < count:
            stop = start + int(np.argmax(keys[start:] != keys[start])) if np.any(
                keys[start:] != keys[start]) else count
            disc = self._disc(float(peak[start]))
            if int(keys[start]) != self._key:
                state = rescale_state(state, self._disc(self._key * self.resolution), disc)
                self._key = int(keys[start])
            forced = noise[start:stop] @ disc.noise_factor.T
            ad_t = np.ascontiguousarray(disc.ad.T)
            states = np.empty((stop - start + 1, NDOF_WAVES, dim))
            states[0] = state
            for k in range(stop - start):
                state = state @ ad_t + forced[k]
                states[k + 1] = state
            outputs[start:stop] = states[1:] @ disc.c
            impulses[start:stop] = np.diff(states @ disc.c_integrals[0], axis=0)
            start = stop
        self.state = state
        self.steps_done += count
        outputs *= self.sigma
        impulses *= self.sigma
        if count:
            self.output = outputs[-1].copy()
        return outputs, impulses, peak
