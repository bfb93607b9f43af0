"""Stability of a DP loop: bounded, and no limit cycle (issue 6 closed-loop target).

A loop is **stable** when it is bounded and shows no limit cycle over the scored part (after the
warm-up):

- **Bounded**: the run was not aborted (`ABORT_EXCURSION`), the true LF pose stayed finite, the
  horizontal excursion from the setpoint stayed ≤ max(`EXCURSION_FACTOR` × the ideal loop's
  maximum excursion, `EXCURSION_FLOOR`) and (3 DOF) the heading error ≤ max(`EXCURSION_FACTOR` ×
  the ideal loop's, `HEADING_FLOOR`). The ideal loop (PID on the true LF pose, same seed, same
  waves and noise) sets the scale of what the weather alone does to this vessel and controller;
  ten times that is far outside any estimator-induced degradation of a working loop, and the
  floors (5 m, 10°, about the red-alarm radius of a DP watch circle and a heading alarm) keep a
  very calm ideal run from declaring a harmless metre "unbounded".
- **No limit cycle**: for each DOF of the LF pose error e = η_LF − η_setpoint (heading wrapped,
  mean and linear trend removed), the strongest spectral line between `MIN_CYCLES` cycles per
  scored record and the lower edge of the wave band (the LF range a DP loop can oscillate in)
  is found on a Hann-windowed, 8× zero-padded periodogram; a sinusoid at that frequency is
  fitted by least squares. A limit cycle is a self-sustained periodic oscillation, so it is
  declared when that one sinusoid explains ≥ `LIMIT_CYCLE_SHARE` of the variance of e **and**
  its amplitude is ≥ `LIMIT_CYCLE_AMPLITUDE` (below that no DP operator would see it: the order
  of the position-reference noise). A stable PID loop (ζ = 1, no resonance) driven by random
  environmental forces has a broadband error: one sinusoid explains well under half of it (test:
  a seeded first-order Gauss–Markov error explains < 0.3; the thesis's unstable static-network
  loop, §5.4.2, oscillated). Only frequencies with ≥ 3 cycles in the record are checked, so a
  short scored record checks a narrower band (reported as ``checked_band``). A scenario with a
  periodic excitation (the 1-DOF multisine) makes even the ideal loop "oscillate": an
  oscillation the ideal loop shows at the same frequency with ≥ `FORCED_SHARE` of the amplitude
  is the forced response, not a limit cycle (``assess(..., reference=ideal offsets)``).

Thrust hitting its limit is reported (``saturated_fraction``, share of samples with any DOF of
the command at the limit) but is not part of the verdict: a saturated oscillation shows in e.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import signal

FloatArray = NDArray[np.float64]

EXCURSION_FACTOR = 10.0  # bound = this × the ideal loop's maximum excursion (or the floor)
EXCURSION_FLOOR = 5.0  # [m] smallest horizontal bound
HEADING_FLOOR = math.radians(10.0)  # [rad] smallest heading-error bound
ABORT_EXCURSION = 100.0  # [m] a closed-loop run is stopped here: diverged (unbounded)
LIMIT_CYCLE_SHARE = 0.5  # share of the LF error variance one sinusoid must explain
LIMIT_CYCLE_AMPLITUDE = (0.1, 0.1, math.radians(0.5))  # [m, m, rad] smallest cycle that counts
FORCED_SHARE = 0.5  # an oscillation with ≥ this × its amplitude in the ideal loop is forced
MIN_CYCLES = 3.0  # cycles of a frequency the scored record must hold for it to be checked
ZERO_PADDING = 8  # periodogram length / record length (finer peak location)
_YAW = 2


@dataclass(frozen=True)
class Oscillation:
    """The strongest LF sinusoid in a series: frequency [rad/s], amplitude, variance share."""

    frequency: float
    amplitude: float
    share: float


@dataclass(frozen=True)
class Stability:
    """Verdict of one loop (module docstring)."""

    stable: bool
    bounded: bool
    limit_cycle: bool
    reason: str
    excursion_bound: float  # [m]
    checked_band: tuple[float, float]  # [rad/s] frequencies searched for a limit cycle
    oscillations: tuple[Oscillation, ...]  # per DOF

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {'stable': self.stable, 'bounded': self.bounded, 'limit_cycle': self.limit_cycle,
                'reason': self.reason, 'excursion_bound': self.excursion_bound,
                'checked_band': list(self.checked_band),
                'oscillations': [{'frequency': o.frequency, 'amplitude': o.amplitude,
                                  'share': o.share} for o in self.oscillations]}


def dominant_oscillation(x: FloatArray, sample_time: float, max_freq: float,
                         min_cycles: float = MIN_CYCLES) -> Oscillation:
    """Strongest sinusoid of x (uniform samples) in [2π·min_cycles/T, max_freq) rad/s.

    Returns frequency [rad/s], amplitude (units of x) and the share of the variance of the
    detrended x it explains (least-squares fit at the periodogram peak); NaN frequency and zero
    share when the band is empty or x is constant.
    """
    values = np.asarray(x, dtype=np.float64)
    n = values.size
    if n < 8 or not np.all(np.isfinite(values)):
        return Oscillation(math.nan, 0.0, 0.0)
    detrended = signal.detrend(values, type='linear')
    variance = float(detrended @ detrended)
    if variance <= 0.0:
        return Oscillation(math.nan, 0.0, 0.0)
    nfft = ZERO_PADDING * (1 << (n - 1).bit_length())
    spectrum = np.abs(np.fft.rfft(detrended * np.hanning(n), nfft)) ** 2
    omega = 2.0 * math.pi * np.fft.rfftfreq(nfft, sample_time)  # [rad/s]
    inside = (omega >= 2.0 * math.pi * min_cycles / (n * sample_time)) & (omega < max_freq)
    if not np.any(inside):
        return Oscillation(math.nan, 0.0, 0.0)
    peak = float(omega[inside][int(np.argmax(spectrum[inside]))])
    amplitude, residual = _fit_sinusoid(detrended, sample_time, peak)
    return Oscillation(peak, amplitude, 1.0 - float(residual @ residual) / variance)


def amplitude_at(x: FloatArray, sample_time: float, frequency: float) -> float:
    """Amplitude of the least-squares sinusoid at ``frequency`` [rad/s] in detrended x."""
    values = np.asarray(x, dtype=np.float64)
    if values.size < 8 or not math.isfinite(frequency) or not np.all(np.isfinite(values)):
        return 0.0
    return _fit_sinusoid(signal.detrend(values, type='linear'), sample_time, frequency)[0]


def _fit_sinusoid(detrended: FloatArray, sample_time: float,
                  frequency: float) -> tuple[float, FloatArray]:
    """(amplitude, residual) of the least-squares a·cos + b·sin + c fit at ``frequency``."""
    t = np.arange(detrended.size) * sample_time
    design = np.column_stack([np.cos(frequency * t), np.sin(frequency * t),
                              np.ones(detrended.size)])
    coef = np.linalg.lstsq(design, detrended, rcond=None)[0]
    return float(math.hypot(coef[0], coef[1])), detrended - design @ coef


def checked_band(samples: int, sample_time: float, wave_band_low: float,
                 min_cycles: float = MIN_CYCLES) -> tuple[float, float]:
    """Frequencies [rad/s] searched for a limit cycle in a record of `samples` samples."""
    return (2.0 * math.pi * min_cycles / (samples * sample_time), wave_band_low)


def is_limit_cycle(oscillation: Oscillation, dof: int) -> bool:
    """The rule of the module docstring for one DOF (0 north, 1 east, 2 yaw)."""
    return (oscillation.share >= LIMIT_CYCLE_SHARE
            and oscillation.amplitude >= LIMIT_CYCLE_AMPLITUDE[dof])


def excursion_bounds(ideal_max_excursion: float, ideal_max_heading_error: float,
                     ) -> tuple[float, float]:
    """(horizontal [m], heading [rad]) bounds from the ideal loop (module docstring)."""
    return (max(EXCURSION_FACTOR * ideal_max_excursion, EXCURSION_FLOOR),
            max(EXCURSION_FACTOR * ideal_max_heading_error, HEADING_FLOOR))


def pose_offset(truth_lf_pose: FloatArray, setpoint: FloatArray, ndof: int) -> FloatArray:
    """LF pose − setpoint on the first ndof columns, heading wrapped to (−π, π].

    ``setpoint`` is one pose (3,) or one per sample (n, 3) (a setpoint schedule).
    """
    offset = truth_lf_pose[:, :ndof] - np.asarray(setpoint, dtype=np.float64)[..., :ndof]
    if ndof == 3:
        offset[:, _YAW] = np.angle(np.exp(1j * offset[:, _YAW]))
    return np.asarray(offset, dtype=np.float64)


def max_offsets(offset: FloatArray, ndof: int) -> tuple[float, float]:
    """(max horizontal excursion [m], max |heading error| [rad]; 0 for 1 DOF)."""
    if offset.shape[0] == 0:
        return math.nan, math.nan
    if ndof == 1:
        return float(np.max(np.abs(offset[:, 0]))), 0.0
    return (float(np.max(np.hypot(offset[:, 0], offset[:, 1]))),
            float(np.max(np.abs(offset[:, _YAW]))))


def assess(offset: FloatArray, sample_time: float, ndof: int, bounds: tuple[float, float],
           wave_band_low: float, aborted: bool,
           reference: FloatArray | None = None) -> Stability:
    """Stability of one loop from its scored LF pose offsets (n, ndof) (module docstring).

    ``reference``: the ideal loop's offsets on the same samples; an oscillation the ideal loop
    has too (≥ `FORCED_SHARE` of the amplitude at the same frequency) is the response to the
    scenario's own excitation, not a limit cycle.
    """
    band = checked_band(max(offset.shape[0], 1), sample_time, wave_band_low)
    finite = bool(np.all(np.isfinite(offset)))
    excursion, heading = max_offsets(offset, ndof) if finite else (math.inf, math.inf)
    reasons = []
    if aborted:
        reasons.append(f'diverged: left {ABORT_EXCURSION:g} m, run aborted')
    if not finite:
        reasons.append('non-finite pose')
    if offset.shape[0] == 0:
        reasons.append('no samples after the warm-up')
    elif not excursion <= bounds[0]:
        reasons.append(f'excursion {excursion:.3g} m > bound {bounds[0]:.3g} m')
    if ndof == 3 and offset.shape[0] > 0 and not heading <= bounds[1]:
        reasons.append(f'heading error {heading:.3g} rad > bound {bounds[1]:.3g} rad')
    bounded = not reasons
    oscillations = tuple(dominant_oscillation(offset[:, i], sample_time, wave_band_low)
                         for i in range(ndof)) if finite else ()
    cycles = [i for i, osc in enumerate(oscillations) if is_limit_cycle(osc, i)
              and not _forced(osc, reference, i, sample_time)]
    for i in cycles:
        osc = oscillations[i]
        reasons.append(f'limit cycle in DOF {i}: {osc.amplitude:.3g} at {osc.frequency:.3g} '
                       f'rad/s explains {osc.share:.0%} of the error variance')
    return Stability(stable=bounded and not cycles, bounded=bounded, limit_cycle=bool(cycles),
                     reason='; '.join(reasons) or 'bounded, no limit cycle',
                     excursion_bound=bounds[0], checked_band=band, oscillations=oscillations)


def _forced(oscillation: Oscillation, reference: FloatArray | None, dof: int,
            sample_time: float) -> bool:
    """True when the ideal loop oscillates at the same frequency with a comparable amplitude."""
    if reference is None or reference.shape[0] < 8:
        return False
    ideal = amplitude_at(reference[:, dof], sample_time, oscillation.frequency)
    return ideal >= FORCED_SHARE * oscillation.amplitude


def saturated_fraction(thrust_command: FloatArray, limit: FloatArray | None, ndof: int) -> float:
    """Share of samples whose command is at the limit [0, 1] on any of the first ndof DOFs."""
    if limit is None or thrust_command.shape[0] == 0:
        return 0.0
    at_limit = np.abs(thrust_command[:, :ndof]) >= np.asarray(limit)[:ndof] * (1.0 - 1e-9)
    return float(np.mean(np.any(at_limit, axis=1)))
