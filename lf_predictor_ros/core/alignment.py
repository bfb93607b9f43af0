"""Align pose and thrust streams by stamp and resample them to the predictor's sample time.

The predictor works on a uniform grid t_k = k·T (T = `sample_time`); sensors and actuators do not.
`InputAligner` turns two asynchronous, possibly faulty streams into that grid:

- **pose** (GNSS position + gyro heading): linearly interpolated onto the grid between consecutive
  valid poses (heading interpolated along the shortest arc). A grid point is emitted once a pose
  at or after it has arrived, so the output is causal with at most one input period of delay.
- **thrust**: zero-order hold of the newest force not newer than the grid point; older than
  `thrust_timeout` (or never received) → zeros, and the sample is flagged `force_stale`.

Documented safe behaviour for bad input (nothing raises on data; every case is counted):

| input | behaviour | counter |
|---|---|---|
| NaN/Inf, wrong shape, horizontal position beyond `max_abs_position` | dropped | `invalid` |
| stamp equal to or older than the last pose (by < `backward_jump`) | dropped | `out_of_order` |
| stamp older by ≥ `backward_jump` (simulator reset, bag loop) | stream restarts | `resets` |
| jump faster than `max_speed` (GNSS outlier) | dropped | `outliers` |
| gap between valid poses > `max_gap` | no interpolation across; stream restarts | `gaps` |

A restart emits a sample with `segment_start=True`: consumers must not let regressors or training
windows span it (the predictor clears its buffers, keeps its trained model).
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class AlignerSettings:
    """Rules of `InputAligner`; times in seconds, distances in metres."""

    sample_time: float = 0.5
    max_gap: float = 5.0
    thrust_timeout: float = 2.0
    backward_jump: float = 5.0
    max_speed: float = 20.0
    max_abs_position: float = 1.0e7

    def __post_init__(self) -> None:
        if not (self.sample_time > 0 and math.isfinite(self.sample_time)):
            raise ValueError(f'sample_time must be > 0 s, got {self.sample_time}')
        if self.max_gap < self.sample_time:
            raise ValueError(
                f'max_gap ({self.max_gap} s) must be >= sample_time ({self.sample_time} s): '
                'a gap shorter than one sample cannot be detected')
        for name in ('thrust_timeout', 'backward_jump', 'max_speed', 'max_abs_position'):
            if not getattr(self, name) > 0:
                raise ValueError(f'{name} must be > 0, got {getattr(self, name)}')


@dataclass(frozen=True)
class AlignedSample:
    """One grid sample: pose (3,) [m, m, rad wrapped], force (3,) [N, N, N·m]."""

    t: float
    pose: FloatArray
    force: FloatArray
    force_stale: bool
    segment_start: bool


@dataclass
class AlignerCounters:
    """How many inputs of each kind were dropped or caused a restart."""

    poses: int = 0
    forces: int = 0
    invalid: int = 0
    out_of_order: int = 0
    outliers: int = 0
    gaps: int = 0
    resets: int = 0
    stale_force_samples: int = 0
    extra: dict[str, int] = field(default_factory=dict)

    def as_dict(self) -> dict[str, int]:
        """Counters by name, for diagnostics."""
        out = {k: v for k, v in vars(self).items() if isinstance(v, int)}
        out.update(self.extra)
        return out


def _wrap(angle: float) -> float:
    """Wrap to (−π, π]."""
    wrapped = math.remainder(angle, 2.0 * math.pi)
    return math.pi if wrapped == -math.pi else wrapped


def _valid_vector(value: object, max_abs: float) -> FloatArray | None:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        return None
    if max(abs(arr[0]), abs(arr[1])) > max_abs:
        return None
    return arr.copy()


class InputAligner:
    """Stateful resampler of (pose, thrust) streams onto a uniform grid; see module docstring."""

    def __init__(self, settings: AlignerSettings) -> None:
        self.settings = settings
        self.counters = AlignerCounters()
        self._forces: deque[tuple[float, FloatArray]] = deque(maxlen=256)
        self._last_t: float | None = None
        self._last_pose: FloatArray | None = None
        self._next_grid: float | None = None
        self._segment_start = True

    def reset(self) -> None:
        """Forget the pose stream (counters are kept); the next pose starts a new segment."""
        self._last_t = None
        self._last_pose = None
        self._next_grid = None
        self._segment_start = True

    def add_force(self, t: float, force: object) -> bool:
        """Store an applied force for zero-order hold; returns False if it was dropped."""
        arr = _valid_vector(force, math.inf)
        if arr is None or not math.isfinite(t):
            self.counters.invalid += 1
            return False
        last_t = self._forces[-1][0] if self._forces else -math.inf
        if t <= last_t - self.settings.backward_jump:
            self._forces.clear()  # time went backwards: the old forces mean nothing
        elif t <= last_t:
            self.counters.out_of_order += 1
            return False
        self.counters.forces += 1
        self._forces.append((t, arr))
        return True

    def _force_at(self, t: float) -> tuple[FloatArray, bool]:
        """Zero-order hold: newest force stamped at or before t; (zeros, True) if stale."""
        for stamp, force in reversed(self._forces):
            if stamp <= t + 1e-9:
                if t - stamp <= self.settings.thrust_timeout:
                    return force.copy(), False
                break
        return np.zeros(3), True

    def add_pose(self, t: float, pose: object) -> list[AlignedSample]:
        """Add a measured pose; return the grid samples it completes (possibly none)."""
        s = self.settings
        arr = _valid_vector(pose, s.max_abs_position)
        if arr is None or not math.isfinite(t):
            self.counters.invalid += 1
            return []
        arr[2] = _wrap(float(arr[2]))
        if self._last_t is not None and self._last_pose is not None:
            dt = t - self._last_t
            if dt <= -s.backward_jump:
                self.counters.resets += 1
                self.reset()
            elif dt <= 0.0:
                self.counters.out_of_order += 1
                return []
            elif dt > s.max_gap:
                self.counters.gaps += 1
                self.reset()
            elif np.hypot(*(arr[:2] - self._last_pose[:2])) > s.max_speed * dt + 1.0:
                self.counters.outliers += 1
                return []
        self.counters.poses += 1
        if self._last_t is None or self._last_pose is None:
            self._last_t, self._last_pose = t, arr
            self._next_grid = math.ceil(t / s.sample_time - 1e-9) * s.sample_time
            return self._emit_until(t, arr, t, arr)
        prev_t, prev_pose = self._last_t, self._last_pose
        self._last_t, self._last_pose = t, arr
        return self._emit_until(prev_t, prev_pose, t, arr)

    def _emit_until(self, t0: float, p0: FloatArray, t1: float,
                    p1: FloatArray) -> list[AlignedSample]:
        out: list[AlignedSample] = []
        assert self._next_grid is not None
        step = self.settings.sample_time
        dyaw = _wrap(float(p1[2] - p0[2]))
        while self._next_grid <= t1 + 1e-9:
            tg = self._next_grid
            w = 0.0 if t1 <= t0 else min(max((tg - t0) / (t1 - t0), 0.0), 1.0)
            if w >= 1.0:  # exactly on the new pose: no rounding from interpolation
                pose = p1.copy()
            else:
                pose = p0 + w * (p1 - p0)
                pose[2] = _wrap(float(p0[2]) + w * dyaw)
            out.append(self._sample(tg, pose))
            self._next_grid = round((tg + step) / step) * step
        return out

    def _sample(self, t: float, pose: FloatArray) -> AlignedSample:
        force, stale = self._force_at(t)
        if stale:
            self.counters.stale_force_samples += 1
        sample = AlignedSample(t=t, pose=pose, force=force, force_stale=stale,
                               segment_start=self._segment_start)
        self._segment_start = False
        return sample
