"""Exploratory: the motion gate's heading offset not low-passed (the twin's heading at gain 1).

    OMP_NUM_THREADS=1 python docs/scripts/yaw_raw_offset_probe.py --scenarios rao_supply \
        --seeds 755 756 --closed-loop --loops-only --variant "raw="

`method_probe.py` (or, with ``--blocks`` first, `loop_block_probe.py`) with, in this process
only (nothing in the package changes), the low-pass of the gate's offset twin − holding
(``motion_gate_smoothing``, 5 s) left off the heading entry: the gated heading is holding +
g·(twin − holding), so at the heading gain 1 of a turn (``motion_gate_yaw_moment_ratio``) it
is the twin's heading itself. Why (docs/BENCHMARKS.md, forty-fifth session, "the heading's
output steps"): at gain 1 the low-passed offset lets a source switch of the holding side (a
guard trip) reach the published heading at once, a 0.12 rad step on rao_supply 760. North and
east keep their low-pass. Every variant of the run gets the patch. Development seeds only, as
`method_probe.py`.
"""
from __future__ import annotations

from pathlib import Path
import sys
from typing import Any

import numpy as np
from numpy.typing import NDArray

sys.path.insert(0, str(Path(__file__).resolve().parent))
import loop_block_probe  # noqa: E402 - the sibling script

from lf_predictor_ros.core import predictor as predictor_module  # noqa: E402
from lf_predictor_ros.core.filters import low_pass_step  # noqa: E402


def raw_heading_low_pass(state: Any, value: Any, weight: float) -> NDArray[np.float64]:
    """`low_pass_step` of the gate's offset, its heading entry (of three) the value itself."""
    out = low_pass_step(state, value, weight)
    if out.shape == (3,):
        out[2] = float(np.asarray(value, dtype=np.float64)[2])
    return out


if __name__ == '__main__':
    # the patch: core.predictor's low_pass_step is used by `_gated` alone
    setattr(predictor_module, 'low_pass_step', raw_heading_low_pass)  # noqa: B010
    print("# the gate offset's heading entry not low-passed", flush=True)
    sys.exit(loop_block_probe.probe_main(sys.argv[1:]))
