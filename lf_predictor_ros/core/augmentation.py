"""Wave-invariance augmentation of a training window (our addition to thesis §4.3).

The thesis trains the network on the newest N samples only, so the learned filter is defined by
the sea it has seen: at frequencies where the window holds no wave energy its gain is whatever
the fit left there. Measured on the Fig. 4.1 steps: the filter learned in a 0.3 rad/s sea passed
1.25 rad/s motion with gain 0.99, the one learned at 1.25 rad/s passed 0.3 rad/s with gain 1.14,
so for the Δs after every change of sea state the predictor put the new waves into the LF pose.

A DP engineer knows more than the window shows: the target filter (notch at ω0 + low-pass,
thesis §4.2.2) says what the LF estimate of *any* motion is, not only of the motion in the window.
This module turns that into data. It appends to the window a copy of itself with synthetic motion
added to the measured positions: band-limited Gaussian motion with a flat spectrum over
[ωLP, Nyquist] (above the target filter's low-pass cutoff, where the window of a narrow-band sea
holds nothing) and an RMS of the window's own wave motion times ``wave_augmentation``; the copy's
targets are the window's targets plus that motion's zero-phase target-filter output (≈ 0 there:
`periodic_zero_phase`, exact for the periodic motion). The forces are unchanged (waves move the
vessel, not the thrust). The fit is thus asked to reject, as the targets do, frequencies the sea
has not shown yet: a stop band learned along with the data. The copy's first ``guard`` targets
are masked (their regressors would reach back across the join into the real window).

Putting the motion over the whole wave band instead (from 0.25 rad/s) fought the targets below
ωLP: the candidate got worse on the real window and was rejected for up to a third of the
retrainings (docs/BENCHMARKS.md, round 3).

**LF-motion augmentation** (issue 13). In station keeping the window holds almost no LF motion,
so nothing in it fixes how the learned filter responds to a moving vessel: a setpoint move or a
turn shows up as a lag of the estimate (measured on rao_supply: 1.1 m during a 15 m move, 0.055
rad in a 45° turn, against 0.07 m / 0.002 rad while holding position; docs/BENCHMARKS.md). A
second copy of the window gets band-limited motion over ``LF_MOTION_BAND`` (below the DP control
bandwidth, where a DP vessel's own LF motion lives) added to the positions *and* to the targets
(through the target filter: ≈ 1 there), with a given RMS velocity per DOF: the fit is asked to
pass LF motion without lag, as the targets do. The forces are unchanged (the synthetic motion
plays the role of an unmeasured slow force such as current).

Pure functions of numpy arrays; the random motion comes from a seeded generator, so a retraining
is reproducible.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from lf_predictor_ros.core.filters import frequency_response

FloatArray = NDArray[np.float64]

# Band of the synthetic LF motion [rad/s]: up to the usual DP control bandwidth ω_n ≈ 0.1 rad/s
# (Fossen 2011 §12.2; the supply vessel's PID here: 0.1/0.1/0.2 rad/s, setpoint filter 10 s).
LF_MOTION_BAND = (0.0, 0.1)


def band_limited_motion(n_samples: int, channels: int, sample_time: float,
                        band: tuple[float, float], rms: FloatArray,
                        rng: np.random.Generator) -> FloatArray:
    """Gaussian motion (n_samples, channels) with a flat spectrum on ``band`` [rad/s].

    White noise with every FFT bin outside ``band`` zeroed, then scaled per channel to exactly
    ``rms`` (channels with rms 0 stay 0). ``band`` is clipped to (0, π / sample_time].
    """
    if n_samples < 2:
        raise ValueError(f'need at least 2 samples of motion, got {n_samples}')
    rms = np.broadcast_to(np.asarray(rms, dtype=np.float64), (channels,))
    if not np.all(np.isfinite(rms)) or np.any(rms < 0.0):
        raise ValueError(f'rms must be finite and ≥ 0 per channel, got {rms}')
    low, high = band
    nyquist = math.pi / sample_time
    if not 0.0 <= low < min(high, nyquist):
        raise ValueError(f'band {band} rad/s must satisfy 0 ≤ low < high and low < Nyquist '
                         f'{nyquist:.4g} rad/s')
    omega = 2.0 * math.pi * np.fft.rfftfreq(n_samples, d=sample_time)  # [rad/s]
    inside = (omega >= low) & (omega <= high)
    if not inside.any():
        raise ValueError(f'no frequency bin of a {n_samples}-sample window lies in {band} rad/s: '
                         'lengthen the window or widen the band')
    spectrum = np.fft.rfft(rng.standard_normal((n_samples, channels)), axis=0)
    spectrum[~inside] = 0.0
    motion = np.fft.irfft(spectrum, n=n_samples, axis=0)
    level = np.sqrt(np.mean(motion ** 2, axis=0))
    result: FloatArray = motion * np.where(level > 0.0, rms / np.where(level > 0.0, level, 1.0),
                                           0.0)
    return result


def lf_motion(n_samples: int, sample_time: float, rms_velocity: FloatArray,
              rng: np.random.Generator) -> FloatArray:
    """Band-limited LF motion (n_samples, len(rms_velocity)) over ``LF_MOTION_BAND``.

    Its finite-difference velocity has exactly ``rms_velocity`` RMS per channel (0: no motion).
    """
    speeds = np.asarray(rms_velocity, dtype=np.float64)
    if speeds.ndim != 1 or not np.all(np.isfinite(speeds)) or np.any(speeds < 0.0):
        raise ValueError(f'rms_velocity must be finite and ≥ 0 per channel, got {speeds}')
    unit = band_limited_motion(n_samples, speeds.size, sample_time, LF_MOTION_BAND,
                               np.ones(speeds.size), rng)
    velocity = np.sqrt(np.mean((np.diff(unit, axis=0) / sample_time) ** 2, axis=0))
    scaled: FloatArray = unit * np.where(velocity > 0.0, speeds / np.where(
        velocity > 0.0, velocity, 1.0), 0.0)
    return scaled


def periodic_zero_phase(motion: FloatArray, sos: FloatArray, sample_time: float) -> FloatArray:
    """Zero-phase filtering of a periodic series: every bin times |H(e^{jωh})|², exactly.

    What `filters.zero_phase` (forward-backward) does to a signal, without its edge transients,
    which a series made by an inverse FFT (``band_limited_motion``) does not have.
    """
    n = motion.shape[0]
    omega = 2.0 * math.pi * np.fft.rfftfreq(n, d=sample_time)
    gain = np.abs(frequency_response(sos, omega, sample_time)) ** 2
    spectrum = np.fft.rfft(motion, axis=0) * gain.reshape((-1,) + (1,) * (motion.ndim - 1))
    filtered: FloatArray = np.fft.irfft(spectrum, n=n, axis=0)
    return filtered


Window = tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]  # u, y, targets, mask


def augment_window(u: FloatArray, y: FloatArray, targets: FloatArray, mask: NDArray[np.bool_],
                   motion: FloatArray, motion_targets: FloatArray, guard: int) -> Window:
    """The window followed by its `augmented_copy` (new arrays, inputs untouched)."""
    copy = augmented_copy(u, y, targets, mask, motion, motion_targets, guard)
    return (np.concatenate([u, copy[0]]), np.concatenate([y, copy[1]]),
            np.concatenate([targets, copy[2]]), np.concatenate([mask, copy[3]]))


def augmented_copy(u: FloatArray, y: FloatArray, targets: FloatArray, mask: NDArray[np.bool_],
                   motion: FloatArray, motion_targets: FloatArray, guard: int) -> Window:
    """A copy of the window with ``motion`` added (new arrays, inputs untouched).

    ``u`` (n, k), ``y`` and ``targets`` (n, ndof), ``mask`` (n,), ``motion`` (n, ndof) added to
    y, ``motion_targets`` (n, ndof) added to the targets (the target filter's output for the
    motion); ``guard`` ≥ 1 (the longest regressor + 1): targets masked at the start of the copy,
    whose regressors would reach into the previous window.
    """
    n = y.shape[0]
    if motion.shape != y.shape or motion_targets.shape != y.shape or targets.shape[0] != n \
            or u.shape[0] != n or mask.shape != (n,):
        raise ValueError(f'augmented_copy needs u, y, targets, mask and motion of one length '
                         f'with motion shaped like y {y.shape}; got u {u.shape}, targets '
                         f'{targets.shape}, mask {mask.shape}, motion {motion.shape}')
    if guard < 1:
        raise ValueError(f'guard must be ≥ 1 sample, got {guard}')
    copy_mask = mask.copy()
    copy_mask[:guard] = False
    return u.copy(), y + motion, targets + motion_targets, copy_mask
