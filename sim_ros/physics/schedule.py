"""Schedules of the dominating wave frequency ω0(t): constant, steps, ramps, tables.

Every schedule is a piecewise-linear table (t_i, ω_i) with non-decreasing times; a step is two
points at the same time (the later value applies from that time on), values are held constant
before the first and after the last point. The thesis varies ω0 over 0.3–1.3 rad/s (eq. 3.9).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import math

import numpy as np

from sim_ros.physics.kinematics import FloatArray

MIN_PEAK_FREQ = 0.05  # rad/s, below any ocean wave (swell ≈ 0.3 rad/s)
MAX_PEAK_FREQ = 5.0  # rad/s, above any sea state a DP vessel responds to


@dataclass(frozen=True)
class PeakFreqSchedule:
    """Piecewise-linear ω0(t) [rad/s]: `times` [s] non-decreasing, `values` [rad/s]."""

    times: tuple[float, ...]
    values: tuple[float, ...]

    def __post_init__(self) -> None:
        """Check the table: same length, ordered times, physical frequencies."""
        if len(self.times) == 0 or len(self.times) != len(self.values):
            raise ValueError('a wave peak frequency schedule needs one value per time and at '
                             'least one point; give e.g. [[0, 0.8]]')
        if any(b < a for a, b in zip(self.times, self.times[1:], strict=False)):
            raise ValueError(f'schedule times must be non-decreasing, got {self.times}; sort '
                             'the table by time')
        for value in self.values:
            if not (MIN_PEAK_FREQ <= value <= MAX_PEAK_FREQ) or not math.isfinite(value):
                raise ValueError(f'wave peak frequency {value} rad/s is outside '
                                 f'[{MIN_PEAK_FREQ}, {MAX_PEAK_FREQ}] rad/s; use rad/s, not Hz')

    def __call__(self, t: float) -> float:
        """ω0 at time t [s] (right-continuous at steps)."""
        return float(self.sample(np.array([t], dtype=np.float64))[0])

    def sample(self, times: FloatArray) -> FloatArray:
        """ω0 at many times [s], vectorized; right-continuous at steps."""
        grid = np.asarray(self.times, dtype=np.float64)
        vals = np.asarray(self.values, dtype=np.float64)
        count = len(grid)
        index = np.searchsorted(grid, times, side='right')  # number of table times <= t
        inside = (index > 0) & (index < count)
        hi = np.clip(index, 1, max(count - 1, 1)) if count > 1 else np.zeros_like(index)
        lo = np.maximum(hi - 1, 0)
        span = np.where(inside, grid[hi] - grid[lo], 1.0)  # > 0 whenever inside
        frac = np.where(inside, (times - grid[lo]) / span, 0.0)
        out = np.where(inside, vals[lo] + (vals[hi] - vals[lo]) * frac, 0.0)
        out = np.where(index == 0, vals[0], out)
        return np.asarray(np.where(index >= count, vals[-1], out), dtype=np.float64)


def constant(peak_freq: float) -> PeakFreqSchedule:
    """ω0 constant [rad/s]."""
    return PeakFreqSchedule((0.0,), (float(peak_freq),))


def steps(initial: float, changes: Sequence[tuple[float, float]]) -> PeakFreqSchedule:
    """ω0 = `initial` until the first change (t, ω0_new), and so on."""
    times, values = [0.0], [float(initial)]
    for t, value in changes:
        times += [float(t), float(t)]
        values += [values[-1], float(value)]
    return PeakFreqSchedule(tuple(times), tuple(values))


def delayed(schedule: PeakFreqSchedule, delay: float) -> PeakFreqSchedule:
    """``schedule`` with every point after t = 0 ``delay`` [s] later (pure).

    The value at t = 0 holds until the first moved point, so a step or a ramp corner at t comes
    at t + delay and the values are unchanged; a constant schedule is returned as it is. Used to
    draw the phase of a sea change against an estimator's own timing (the benchmark's
    ``--schedule-spread``).
    """
    if not (math.isfinite(delay) and delay >= 0.0):
        raise ValueError(f'a schedule delay must be finite and >= 0 s, got {delay!r}')
    if delay == 0.0 or all(t <= 0.0 for t in schedule.times):
        return schedule
    return PeakFreqSchedule(tuple(t + delay if t > 0.0 else t for t in schedule.times),
                            schedule.values)


def ramp(t_start: float, t_end: float, start: float, end: float) -> PeakFreqSchedule:
    """ω0 = `start` until t_start, linear to `end` at t_end, then constant."""
    if t_end < t_start:
        raise ValueError(f'ramp must end after it starts (t_start={t_start}, t_end={t_end})')
    return PeakFreqSchedule((float(t_start), float(t_end)), (float(start), float(end)))


def table(points: Sequence[Sequence[float]]) -> PeakFreqSchedule:
    """ω0 from [[t, ω0], ...] linearly interpolated."""
    if any(len(p) != 2 for p in points):
        raise ValueError('a peak frequency table is a list of [time_s, omega_rad_s] pairs')
    return PeakFreqSchedule(tuple(float(p[0]) for p in points),
                            tuple(float(p[1]) for p in points))


def thesis_fig_4_1() -> PeakFreqSchedule:
    """The thesis Fig. 4.1 experiment: ω0 1.25 → 0.3 → 1.25 rad/s over 480 min.

    The figure only gives the end points and the span; our reconstruction holds 1.25 rad/s for
    60 min, ramps down over 120 min, holds 0.3 rad/s for 120 min, ramps back up over 120 min and
    holds for the last 60 min.
    """
    minute = 60.0  # s
    return table([[0.0, 1.25], [60 * minute, 1.25], [180 * minute, 0.3],
                  [300 * minute, 0.3], [420 * minute, 1.25], [480 * minute, 1.25]])
