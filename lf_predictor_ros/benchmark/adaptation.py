"""Adaptation metric (issue 6): how fast the estimate recovers after the wave peak frequency moves.

For each change of the ω0 schedule (a step, or a breakpoint of a piecewise-linear schedule such
as the thesis Fig. 4.1 ramps: `change_times`), with the rolling RMSE r(t) of the LF error over a
trailing window Δ (the retraining period; `rolling_rmse`):

- steady RMSE: the median of the adaptive predictor's r(t) over the settled part of the
  FOLLOWING segment, its second half (the segment runs from this change to the next one, or the
  end of the record): the level the predictor settles to in the new sea. The preceding
  segment's level is the wrong yardstick when the sea gets harder: at ω0 = 0.3 rad/s the waves
  overlap the LF band and no causal filter gets back to its error at 1.25 rad/s;
- recovery time: the first time τ ≥ 0 after the change from which the adaptive r(t) stays within
  `TOLERANCE` × steady for a full window Δ (so a lucky dip does not count), searched up to the
  next change (or the end); +inf if it never does. Target: τ ≤ 2Δ;
- frozen ratio: RMS of the frozen network's error / RMS of the adaptive error over [t, t + 2Δ)
  after the change. Target: ≥ 3.

Pure functions on uniformly sampled arrays (one error value per sample, e.g. the north error of a
1-DOF run or the horizontal error of a 3-DOF one).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
import math

import numpy as np
from numpy.typing import NDArray

from sim_ros.physics.schedule import PeakFreqSchedule

FloatArray = NDArray[np.float64]

TOLERANCE = 1.2  # recovered: rolling RMSE ≤ this × steady RMSE (issue 6)
RECOVERY_WINDOWS = 2.0  # target: recovered within this many Δ (issue 6)
FROZEN_RATIO = 3.0  # target: frozen RMSE ≥ this × adaptive over the 2Δ after a change


@dataclass(frozen=True)
class AdaptationEvent:
    """Scores around one ω0 change at `time` [s] (module docstring); RMSE in the error's unit."""

    time: float
    steady_rmse: float
    recovery_time: float  # [s], inf = not recovered before the next change
    adaptive_rmse_after: float  # over [time, time + 2Δ)
    frozen_rmse_after: float
    frozen_ratio: float

    def to_dict(self) -> dict[str, float]:
        """JSON-ready (inf stays a float)."""
        return {k: float(v) for k, v in asdict(self).items()}


def change_times(schedule: PeakFreqSchedule, start: float, end: float) -> tuple[float, ...]:
    """Times in (start, end) where ω0 jumps or its slope changes (steps and ramp corners)."""
    times = np.asarray(schedule.times, dtype=np.float64)
    values = np.asarray(schedule.values, dtype=np.float64)
    out: list[float] = []
    for t in np.unique(times):
        if not start < t < end:
            continue
        before, after = values[times == t][0], values[times == t][-1]
        left = _slope(times, values, float(t), side='left')
        right = _slope(times, values, float(t), side='right')
        if before != after or not math.isclose(left, right, rel_tol=1e-9, abs_tol=1e-15):
            out.append(float(t))
    return tuple(out)


def _slope(times: FloatArray, values: FloatArray, t: float, side: str) -> float:
    """dω0/dt just before (side 'left') or after ('right') t; 0 outside the table."""
    if side == 'left':
        index = int(np.searchsorted(times, t, side='left'))  # first point at t
        if index == 0:
            return 0.0
        t0, t1, v0, v1 = times[index - 1], times[index], values[index - 1], values[index]
    else:
        index = int(np.searchsorted(times, t, side='right'))  # first point after t
        if index >= times.size:
            return 0.0
        t0, t1, v0, v1 = times[index - 1], times[index], values[index - 1], values[index]
    return float((v1 - v0) / (t1 - t0)) if t1 > t0 else 0.0


def _uniform_step(t: FloatArray) -> float:
    steps = np.diff(t)
    if t.ndim != 1 or t.size < 2 or np.any(steps <= 0.0):
        raise ValueError('t must be a strictly increasing (n,) array with n >= 2')
    step = float(np.median(steps))
    if np.max(np.abs(steps - step)) > 1e-6 * step:
        raise ValueError('the adaptation metric needs uniformly sampled errors (resample first)')
    return step


def window_samples(window: float, sample_time: float) -> int:
    """Samples in a window [s] (at least 1)."""
    if not (window > 0.0):
        raise ValueError(f'the rolling window Δ must be > 0 s, got {window}')
    return max(1, int(round(window / sample_time)))


def rolling_rmse(t: FloatArray, error: FloatArray, window: float) -> FloatArray:
    """Trailing RMS of `error` over the last `window` seconds at each sample (NaN until full)."""
    times = np.asarray(t, dtype=np.float64)
    err = np.asarray(error, dtype=np.float64)
    if err.shape != times.shape:
        raise ValueError(f'error must have the shape of t {times.shape}, got {err.shape}')
    width = window_samples(window, _uniform_step(times))
    out = np.full(times.size, math.nan)
    if width <= times.size:
        sums = np.concatenate([[0.0], np.cumsum(err**2)])
        mean_square = (sums[width:] - sums[:-width]) / width
        out[width - 1:] = np.sqrt(np.maximum(mean_square, 0.0))
    return out


def _rms(values: FloatArray) -> float:
    return float(np.sqrt(np.mean(values**2))) if values.size else math.nan


def adaptation_events(t: FloatArray, adaptive_error: FloatArray, frozen_error: FloatArray,
                      changes: tuple[float, ...], window: float,
                      tolerance: float = TOLERANCE) -> list[AdaptationEvent]:
    """Score every change inside the record (module docstring)."""
    times = np.asarray(t, dtype=np.float64)
    adaptive = np.asarray(adaptive_error, dtype=np.float64)
    frozen = np.asarray(frozen_error, dtype=np.float64)
    if frozen.shape != times.shape:
        raise ValueError(f'frozen_error must have the shape of t {times.shape}')
    if not tolerance >= 1.0:
        raise ValueError(f'tolerance must be >= 1 (e.g. 1.2), got {tolerance}')
    rolling = rolling_rmse(times, adaptive, window)
    width = window_samples(window, _uniform_step(times))
    inside = [c for c in changes if times[0] < c <= times[-1]]
    events = []
    for i, change in enumerate(inside):
        following = inside[i + 1] if i + 1 < len(inside) else math.inf
        segment_end = min(following, float(times[-1]) + _uniform_step(times))
        settled = (times >= 0.5 * (change + segment_end)) & (times < segment_end)
        values = rolling[settled]
        values = values[np.isfinite(values)]
        steady = float(np.median(values)) if values.size else math.nan
        after = (times >= change) & (times < change + RECOVERY_WINDOWS * window)
        adaptive_after, frozen_after = _rms(adaptive[after]), _rms(frozen[after])
        ratio = frozen_after / adaptive_after if adaptive_after > 0.0 else math.inf
        events.append(AdaptationEvent(
            time=change, steady_rmse=steady,
            recovery_time=_recovery(times, rolling, change, following, tolerance * steady,
                                    width),
            adaptive_rmse_after=adaptive_after, frozen_rmse_after=frozen_after,
            frozen_ratio=ratio))
    return events


def _recovery(times: FloatArray, rolling: FloatArray, change: float, following: float,
              bound: float, width: int) -> float:
    """First τ ≥ 0 with rolling ≤ bound on `width` consecutive samples from change + τ."""
    if not math.isfinite(bound):
        return math.inf
    segment = np.flatnonzero((times >= change) & (times < following))
    ok = rolling[segment] <= bound  # NaN compares False
    if ok.size < width:
        return math.inf
    runs = np.convolve(ok.astype(np.int64), np.ones(width, dtype=np.int64), mode='valid')
    full = np.flatnonzero(runs == width)
    return float(times[segment[full[0]]] - change) if full.size else math.inf
