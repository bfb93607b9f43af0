"""Exploratory: the motion gate acts on the heading while the yaw moment says the vessel turns.

    OMP_NUM_THREADS=1 python docs/scripts/yaw_moment_gate_probe.py --scenarios rao_supply \
        --seeds 675 694 --closed-loop --loops-only --variant "ym=motion_gate_yaw:true"
    OMP_NUM_THREADS=1 python docs/scripts/yaw_moment_gate_probe.py --blocks rao_supply 694 \
        motion_gate_yaw:true 1110 1200 --block 4 --bias --rate --force

`method_probe.py` (or, with ``--blocks`` first, `loop_block_probe.py`) with, in this process
only (nothing in the package changes), the motion gate's heading gain taken from the applied
yaw moment instead of the twin's step size. Why (docs/BENCHMARKS.md, forty-fourth session): in
rao_supply's turn excursions the holding network's heading lags by about 0.1 rad, and the yaw
gate (`motion_gate_yaw`) removes that only where it opens early in the turn (seed 675, not
694); the yaw moment jumps from about 1 MN·m to its 16–19 MN·m limit at the turn's first
second, and the yaw gate's cost is the swell's yaw it lets through outside turns.

The patch (only with ``motion_gate_yaw: true``, whose heading gain it replaces; north and east
unchanged): |yaw moment| low-passed over ``YM_TIME`` s against its level (its running mean
over the first ``YM_LEVEL_TIME`` s, then low-passed over that time; no gain before); the heading
gain is 1 while the ratio exceeds ``YM_RATIO`` and for ``YM_HOLD`` s after, then falls linearly
to 0 over ``YM_FADE`` s. It multiplies the gate's (low-passed, notched) heading offset twin −
holding as the shipped gain does. Environment variables set the constants; ``GUARD_FLOOR_YAW``
(rad, unset: the shipped 0.02) also sets the sanity guard's heading floor, as
`guard_heading_floor_probe.py` does. Every variant of the run gets the patch. Development seeds
only, as `method_probe.py`.
"""
from __future__ import annotations

import os
from pathlib import Path
import sys
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import guard_heading_floor_probe  # noqa: E402 - the sibling script
import loop_block_probe  # noqa: E402 - the sibling script

from lf_predictor_ros.core.motion_gate import shifted  # noqa: E402
from lf_predictor_ros.core.predictor import AdaptivePredictor  # noqa: E402

YM_TIME = float(os.environ.get('YM_TIME', '2'))  # [s]
YM_LEVEL_TIME = float(os.environ.get('YM_LEVEL_TIME', '600'))  # [s]
YM_RATIO = float(os.environ.get('YM_RATIO', '5'))  # [-]
YM_HOLD = float(os.environ.get('YM_HOLD', '30'))  # [s]
YM_FADE = float(os.environ.get('YM_FADE', '10'))  # [s]

_GATED = AdaptivePredictor._gated


def _moment_gain(self: Any, moment: float) -> float:
    """The heading gain of this sample from the yaw moment (module docstring)."""
    h = self.params.sample_time
    size = abs(moment)
    if not hasattr(self, 'probe_moment'):
        self.probe_moment = size
        self.probe_level = size
        self.probe_samples = 0
        self.probe_since = np.inf  # s since the ratio last exceeded YM_RATIO
    self.probe_samples += 1
    self.probe_moment += min(1.0, h / YM_TIME) * (size - self.probe_moment)
    # the level: the running mean of |moment| until YM_LEVEL_TIME has passed, then its low-pass
    self.probe_level += max(h / YM_LEVEL_TIME, 1.0 / self.probe_samples) * (
        size - self.probe_level)
    warm = self.probe_samples * h >= YM_LEVEL_TIME
    if warm and self.probe_moment > YM_RATIO * max(self.probe_level, 1.0):
        self.probe_since = 0.0
    else:
        self.probe_since += h
    if self.probe_since <= YM_HOLD:
        return 1.0
    return max(0.0, 1.0 - float(self.probe_since - YM_HOLD) / YM_FADE)


def gated_by_yaw_moment(self: Any, t: float, out: np.ndarray, pose: np.ndarray,
                        force: np.ndarray) -> np.ndarray:
    """`_gated`, its heading gain replaced by the yaw moment's (module docstring)."""
    result: np.ndarray = _GATED(self, t, out, pose, force)
    if self.ndof != 3 or not self.params.motion_gate_yaw:
        return result
    gain = _moment_gain(self, float(force[2]))
    offset = self._scaled_offset
    if offset is None or not self._gate_valid[2]:
        return result  # the gate is restarting (the twin on its fallback): no offset to scale
    change = gain - float(self._gain[2])
    self._gain = np.array([self._gain[0], self._gain[1], gain])
    return shifted(result, np.array([0.0, 0.0, change * float(offset[2])]), 3)


if __name__ == '__main__':
    setattr(AdaptivePredictor, '_gated', gated_by_yaw_moment)  # noqa: B010 - the patch
    if 'GUARD_FLOOR_YAW' in os.environ:
        guard_heading_floor_probe.set_heading_floor(float(os.environ['GUARD_FLOOR_YAW']))
    print(f'# yaw moment gate: YM_TIME {YM_TIME} s, YM_LEVEL_TIME {YM_LEVEL_TIME} s, '
          f'YM_RATIO {YM_RATIO}, YM_HOLD {YM_HOLD} s, YM_FADE {YM_FADE} s', flush=True)
    sys.exit(loop_block_probe.probe_main(sys.argv[1:]))
