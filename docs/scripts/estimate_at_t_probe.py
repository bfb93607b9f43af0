"""Probe: the shipped predictor trained to estimate the LF pose at t instead of t + h (issue 13).

    OMP_NUM_THREADS=1 python docs/scripts/estimate_at_t_probe.py rao_swell 1 2 3

The predictor publishes the LF pose predicted for the next sample (thesis: ŷLF(t + 1)); the
baselines estimate the pose at t. This probe patches `prepare_window` in `core.training` (the name
it imported from `core.training_window`) so that row t's training target is yT(t) (the target
series and its mask shifted one sample later; nothing else changes: the same windows, targets,
regressors and defaults) and prints, per seed, the open-loop RMSE of that predictor against the
truth at t and at t + h, and its DP loop next to the observer, oracle_kf and raw loops
(`method_probe.loops`, variant 'now'; the loops use every output at once, as for the shipped
predictor). Tuning and development seeds only. Compare with the default rows of `method_probe.py
--closed-loop` on the same seeds.
"""
from __future__ import annotations

from pathlib import Path
import sys
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
import torch

from lf_predictor_ros.benchmark.baseline_tuning import TUNING_SEEDS
from lf_predictor_ros.benchmark.suite import scored_start
from lf_predictor_ros.core import training
from lf_predictor_ros.core.heading import wrap_angle
from lf_predictor_ros.core.predictor import AdaptivePredictor
from lf_predictor_ros.core.training_window import prepare_window

sys.path.insert(0, str(Path(__file__).parent))
import method_probe  # noqa: E402  (the sibling script)

DURATION = 1800.0  # [s] as method_probe's default
_ORIGINAL = prepare_window


def _targets_at_t(spec: Any, u: ArrayLike, y: ArrayLike, targets: ArrayLike,
                  mask: ArrayLike | None) -> Any:
    """`prepare_window` with the targets one sample later: row t is trained on yT(t)."""
    series = np.asarray(targets, dtype=np.float64)
    series = np.concatenate([series[:1], series[:-1]])
    shifted = None if mask is None else np.concatenate(
        [[False], np.asarray(mask, dtype=bool)[:-1]])
    return _ORIGINAL(spec, u, y, series, shifted)


def run(scenario_name: str, seed: int) -> None:
    scenario, params, setup, recording = method_probe.fair_case(scenario_name, seed, DURATION)
    data = recording.data()
    t, y, u, truth = data['t'], data['y'], data['u'], data['truth']
    predictor = AdaptivePredictor(params, background=False)
    estimate = np.array([predictor.update(t[k], y[k], u[k]) for k in range(len(t))])
    start = scored_start(params, len(t))
    for label, error in (('now vs truth[k]', estimate - truth),
                         ('now vs truth[k+1]', estimate[:-1] - truth[1:])):
        error = np.array(error, dtype=np.float64)
        error[:, 2] = wrap_angle(error[:, 2])
        rmse = np.sqrt(np.mean(error[start:, :params.ndof] ** 2, axis=0))
        print(f'{scenario_name:20s} {seed} {label:18s} ' + ' '.join(f'{v:.4f}' for v in rmse),
              flush=True)
    if scenario.controller.enabled:
        method_probe.loops(scenario, seed, DURATION, setup, recording, [('now', {})],
                           float(t[start]))


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print(__doc__)
        return 2
    seeds = [int(s) for s in argv[1:]]
    if set(seeds) - set(TUNING_SEEDS) - set(method_probe.DEVELOPMENT_SEEDS):
        print('tuning and development seeds only (held-out seeds: `benchmark`)')
        return 2
    setattr(training, 'prepare_window', _targets_at_t)  # noqa: B010 - the name training uses
    torch.set_num_threads(1)
    for seed in seeds:
        run(argv[0], seed)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
