"""Wave peak frequency estimate from past positions (thesis §4.2.1, Algorithm 4.1 l. 19–23).

The measured position is dominated by the low-frequency (LF) motion; the wave-frequency (WF)
oscillation is a smaller bump in the spectrum (thesis Fig. 4.6). The estimate therefore

1. removes the LF motion with a 2nd-order Butterworth high-pass at ``highpass_cutoff`` ωHP
   (thesis §4.2.1), applied forward-backward (zero-phase: the data is back-dated, so causality is
   not needed, and the squared magnitude suppresses the LF motion twice as hard);
2. estimates the power spectral density with Welch's method and a Hamming window (thesis §4.2.1,
   Welch 1967; MATLAB ``pwelch`` in the thesis, ``scipy.signal.welch`` here), each segment
   linearly detrended;
3. divides the PSD inside the wave band by the high-pass power response |H_HP(e^{jωh})|⁴, so the
   high-pass does not push the peak towards higher frequencies (without it a peak at 0.3 rad/s
   moves up by about 1 % for ωHP = 0.25 rad/s);
4. looks for the highest local maximum inside ``wave_band`` (thesis eq. 3.9: 0.3–1.3 rad/s) and
   refines it below the bin width by parabolic interpolation of the log-power of the peak bin and
   its two neighbours (Gaussian-peak interpolation; Smith & Serra 1987, "PARSHL");
5. refines that value further by fitting, over the wave band, the wave-motion spectrum of the
   2nd-order shaping filter (thesis eq. 3.10, anchors §3)
   S(ω) = g (2λω0ω)² / ((ω0² − ω²)² + (2λω0ω)²) + floor, whose maximum lies exactly at ω0, by the
   Whittle likelihood Σ ln S + P/S (Whittle 1953). A sea state is a random process: the highest
   bin of a finite record wanders by a fair part of the peak width λω0, while the fit uses every
   bin of the peak. Measured on 120 seeded 20 min records, λ = 0.1, ω0 0.3–1.3 rad/s, h 0.1 and
   1 s: highest bin + parabola up to 13 % off (rms 4.4 %), the fit up to 5 % (rms 1.7 %); the
   Cramér–Rao bound for a Lorentzian peak is std ≈ √(λω0/T), 0.8–1.7 % here. The parabolic value
   is kept when the fit fails or leaves the band;
6. with several DOFs, sums the per-DOF PSDs each normalized by its own in-band median, so every
   DOF counts by the prominence of its wave peak, whatever its unit (m² or rad²).

A peak counts as clear when its (combined, normalized) PSD exceeds ``min_peak_ratio`` times the
median PSD over the wave band. Without a clear peak the previous estimate is kept and flagged
``confident=False``.

Heading must be unwrapped (``heading.unwrap_heading``) before it is passed here.
"""
from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
import math
import threading

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import optimize, signal

# Welch segments: each segment is 1/WELCH_SEGMENTS_PER_WINDOW of the estimation window, with 50 %
# overlap, so 2·WELCH_SEGMENTS_PER_WINDOW − 1 = 7 periodograms are averaged.
WELCH_SEGMENTS_PER_WINDOW = 4
WELCH_OVERLAP = 0.5  # fraction of a segment shared with the next one
HIGHPASS_ORDER = 2  # Butterworth order of the LF-removing high-pass (thesis §4.2.1)
MIN_BAND_BINS = 3  # Welch bins needed inside the wave band to find and refine a peak
FIT_DAMPING_RANGE = (0.005, 1.0)  # λ range [-] allowed in the spectrum fit (thesis eq. 3.10)

_FloatArray = NDArray[np.float64]

# The last few estimates by their exact inputs: with the motion gate on, the twin's retraining
# estimates ω0 on the very same window right after the holding network's (half of all calls).
_RECENT_SIZE = 4
_RECENT: OrderedDict[tuple[object, ...], FrequencyEstimate] = OrderedDict()
_RECENT_LOCK = threading.Lock()


@dataclass(frozen=True)
class FrequencyEstimate:
    """Result of one wave peak frequency estimate.

    Attributes:
        wave_peak_freq: estimated dominating wave frequency ω0 [rad/s] (or the previous value
            when ``confident`` is False and a previous value was given).
        confident: True when a clear peak stood out in the wave band.
        peak_ratio: combined normalized PSD at the peak divided by its median over the wave
            band [-] (1 = no peak at all).
        per_dof: each DOF's own peak frequency [rad/s] (NaN for a DOF without in-band power).
        peak_damping: relative damping λ of the wave-motion spectrum fitted to the combined peak
            (step 5; its half-power width is ≈ 2λω0) [-]; NaN when the fit did not run or
            failed. The sea's bandwidth: ≈ 0.01 for the thesis's narrow shaping-filter seas,
            ≈ 0.1 for a JONSWAP sea (docs/BENCHMARKS.md, eleventh session).

    """

    wave_peak_freq: float
    confident: bool
    peak_ratio: float
    per_dof: tuple[float, ...]
    peak_damping: float = math.nan


# What computes an estimate that is not cached: `spectrum_estimate`'s arguments in, its result
# out (`spectrum_fit_by`).
SpectrumFit = Callable[[_FloatArray, float, float, tuple[float, float], float,
                        float | FrequencyEstimate | None], FrequencyEstimate]
_FIT = threading.local()  # .fit: this thread's SpectrumFit (none set: `spectrum_estimate`)


def welch_segment_length(n_samples: int) -> int:
    """Welch segment length [samples] used for an estimation window of ``n_samples``."""
    return max(1, n_samples // WELCH_SEGMENTS_PER_WINDOW)


def welch_resolution(n_samples: int, sample_time: float) -> float:
    """Frequency bin width [rad/s] of the Welch PSD for a window of ``n_samples``.

    Δω = 2π / (segment_length · h) with h the sample time.
    """
    return 2.0 * math.pi / (welch_segment_length(n_samples) * sample_time)


def highpass_sos(highpass_cutoff: float, sample_time: float) -> _FloatArray:
    """2nd-order Butterworth high-pass at ``highpass_cutoff`` [rad/s] as SOS (thesis §4.2.1)."""
    nyquist = math.pi / sample_time  # rad/s
    if not 0.0 < highpass_cutoff < nyquist:
        raise ValueError(
            f'highpass_cutoff must lie between 0 and the Nyquist frequency π/sample_time = '
            f'{nyquist:.4g} rad/s, got {highpass_cutoff!r} rad/s: lower highpass_cutoff or the '
            'sample time')
    sos: _FloatArray = signal.butter(
        HIGHPASS_ORDER, highpass_cutoff / nyquist, btype='highpass', output='sos')
    return sos


def estimate_wave_peak_freq(
    y: ArrayLike,
    sample_time: float,
    *,
    highpass_cutoff: float,
    wave_band: tuple[float, float],
    min_peak_ratio: float,
    previous: float | FrequencyEstimate | None = None,
) -> FrequencyEstimate:
    """Estimate the dominating wave frequency ω0 from past measured positions (thesis §4.2.1).

    Args:
        y: measured positions, shape (n,) or (n, k), one column per DOF, heading unwrapped.
        sample_time: sample time h [s].
        highpass_cutoff: cutoff ωHP [rad/s] of the LF-removing high-pass.
        wave_band: (low, high) [rad/s] range searched for the peak (thesis eq. 3.9).
        min_peak_ratio: peak PSD over median in-band PSD needed for a clear peak [-].
        previous: the last estimate [rad/s] (or FrequencyEstimate), returned when no clear peak.

    Returns:
        The estimate; ``confident`` is False when no clear peak stood out.

    Raises:
        ValueError: on NaN/inf input, bad parameters or a window too short to resolve the band.

    """
    data = _as_columns(y)
    _check_parameters(data.shape[0], sample_time, highpass_cutoff, wave_band, min_peak_ratio)
    # repr is exact for floats (and tells -0.0 from 0.0), so equal keys mean equal inputs
    key = (data.shape, data.tobytes(), repr(sample_time), repr(highpass_cutoff),
           repr(wave_band), repr(min_peak_ratio), repr(previous))
    with _RECENT_LOCK:
        cached = _RECENT.get(key)
    if cached is not None:
        return cached
    fit: SpectrumFit = getattr(_FIT, 'fit', None) or spectrum_estimate
    estimate = fit(data, sample_time, highpass_cutoff, wave_band, min_peak_ratio, previous)
    with _RECENT_LOCK:
        _RECENT[key] = estimate
        while len(_RECENT) > _RECENT_SIZE:
            _RECENT.popitem(last=False)
    return estimate


@contextmanager
def spectrum_fit_by(fit: SpectrumFit | None) -> Iterator[None]:
    """Within the block, this thread's uncached estimates are computed by ``fit``.

    ``fit`` takes `spectrum_estimate`'s arguments and returns its result, e.g.
    `core.fit_process.FitProcess`, which runs it in a child process; None: `spectrum_estimate`
    itself, on this thread. The cache of recent estimates stays in this process. Other threads
    are not affected (a thread-local setting, as numpy's ``errstate``).
    """
    before = getattr(_FIT, 'fit', None)
    _FIT.fit = fit
    try:
        yield
    finally:
        _FIT.fit = before


def spectrum_estimate(data: _FloatArray, sample_time: float, highpass_cutoff: float,
                      wave_band: tuple[float, float], min_peak_ratio: float,
                      previous: float | FrequencyEstimate | None) -> FrequencyEstimate:
    """``estimate_wave_peak_freq`` of checked (n, k) data (no cache; a pure function)."""
    omega, psd = _compensated_psd(data, sample_time, highpass_cutoff)
    in_band = (omega >= wave_band[0]) & (omega <= wave_band[1])
    per_dof: list[float] = []
    normalized: list[_FloatArray] = []
    for column in psd.T:
        median = float(np.median(column[in_band]))
        if not median > 0.0:
            per_dof.append(math.nan)
            continue
        per_dof.append(_fit_peak(omega, column, in_band,
                                 _refined_peak(omega, column, in_band))[0])
        normalized.append(column / median)
    if not normalized:
        return _fallback(previous, math.nan, tuple(per_dof), wave_band)
    combined = np.sum(normalized, axis=0)
    peak = _refined_peak(omega, combined, in_band)
    _, peak_value, is_local_max = peak
    peak_freq, peak_damping = _fit_peak(omega, combined, in_band, peak)
    peak_ratio = peak_value / float(np.median(combined[in_band]))
    if is_local_max and peak_ratio >= min_peak_ratio:
        return FrequencyEstimate(peak_freq, True, peak_ratio, tuple(per_dof), peak_damping)
    return _fallback(previous, peak_ratio, tuple(per_dof), wave_band, peak_freq)


def _as_columns(y: ArrayLike) -> _FloatArray:
    """Return y as a float (n, k) array (a copy is never modified in place), checked for NaN."""
    data = np.asarray(y, dtype=np.float64)
    if data.ndim == 1:
        data = data[:, np.newaxis]
    if data.ndim != 2 or data.shape[1] < 1:
        raise ValueError(f'y must have shape (n,) or (n, k), got {np.shape(y)}: pass one column '
                         'per DOF')
    if not np.all(np.isfinite(data)):
        raise ValueError('y contains NaN or inf: drop or interpolate invalid samples (sensor '
                         'dropouts) before estimating the wave peak frequency')
    return data


def _check_parameters(n_samples: int, sample_time: float, highpass_cutoff: float,
                      wave_band: tuple[float, float], min_peak_ratio: float) -> None:
    """Raise ValueError for parameters the estimate cannot work with."""
    if not sample_time > 0.0:
        raise ValueError(f'sample_time must be positive, got {sample_time!r} s')
    low, high = wave_band
    nyquist = math.pi / sample_time  # rad/s
    if not 0.0 < low < high < nyquist:
        raise ValueError(
            f'wave_band must satisfy 0 < low < high < π/sample_time = {nyquist:.4g} rad/s, got '
            f'{wave_band!r}: order the band edges or sample faster')
    if not min_peak_ratio > 1.0:
        raise ValueError(f'min_peak_ratio must exceed 1 (peak above the band median), got '
                         f'{min_peak_ratio!r}')
    resolution = welch_resolution(n_samples, sample_time)
    if resolution * MIN_BAND_BINS > high - low:
        needed = MIN_BAND_BINS * WELCH_SEGMENTS_PER_WINDOW * 2.0 * math.pi / (high - low)
        raise ValueError(
            f'{n_samples} samples ({n_samples * sample_time:.4g} s) give a Welch bin of '
            f'{resolution:.3g} rad/s, too coarse for the wave band {wave_band!r}: pass at least '
            f'{needed:.4g} s of data')
    highpass_sos(highpass_cutoff, sample_time)


def _compensated_psd(data: _FloatArray, sample_time: float,
                     highpass_cutoff: float) -> tuple[_FloatArray, _FloatArray]:
    """High-pass, Welch PSD (Hamming), compensated for the high-pass power response.

    Returns (omega [rad/s], psd of shape (n_freq, k)).
    """
    sos = highpass_sos(highpass_cutoff, sample_time)
    filtered = signal.sosfiltfilt(sos, data, axis=0)
    segment = welch_segment_length(data.shape[0])
    freq_hz, psd = signal.welch(
        filtered, fs=1.0 / sample_time, window='hamming', nperseg=segment,
        noverlap=int(segment * WELCH_OVERLAP), detrend='linear', axis=0)
    omega = 2.0 * math.pi * np.asarray(freq_hz, dtype=np.float64)
    _, response = signal.sosfreqz(sos, worN=omega * sample_time)
    power = np.abs(response) ** 4  # forward-backward: |H|² applied twice
    with np.errstate(divide='ignore', invalid='ignore'):
        compensated = np.where(power[:, np.newaxis] > 0.0, psd / power[:, np.newaxis], 0.0)
    return omega, np.asarray(compensated, dtype=np.float64)


def _refined_peak(omega: _FloatArray, psd: _FloatArray,
                  in_band: NDArray[np.bool_]) -> tuple[float, float, bool]:
    """Highest in-band local maximum, refined by parabolic interpolation of the log-power.

    Returns (frequency [rad/s], PSD at the peak bin, whether it is a true local maximum). When the
    band holds no local maximum (monotonic PSD) the in-band maximum is returned unrefined.
    """
    band_index = np.flatnonzero(in_band)
    inner = band_index[(band_index > 0) & (band_index < psd.size - 1)]
    is_max = (psd[inner] > psd[inner - 1]) & (psd[inner] >= psd[inner + 1])
    candidates = inner[is_max]
    if candidates.size == 0:
        best = int(band_index[np.argmax(psd[band_index])])
        return float(omega[best]), float(psd[best]), False
    peak = int(candidates[np.argmax(psd[candidates])])
    left, centre, right = np.log(np.maximum(psd[peak - 1:peak + 2], np.finfo(float).tiny))
    curvature = left - 2.0 * centre + right
    offset = 0.5 * (left - right) / curvature if curvature < 0.0 else 0.0
    step = float(omega[1] - omega[0])
    return float(omega[peak] + offset * step), float(psd[peak]), True


def _fit_peak(omega: _FloatArray, psd: _FloatArray, in_band: NDArray[np.bool_],
              start: tuple[float, float, bool]) -> tuple[float, float]:
    """Whittle fit of the 2nd-order wave-motion spectrum (thesis eq. 3.10) around ``start``.

    Returns the fitted (ω0 [rad/s], damping λ [-]), or (start frequency, NaN) when there is no
    local maximum, the fit fails or its ω0 leaves the band.
    """
    start_freq, start_value, is_local_max = start
    band_omega = omega[in_band]
    band_psd = psd[in_band]
    if not is_local_max or start_value <= 0.0:
        return start_freq, math.nan
    floor = max(float(np.median(band_psd)), start_value * 1e-6)
    low, high = float(band_omega[0]), float(band_omega[-1])
    band_omega_sq = band_omega ** 2  # hoisted out of the ~400 evaluations of one fit
    min_damping, max_damping = FIT_DAMPING_RANGE
    add_reduce = np.add.reduce  # what np.sum of a 1-D array runs, without its dispatch

    def negative_log_likelihood(theta: _FloatArray) -> float:
        wave_freq, log_damping, log_gain, log_floor = theta.tolist()
        damping = math.exp(log_damping)
        if not (low <= wave_freq <= high and min_damping <= damping <= max_damping):
            return math.inf
        model = _wave_spectrum(band_omega, wave_freq, damping, band_omega_sq)
        model *= math.exp(log_gain)
        model += math.exp(log_floor)
        terms = np.log(model)
        terms += band_psd / model
        return float(add_reduce(terms))

    theta0 = np.array([start_freq, math.log(0.1), math.log(start_value), math.log(floor)])
    # a vertex outside the band scores inf; scipy's convergence test then computes inf − inf
    # (a RuntimeWarning on every such fit, harmless: the comparison is False and it iterates on)
    with np.errstate(invalid='ignore'):
        result = optimize.minimize(negative_log_likelihood, theta0, method='Nelder-Mead',
                                   options={'xatol': 1e-5, 'fatol': 1e-9, 'maxiter': 2000})
    fitted = float(result.x[0])
    if not (math.isfinite(result.fun) and low < fitted < high):
        return start_freq, math.nan
    return fitted, math.exp(float(result.x[1]))


def _wave_spectrum(omega: _FloatArray, wave_freq: float, damping: float,
                   omega_sq: _FloatArray | None = None) -> _FloatArray:
    """|H(jω)|² / σ² of the shaping filter H(s) = 2λω0σ s / (s² + 2λω0 s + ω0²) (eq. 3.10).

    ``omega_sq``: ``omega ** 2`` when the caller has it already (the same numbers).
    """
    damped = (2.0 * damping * wave_freq * omega) ** 2
    if omega_sq is None:
        omega_sq = omega ** 2
    return np.asarray(damped / ((wave_freq ** 2 - omega_sq) ** 2 + damped), dtype=np.float64)


def _fallback(previous: float | FrequencyEstimate | None, peak_ratio: float,
              per_dof: tuple[float, ...], wave_band: tuple[float, float],
              raw_freq: float | None = None) -> FrequencyEstimate:
    """Estimate without a clear peak: the previous value, else the raw peak, flagged unsure.

    The previous estimate's peak damping is kept with its frequency (NaN without one).
    """
    damping = math.nan
    if isinstance(previous, FrequencyEstimate):
        damping = previous.peak_damping
        previous = previous.wave_peak_freq
    if previous is not None and math.isfinite(previous):
        freq = float(previous)
    elif raw_freq is not None:
        freq, damping = raw_freq, math.nan
    else:
        freq, damping = math.sqrt(wave_band[0] * wave_band[1]), math.nan  # band centre [rad/s]
    return FrequencyEstimate(freq, False, peak_ratio, per_dof, damping)
