"""Align pose and thrust streams by stamp and resample them to the predictor's sample time.

The predictor works on a uniform grid t_k = k·T (T = `sample_time`); sensors and actuators do not.
`InputAligner` turns two asynchronous, possibly faulty streams into that grid:

- **pose** (GNSS position + gyro heading): the grid sample at t_k is the mean of the valid poses
  stamped in (t_k − T, t_k] (heading averaged on the circle), when `average_poses` is on and at
  least two arrived; otherwise (a sensor not faster than the grid, or `average_poses` off) the
  pose linearly interpolated at t_k between consecutive valid poses (heading along the shortest
  arc). A grid point is emitted once a pose at or after it has arrived, so the output is causal
  with at most one input period of delay. The mean is the anti-aliasing step of the decimation:
  picking one 10 Hz GNSS sample per second folds the noise and the wave motion above the grid's
  Nyquist frequency into the 1 Hz series; the interval mean (a boxcar, delay (T − input
  period)/2) averages the noise down. Measured on the supply vessel (tuning seed 1): adaptive
  predictor RMSE 0.080 → 0.066 m north, every baseline improved too (docs/BENCHMARKS.md).
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
    average_poses: bool = True

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
        if not isinstance(self.average_poses, bool):
            raise ValueError(f'average_poses must be true or false, got {self.average_poses!r}')


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
    if arr.shape != (3,):
        return None
    north, east, yaw = arr.tolist()
    if not (math.isfinite(north) and math.isfinite(east) and math.isfinite(yaw)):
        return None
    if max(abs(north), abs(east)) > max_abs:
        return None
    return arr.copy()


def mean_pose(poses: FloatArray) -> FloatArray:
    """Mean of poses (m, 3) [m, m, rad]: positions averaged, heading on the circle (wrapped).

    The heading mean is taken about the first heading (wrapped differences), so a block that
    crosses ±π averages to the right side; the poses of one grid interval are far closer than π.
    """
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 2 or poses.shape[1] != 3 or poses.shape[0] == 0:
        raise ValueError(f'mean_pose needs poses of shape (m ≥ 1, 3), got {poses.shape}')
    ref = float(poses[0, 2])
    offset = np.remainder(poses[:, 2] - ref + math.pi, 2.0 * math.pi) - math.pi
    return _mean_with_offsets(poses, offset)


def _mean_with_offsets(poses: FloatArray, offsets: FloatArray) -> FloatArray:
    """`mean_pose` given each heading's wrapped offset from the first heading (poses.mean)."""
    count = poses.shape[0]
    out = np.add.reduce(poses, axis=0) / count  # poses.mean(axis=0): sum / count
    out[2] = _wrap(float(poses[0, 2]) + float(np.add.reduce(offsets)) / count)
    return np.asarray(out, dtype=np.float64)


def block_mean_poses(poses: FloatArray, stride: int) -> FloatArray:
    """`mean_pose` over consecutive blocks of ``stride`` rows of a uniform series (m, 3).

    Row k of the result averages rows k·stride … k·stride + stride − 1: on a sensor grid whose
    every ``stride``-th sample is a grid point, exactly what `InputAligner` emits with
    ``average_poses`` on. A trailing partial block is dropped.
    """
    poses = np.asarray(poses, dtype=np.float64)
    if stride < 1:
        raise ValueError(f'stride must be ≥ 1 sample, got {stride}')
    blocks = poses[:poses.shape[0] // stride * stride].reshape(-1, stride, poses.shape[1])
    out = blocks.mean(axis=1)
    ref = blocks[:, :1, 2]
    offset = np.remainder(blocks[:, :, 2] - ref + math.pi, 2.0 * math.pi) - math.pi
    out[:, 2] = np.remainder(ref[:, 0] + offset.mean(axis=1) + math.pi, 2.0 * math.pi) - math.pi
    return np.asarray(out, dtype=np.float64)


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
        # valid poses stamped in (next_grid − T, next_grid]: the first _block_size rows (an
        # array that grows as needed, so the grid sample's mean needs no copy of a list)
        self._block = np.zeros((16, 3))
        self._block_size = 0
        # per block row: its heading about the first row's, wrapped (mean_pose's offsets)
        self._block_offsets = np.zeros(16)

    def reset(self) -> None:
        """Forget the pose stream (counters are kept); the next pose starts a new segment."""
        self._last_t = None
        self._last_pose = None
        self._next_grid = None
        self._segment_start = True
        self._block_size = 0

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
            elif np.hypot(arr[0] - self._last_pose[0], arr[1] - self._last_pose[1]) > \
                    s.max_speed * dt + 1.0:
                self.counters.outliers += 1
                return []
        self.counters.poses += 1
        if self._last_t is None or self._last_pose is None:
            self._last_t, self._last_pose = t, arr
            self._next_grid = math.ceil(t / s.sample_time - 1e-9) * s.sample_time
            prev_t, prev_pose = t, arr
        else:
            prev_t, prev_pose = self._last_t, self._last_pose
            self._last_t, self._last_pose = t, arr
        assert self._next_grid is not None
        if t <= self._next_grid + 1e-9:
            self._block_append(arr)
        out = self._emit_until(prev_t, prev_pose, t, arr)
        if t > self._next_grid - s.sample_time + 1e-9 and not self._block_size:
            self._block_append(arr)  # the first pose of the next grid interval
        return out

    def _block_append(self, pose: FloatArray) -> None:
        size = self._block_size
        if size == self._block.shape[0]:
            self._block = np.concatenate((self._block, np.zeros_like(self._block)))
            self._block_offsets = np.concatenate((self._block_offsets,
                                                  np.zeros_like(self._block_offsets)))
        self._block[size] = pose
        yaw = float(pose[2])
        ref = yaw if size == 0 else float(self._block[0, 2])
        # mean_pose's np.remainder(yaw − ref + π, 2π) − π, one pose at a time
        self._block_offsets[size] = (yaw - ref + math.pi) % (2.0 * math.pi) - math.pi
        self._block_size = size + 1

    def _block_mean(self) -> FloatArray:
        """`mean_pose` of the block, value for value, with the offsets made as poses came."""
        count = self._block_size
        return _mean_with_offsets(self._block[:count], self._block_offsets[:count])

    def _emit_until(self, t0: float, p0: FloatArray, t1: float,
                    p1: FloatArray) -> list[AlignedSample]:
        out: list[AlignedSample] = []
        assert self._next_grid is not None
        step = self.settings.sample_time
        dyaw = _wrap(float(p1[2] - p0[2]))
        while self._next_grid <= t1 + 1e-9:
            tg = self._next_grid
            w = 0.0 if t1 <= t0 else min(max((tg - t0) / (t1 - t0), 0.0), 1.0)
            if self.settings.average_poses and self._block_size > 1:
                pose = self._block_mean()
            elif w >= 1.0:  # exactly on the new pose: no rounding from interpolation
                pose = p1.copy()
            else:
                pose = p0 + w * (p1 - p0)
                pose[2] = _wrap(float(p0[2]) + w * dyaw)
            self._block_size = 0
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
