"""The benchmark's cases with every scheduled event of the scenario moved by a fixed time.

    OMP_NUM_THREADS=1 python docs/scripts/phase_shift_probe.py rao_supply --shift 30 \
        --seeds 11 12 13 14 15 16 17 18 19 20 -o phase_shift30_rao_supply.json.gz

Every held-out seed of `benchmark` has the same setpoint event times, and the predictor retrains
at the same instants (first training + k·Δ) in every run, so the benchmark's intervals do not
cover the phase between trainings and manoeuvres (docs/BENCHMARKS.md, twenty-first session).
This script runs `suite.run_case` (the benchmark's own case: fair recording, open-loop scores,
every closed loop) with ``schedule_shift`` = ``shift`` for each seed, prints one line per seed
(adaptive and observer loop position RMSE) and writes the cases as the benchmark's JSON
(``{'command': ..., 'cases': [...]}``, gzip if the name ends in .gz). `benchmark
--schedule-spread S` draws a shift per seed instead. Reporting only: nothing is chosen from
held-out seeds.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
import gzip
import json
from pathlib import Path
import sys

from lf_predictor_ros.benchmark.suite import run_case


def main(argv: Sequence[str] | None = None) -> int:
    """Run the shifted cases and write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('scenario')
    parser.add_argument('--shift', type=float, required=True, help='[s] added to every event')
    parser.add_argument('--seeds', type=int, nargs='+', required=True)
    parser.add_argument('-o', '--output', required=True, help='JSON (.json or .json.gz)')
    args = parser.parse_args(argv)
    cases = []
    for seed in args.seeds:
        case = run_case(args.scenario, seed, schedule_shift=args.shift).to_dict()
        cases.append(case)
        loops = case['closed_loop']
        print(f"{args.scenario} {seed} adaptive {loops['adaptive']['position_rmse']:.4f} m "
              f"observer {loops['observer']['position_rmse']:.4f} m", flush=True)
    command = 'python docs/scripts/phase_shift_probe.py ' + ' '.join(sys.argv[1:] if argv is None
                                                                    else argv)
    text = json.dumps({'command': command, 'cases': cases})
    if args.output.endswith('.gz'):
        with gzip.open(args.output, 'wt', encoding='utf-8') as stream:
            stream.write(text)
    else:
        Path(args.output).write_text(text, encoding='utf-8')
    return 0


if __name__ == '__main__':
    sys.exit(main())
