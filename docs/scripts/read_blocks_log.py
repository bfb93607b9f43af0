"""Exploratory: every block the controller read pooled, and every read, over `odometry_bench` runs.

    OMP_NUM_THREADS=1 python docs/scripts/read_blocks_log.py blocks.json run --workers 1 \
        --scheduler none --scenarios onedof_feedback --seeds 1313 1314 --duration 1500 \
        --no-loops --no-tracking --dead-reckoning-commands -o bench.json

Everything after the output file is `odometry_bench`'s command line, run in this process with
`lf_state.pooled_input_gain` wrapped (the default pooled read). Written as JSON: per pooled
block (each once) its R² per DOF, the inertia Kd² / (4 Kp) and natural frequency 2 Kp / Kd
it implies and whether each DOF is believed under the run's bounds; per read its outcome,
the inertia in force and its note ("k of n blocks … believed"). The sixty-third session's
R² distributions (docs/BENCHMARKS.md) come from this. Development seeds only.
"""
from __future__ import annotations

import json
import math
import sys
from typing import Any

import torch

from lf_predictor_ros.benchmark import odometry_bench
from lf_predictor_ros.core import lf_state


def main(argv: list[str] | None = None) -> int:
    """Entry point: the output file, then `odometry_bench`'s arguments."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) < 2:
        print(__doc__)
        return 2
    blocks: dict[int, dict[str, Any]] = {}
    reads: list[dict[str, Any]] = []
    original = lf_state.pooled_input_gain

    def traced(*positional: Any, **keywords: Any) -> tuple[lf_state.ControllerRead,
                                                         lf_state.ReadPool]:
        read, pool = original(*positional, **keywords)
        bound = positional[8] if len(positional) > 8 else \
            keywords.get('max_natural_freq', math.inf)
        for block in pool.blocks:
            blocks[id(block)] = {'r_squared': block.r_squared.tolist(),
                                 'inertia': block.inertia_per_dof().tolist(),
                                 'natural_freq': block.natural_freq().tolist(),
                                 'believed': block.believed(bound).tolist()}
        reads.append({'outcome': read.outcome, 'note': read.note, 'pooled': len(pool.blocks),
                      'inertia': None if read.gain is None else (1.0 / read.gain).tolist()})
        return read, pool

    lf_state.pooled_input_gain = traced
    torch.set_num_threads(1)
    try:
        odometry_bench.main(args[1:])
    finally:
        lf_state.pooled_input_gain = original
    with open(args[0], 'w', encoding='utf-8') as stream:
        json.dump({'blocks': list(blocks.values()), 'reads': reads}, stream, indent=1)
    print(f'{len(blocks)} blocks, {len(reads)} reads -> {args[0]}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
