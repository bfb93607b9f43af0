"""Exploratory: the motion gate driven by the twin-minus-holding offset, not the twin's velocity.

    OMP_NUM_THREADS=1 python docs/scripts/offset_gate_precheck.py --scenarios rao_supply \
        --seeds 361 362 363 364 --closed-loop --loops-only --variant "offgate="

`method_probe.py` with two functions patched in this process only (nothing in the package
changes): `MotionGate.update` is fed the running sum of the offset that the gate scales (the
moving twin's estimate minus the holding output, `motion_gate.moving_offset`), so the 'velocity'
it low-passes and compares with its median over the window is that offset itself. The gate then
opens when the twin and the holding network disagree more than they usually do, whatever the
twin's own speed. Every variant of the run gets the patched gate (run the default rows from
another process). Development seeds only, as `method_probe.py`. docs/BENCHMARKS.md,
thirty-second session.
"""
from __future__ import annotations

from pathlib import Path
import sys
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import method_probe  # noqa: E402 - the sibling script

import lf_predictor_ros.core.motion_gate as motion_gate  # noqa: E402
import lf_predictor_ros.core.predictor as predictor  # noqa: E402

_LAST_OFFSET: dict[str, Any] = {}
_moving_offset = motion_gate.moving_offset  # the function predictor.py imported
_update = motion_gate.MotionGate.update


def _stashed_offset(out: Any, moving: Any, ndof: int) -> Any:
    offset = _moving_offset(out, moving, ndof)
    _LAST_OFFSET['offset'] = offset
    return offset


def _offset_driven_update(self: motion_gate.MotionGate, moving: Any) -> Any:
    offset = _LAST_OFFSET.pop('offset', None)
    if offset is None or not np.all(np.isfinite(offset)):
        return _update(self, moving)
    total = getattr(self, '_offset_sum', None)
    total = np.array(offset, dtype=np.float64) if total is None else total + offset
    self._offset_sum = total  # type: ignore[attr-defined]
    return _update(self, total)


if __name__ == '__main__':
    setattr(predictor, 'moving_offset', _stashed_offset)  # noqa: B010 - the patch is the point
    motion_gate.MotionGate.update = _offset_driven_update  # type: ignore[method-assign]
    sys.exit(method_probe.main(sys.argv[1:]))
