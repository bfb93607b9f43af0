"""Tuning runs of the adaptive predictor on the tuning seed (docs/BENCHMARKS.md, round 2).

    python -m lf_predictor_ros.benchmark.tuning "{'ny': 24, 'nu': 12}" "{'ny': 12, 'nu': 4}"

Each argument is one set of `PredictorParams` overrides (a Python/JSON dict literal); every set is
run on the scenarios (`--scenarios`, default the five of the tuning table) with the tuning seed 1
for `--duration` seconds, and the adaptive predictor's RMSE vs the true LF pose is printed, one
line per set. Held-out seeds are never used here (the `benchmark` executable reports those).
"""
from __future__ import annotations

import argparse
import ast
from collections.abc import Sequence
import sys
import time

import numpy as np

from lf_predictor_ros.benchmark.suite import run_case

TUNING_SEED = 1
TUNING_SCENARIOS = ('onedof_excited', 'onedof_reference', 'onedof_feedback', 'threedof_open_loop',
                    'supply_closed_loop')


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: one output line per override set."""
    parser = argparse.ArgumentParser(prog='tuning', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('overrides', nargs='*', default=['{}'], help='dict literals')
    parser.add_argument('--scenarios', nargs='*', default=list(TUNING_SCENARIOS))
    parser.add_argument('--duration', type=float, default=1800.0, help='simulated s')
    args = parser.parse_args(argv)
    for text in args.overrides:
        try:
            overrides = ast.literal_eval(text)
        except (ValueError, SyntaxError) as exc:
            parser.error(f'{text!r} is not a dict literal: {exc}')
        if not isinstance(overrides, dict):
            parser.error(f'{text!r} is not a dict literal')
        cells = []
        for name in args.scenarios:
            start = time.monotonic()
            try:
                case = run_case(name, TUNING_SEED, duration=args.duration,
                                params_overrides=overrides, estimators=('adaptive',))
            except ValueError as error:
                parser.error(f'{overrides}: {error}')
            rmse = np.round(case.metrics['adaptive'].rmse, 4).tolist()
            cells.append(f'{name}: {rmse} ({time.monotonic() - start:.0f} s)')
        print(overrides, ' | '.join(cells), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
