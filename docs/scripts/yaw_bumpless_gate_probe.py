"""Exploratory: a source switch of the holding side does not move the gated heading at once.

    OMP_NUM_THREADS=1 python docs/scripts/yaw_bumpless_gate_probe.py --scenarios rao_supply \
        --seeds 755 756 --closed-loop --loops-only --variant "bl="

`method_probe.py` (or, with ``--blocks`` first, `loop_block_probe.py`) with, in this process
only (nothing in the package changes), the gate's low-passed heading offset shifted by minus the
holding output's heading jump at the sample where the holding side changes source (a guard trip
or its end: network ↔ cascade; or another network in service), so that holding + offset, the
gated heading at gain 1, continues and the low-pass carries the offset to the new twin − holding
over ``motion_gate_smoothing``. Why (docs/BENCHMARKS.md, forty-fifth session, "the heading's
output steps"): at the heading gain 1 such a switch reached the published heading at once (0.12
rad on rao_supply 760); leaving the offset unfiltered removed those steps but cost position in
the loop. Only with the yaw moment's heading gain (``motion_gate_yaw_moment_ratio`` > 0) and
``motion_gate_smoothing`` > 0; north and east unchanged. Every variant of the run gets the
patch. Development seeds only, as `method_probe.py`.
"""
from __future__ import annotations

from pathlib import Path
import sys
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import loop_block_probe  # noqa: E402 - the sibling script

from lf_predictor_ros.core.heading import wrap_angle  # noqa: E402
from lf_predictor_ros.core.predictor import AdaptivePredictor  # noqa: E402

_GATED = AdaptivePredictor._gated


def bumpless_gated(self: Any, t: float, out: np.ndarray, pose: np.ndarray,
                   force: np.ndarray) -> np.ndarray:
    """`_gated`, its heading offset state shifted at a holding-side source switch."""
    source = (bool(self._used_network), self._model if self._used_network else None)
    last = getattr(self, 'probe_last', None)
    if last is not None and self._yaw_trigger is not None and self._gate_alpha < 1.0:
        last_source, last_heading = last
        if source[0] != last_source[0] or source[1] is not last_source[1]:
            jump = wrap_angle(float(out[2]) - last_heading)
            offset = np.array(self._gate_offset, dtype=np.float64)
            offset[2] -= jump
            self._gate_offset = offset
            self.probe_switches = getattr(self, 'probe_switches', 0) + 1
    self.probe_last = (source, float(out[2]))
    result: np.ndarray = _GATED(self, t, out, pose, force)
    return result


if __name__ == '__main__':
    setattr(AdaptivePredictor, '_gated', bumpless_gated)  # noqa: B010 - the patch
    print('# the gate heading offset shifted at holding-side source switches', flush=True)
    sys.exit(loop_block_probe.probe_main(sys.argv[1:]))
