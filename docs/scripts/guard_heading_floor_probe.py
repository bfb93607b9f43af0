"""Exploratory: the sanity guard's heading floor raised, so that turns do not trip it.

    GUARD_FLOOR_YAW=0.1 OMP_NUM_THREADS=1 python docs/scripts/guard_heading_floor_probe.py \
        --scenarios rao_supply --seeds 675 694 --closed-loop --loops-only --variant "gf="

`method_probe.py` (or, with ``--blocks`` first, `loop_block_probe.py`) with, in this process
only (nothing in the package changes), `core.predictor.GUARD_FLOOR`'s heading entry set to
``GUARD_FLOOR_YAW`` rad (shipped 0.02 rad; the bound is 6 × the window's wave yaw + the floor,
about 0.10 rad on rao_supply). Why (docs/BENCHMARKS.md, forty-fourth session): every guard trip
in rao_supply's turn excursions is the heading's — the holding network lags the turn by 0.11–0.15
rad, the motion gate's twin overshoots its end by 0.10–0.13 rad — and each trip switches the
heading between sources that disagree by up to 0.25 rad. Every variant of the run gets the
patch. Development seeds only, as `method_probe.py`.
"""
from __future__ import annotations

import os
from pathlib import Path
import sys

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import loop_block_probe  # noqa: E402 - the sibling script

from lf_predictor_ros.core import predictor as predictor_module  # noqa: E402

GUARD_FLOOR_YAW = float(os.environ.get('GUARD_FLOOR_YAW', '0.1'))  # [rad]


def set_heading_floor(floor_yaw: float) -> None:
    """The patch: `core.predictor.GUARD_FLOOR`'s heading entry set to ``floor_yaw`` [rad]."""
    floor = np.array(predictor_module.GUARD_FLOOR, dtype=np.float64)
    floor[2] = floor_yaw
    predictor_module.GUARD_FLOOR = floor
    print(f'# guard floor {floor.tolist()}', flush=True)


if __name__ == '__main__':
    set_heading_floor(GUARD_FLOOR_YAW)
    sys.exit(loop_block_probe.probe_main(sys.argv[1:]))
