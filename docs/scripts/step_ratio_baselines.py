"""The output-step ratio of the baselines on the fair recordings: is 3× attainable at all?

    OMP_NUM_THREADS=1 python docs/scripts/step_ratio_baselines.py supply_closed_loop 755 756

Per development seed, open loop on `method_probe.fair_case` (scheduled events delayed as
`method_probe.py` delays them): the largest one-sample output step over the largest true LF
step, north / east / heading (`evaluation.score`'s ``largest_step_ratio``, from the
benchmark's first scored sample), of the oracle Kalman filter (the true model and noise: the
limit), the tuned passive observer, the tuned cascade and the adaptive predictor, as
`suite.run_open_loop` runs them (the predictor's output aligned to its instant). The method
issue asks for no step above 3× in any run. Development seeds only.
"""
from __future__ import annotations

from pathlib import Path
import sys

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
import method_probe as mp  # noqa: E402 - the sibling script

from lf_predictor_ros.benchmark.benchmark import SCHEDULE_SPREAD  # noqa: E402
from lf_predictor_ros.benchmark.suite import run_open_loop, scored_start  # noqa: E402
from lf_predictor_ros.core.evaluation import score  # noqa: E402

NAMES = ('oracle_kf', 'observer', 'cascade', 'adaptive')


def main(argv: list[str]) -> int:
    """One line per seed (module docstring)."""
    if len(argv) < 2 or not all(a.isdigit() for a in argv[1:]):
        print('usage: step_ratio_baselines.py SCENARIO SEED [SEED ...]', file=sys.stderr)
        return 2
    seeds = [int(a) for a in argv[1:]]
    if set(seeds) - set(mp.DEVELOPMENT_SEEDS):
        print('development seeds only (held-out seeds: `benchmark`)', file=sys.stderr)
        return 2
    torch.set_num_threads(1)
    for seed in seeds:
        scenario, params, setup, recording = mp.fair_case(argv[0], seed, 1800.0,
                                                          SCHEDULE_SPREAD)
        data = recording.data()
        outputs = run_open_loop(data, setup, NAMES, {})
        t, truth = data['t'], data['truth']
        start = scored_start(params, len(t))
        cells = []
        for name in NAMES:
            steps = score(t[start:], outputs[name][start:], truth[start:],
                          params.ndof).largest_step_ratio
            cells.append(f'{name} ' + '/'.join(f'{v:.2f}' for v in steps))
        print(argv[0], seed, ' | '.join(cells), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
