"""Exploratory: could an observer be learned without the truth? (issue 13, hypothesis 2).

    OMP_NUM_THREADS=1 python docs/scripts/learned_observer_probe.py rao_swell \
        --tune 1584 1585 --seeds 1586 1587 1588 1589 1590 1591 1592 1593

The benchmark's tuned passive observer knows the true M and D and has its gains chosen against
the true LF pose; `observer_mistuned` (M ×1.3, D ×0.7, ω0 ×1.2, the same gains) still holds
position in the loop 1.6–1.7× better than the adaptive predictor on the RAO vessels
(docs/BENCHMARKS.md, forty-sixth session). A product cannot know the truth. This probe asks the
two questions that decide whether a *learned* observer is worth building:

1. **Gains without the truth.** The passive observer's gains chosen by the same coordinate
   descent (`baseline_tuning.coordinate_search` over `OBSERVER_GRID` from `RECORDING_OBSERVER`)
   against the predictor's zero-phase targets (the benchmark's ``smoother_targets`` row: the
   shipped target settings at the true ω0) instead of the true LF pose, on the ``--tune``
   seeds' fair recordings.
2. **A wrong model.** The same with the model 30 % wrong (M ×1.3, D ×0.7; about what the
   vessel memory learns late in a run, forty-sixth session), ω0 the true one (the predictor
   estimates ω0 itself).

Printed per ``--seeds`` seed (fair recordings, events delayed as `benchmark` delays them):
open-loop RMSE per DOF against the truth and the DP loop's position RMSE and wave-band thrust
share of the raw loop's (`suite.run_closed_loops`, scored from the benchmark's first scored
sample) for ``adaptive`` (shipped defaults), ``obs_truth`` (true model, gains tuned against the
truth on the ``--tune`` seeds), ``obs_targets`` (true model, gains against the targets) and
``obs_learned`` (the 30 % wrong model, gains against the targets). The ω0 each observer uses is
the true one (as the benchmark's observer). ``--wrong-model-truth-gains`` adds ``obs_wrong_tg``:
the 30 % wrong model with ``obs_truth``'s gains (added after the first results, to tell the
model's part from the gains'); ``--benchmark-mistuned`` adds the benchmark's own
``observer_mistuned`` loop (`config/baselines` gains, M ×1.3, D ×0.7 and ω0 ×1.2). Development
seeds only.

Question and decision (written before any run, seventy-first session): (a) if ``obs_targets``
has an open-loop RMSE ≤ 1.15× ``obs_truth``'s in every DOF (mean over the seeds) on rao_supply,
rao_swell and supply_closed_loop, gain selection against the targets works; (b) if
``obs_learned``'s loop holds position at ≤ 0.8× the adaptive loop's (paired geometric mean) on
both RAO vessels and ≤ 1.0× on supply_closed_loop, every loop stable, a learned observer (on the
vessel memory's model, gains chosen against the targets online) is the next thing to build;
otherwise not, and the reason is reported.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
import sys
from typing import Any

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from method_probe import DEVELOPMENT_SEEDS, fair_case  # noqa: E402 - the sibling script

from lf_predictor_ros.benchmark import baseline_tuning as bt  # noqa: E402
from lf_predictor_ros.benchmark.baseline_tuning import smoother_settings  # noqa: E402
from lf_predictor_ros.benchmark.benchmark import SCHEDULE_SPREAD  # noqa: E402
from lf_predictor_ros.benchmark.estimators import EstimatorSetup  # noqa: E402
from lf_predictor_ros.benchmark.suite import run_closed_loops, scored_start  # noqa: E402
from lf_predictor_ros.core.baselines.smoother import smooth_poses  # noqa: E402
from sim_ros.physics.vessels import LinearModel  # noqa: E402
from sim_ros.simulation import simulate  # noqa: E402

DURATION = 1800.0  # [s] as method_probe
WRONG_MASS = 1.3  # the learned model's error assumed: M ×1.3, D ×0.7 (observer_mistuned's)
WRONG_DAMPING = 0.7


def targets_of(data: dict[str, Any], setup: EstimatorSetup) -> np.ndarray:
    """The predictor's zero-phase targets of a whole recording (true ω0).

    The benchmark's ``smoother_targets`` row (`suite.run_open_loop`): the predictor's own target
    settings at the scenario's ω0.
    """
    settings = smoother_settings(setup.baselines, 'smoother_targets', setup.params)
    return smooth_poses(data['y'], setup.sample_time, setup.wave_peak_freq, setup.ndof,
                        **settings)


def tuning_case(scenario_name: str, seeds: Sequence[int], reference: str,
                model: LinearModel | None) -> tuple[bt.TuningCase, LinearModel]:
    """A `TuningCase` of fair recordings scored against ``reference`` ('truth' or 'targets')."""
    data, case = [], None
    for seed in seeds:
        scenario, base, setup, recording = fair_case(scenario_name, seed, DURATION,
                                                     SCHEDULE_SPREAD)
        d = dict(recording.data())
        if reference == 'targets':
            d['truth'] = targets_of(d, setup)
        data.append(d)
        if case is None:
            case = bt.TuningCase(scenario, setup.ndof, setup.sample_time, 1, 0, DURATION,
                                 model if model is not None else setup.model, [])
            case.begin = scored_start(base, len(d['t']))
    assert case is not None
    case.data = data
    case.raw_rmse = [bt.rmse(d['y'], d['truth'], case.ndof, case.begin) for d in data]
    return case, case.model


def wrong(model: LinearModel) -> LinearModel:
    """The model 30 % wrong (module docstring)."""
    return replace(model, mass=np.asarray(model.mass) * WRONG_MASS,
                   damping=np.asarray(model.damping) * WRONG_DAMPING)


def tune(case: bt.TuningCase) -> dict[str, float]:
    """The observer's gains by the baseline tuning's coordinate descent on ``case``."""
    best = bt.coordinate_search(bt.observer_objective(case), dict(bt.RECORDING_OBSERVER),
                                bt.OBSERVER_GRID, bt.OBSERVER_PASSES)
    return {k: float(best.point[k]) for k in bt.OBSERVER_DEFAULT}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('scenario')
    parser.add_argument('--tune', nargs='+', type=int, required=True)
    parser.add_argument('--seeds', nargs='+', type=int, required=True)
    parser.add_argument('--wrong-model-truth-gains', action='store_true',
                        help="also the wrong model with obs_truth's gains (obs_wrong_tg)")
    parser.add_argument('--benchmark-mistuned', action='store_true',
                        help="also the benchmark's observer_mistuned loop")
    args = parser.parse_args(argv)
    if set(args.tune + args.seeds) - set(DEVELOPMENT_SEEDS) or set(args.tune) & set(args.seeds):
        parser.error('development seeds only, the tuning and scoring seeds apart')
    torch.set_num_threads(1)
    truth_case, true_model = tuning_case(args.scenario, args.tune, 'truth', None)
    gains = {'obs_truth': (true_model, tune(truth_case))}
    target_case, _ = tuning_case(args.scenario, args.tune, 'targets', None)
    gains['obs_targets'] = (true_model, tune(target_case))
    learned_case, _ = tuning_case(args.scenario, args.tune, 'targets', wrong(true_model))
    gains['obs_learned'] = (wrong(true_model), tune(learned_case))
    if args.wrong_model_truth_gains:
        gains['obs_wrong_tg'] = (wrong(true_model), gains['obs_truth'][1])
    for name, (_, point) in gains.items():
        print(f'{args.scenario} gains {name}: {point}', flush=True)
    for seed in args.seeds:
        scenario, base, setup, recording = fair_case(args.scenario, seed, DURATION,
                                                     SCHEDULE_SPREAD)
        d = recording.data()
        start_index = scored_start(base, len(d['t']))
        start = float(d['t'][start_index])
        ideal = simulate(scenario, seed=seed, duration=DURATION, controller=True,
                         feedback='truth_lf')
        names = ('adaptive', 'raw') + (('observer_mistuned',) if args.benchmark_mistuned else ())
        loops, _ = run_closed_loops(scenario, seed, DURATION, setup, names, ideal, start)
        rows = {name: loops[name] for name in names if name != 'raw'}
        one = bt.TuningCase(scenario, setup.ndof, setup.sample_time, 1, start_index, DURATION,
                            setup.model, [dict(d)])
        for name, (model, point) in gains.items():
            case = replace(one, model=model)
            case.raw_rmse = [bt.rmse(d['y'], d['truth'], case.ndof, case.begin)]
            open_rmse = bt.observer_objective(case)(point).rmse
            observer_setup = replace(setup, model=model, baselines={'observer': point})
            loop, _ = run_closed_loops(scenario, seed, DURATION, observer_setup, ('observer',),
                                       ideal, start)
            rows[name] = {**loop['observer'], 'open_rmse': open_rmse}
        raw_thrust = loops['raw']['thrust_wave_band_power']
        for name, row in rows.items():
            share = ' / '.join(f'{row["thrust_wave_band_power"][k] / raw_thrust[k]:.4f}'
                               for k in raw_thrust)
            open_text = ' / '.join(f'{v:.4g}' for v in row.get('open_rmse', ()))
            print(f'  {args.scenario} {seed} {name:12s} position {row["position_rmse"]:.4f} m '
                  f'stable {row["stability"]["stable"]} thrust WF share {share}'
                  + (f' open {open_text}' if open_text else ''), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
