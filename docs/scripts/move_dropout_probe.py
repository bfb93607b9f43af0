"""Exploratory: lf_odom's dead reckoning against the truth through each dropout of one loop.

    OMP_NUM_THREADS=1 python docs/scripts/move_dropout_probe.py rao_supply:777 \
        [--spread 500 | --moves 10 60] [--odometry dead_reckoning_motion_balance=true]

Runs `odometry_bench`'s lf_odom dropout loop (the predictor's pose to the PID, the D term from
lf_odom's twist, the commands fed; 3600 s, the dropouts of ``--spread``, or of ``--moves``:
`odometry_bench.move_dropouts`, in the setpoint moves) once and prints, every
10 s of each dropout, the dead-reckoned pose, the true LF pose, the dead-reckoned twist and the
published pose std, and the dead reckoner in use; before each dropout, what its environment
balance starts from (the last twist, its low-passed value, the published twist std).
Development seeds only, as `method_probe.py`.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
import sys
from typing import Any

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
import method_probe as mp  # noqa: E402

from lf_predictor_ros.benchmark import odometry_bench as ob  # noqa: E402
from lf_predictor_ros.benchmark.estimators import predictor_params  # noqa: E402
from lf_predictor_ros.core.lf_dynamics import LfDynamics  # noqa: E402
from lf_predictor_ros.core.odometry import LfOdometry, OdometryEstimate  # noqa: E402
from lf_predictor_ros.core.odometry_params import OdometryParams  # noqa: E402
from lf_predictor_ros.core.params import PredictorParams  # noqa: E402
from sim_ros.simulation import Scenario, load_scenario  # noqa: E402

DURATION = 3600.0  # [s] the odometry bench's loop length


def dropout_parser(description: str | None) -> argparse.ArgumentParser:
    """The probes' common arguments: cases, ``--spread``, ``--moves``, ``--odometry``."""
    parser = argparse.ArgumentParser(description=description,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('cases', nargs='+', help='SCENARIO:SEED (development seeds)')
    parser.add_argument('--spread', type=float, default=500.0, help='--dropout-spread [s]')
    parser.add_argument('--moves', nargs=2, type=float, default=None, metavar=('LOW', 'HIGH'),
                        help='dropouts U(LOW, HIGH) s into each setpoint move instead')
    parser.add_argument('--odometry', nargs='*', default=[], help='OdometryParams FIELD=VALUE')
    return parser


def parse_dropout_args(parser: argparse.ArgumentParser, argv: Sequence[str] | None
                       ) -> tuple[argparse.Namespace, list[tuple[str, int]], dict[str, Any]]:
    """(arguments, development cases, OdometryParams overrides); a bad case exits."""
    args = parser.parse_args(argv)
    try:
        cases = mp.parse_cases(args.cases, mp.DEVELOPMENT_SEEDS)
    except ValueError as exc:
        parser.error(str(exc))
    overrides = ob._odometry_overrides(args.odometry)  # noqa: SLF001 - the CLI's parser
    if overrides is None:  # a bad field was silently dropped before: the run was the default's
        parser.error('--odometry takes FIELD=VALUE with FIELD an OdometryParams field and a '
                     f'valid value, got {args.odometry}')
    return args, cases, overrides


def dropouts_of(scenario: Scenario, params: PredictorParams, seed: int, spread: float,
                moves: Sequence[float] | None) -> list[tuple[float, float]]:
    """The bench's dropouts of a case: the spread schedule, or ``moves`` (LOW, HIGH) s in."""
    if moves is None:
        return list(ob.default_dropouts(params, DURATION, length=ob.DROPOUT_LOOP_LENGTH,
                                        shift=ob.dropout_shift_for_seed(seed, spread)))
    return list(ob.move_dropouts(scenario, params, seed, DURATION,
                                 (float(moves[0]), float(moves[1]))))


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point."""
    args, cases, overrides = parse_dropout_args(dropout_parser(__doc__), argv)
    odometry = OdometryParams(**overrides)

    def one(scenario_name: str, seed: int) -> None:
        scenario = load_scenario(scenario_name)
        params = predictor_params(scenario, None)
        dropouts = dropouts_of(scenario, params, seed, args.spread, args.moves)
        log: list[OdometryEstimate] = []
        original = LfOdometry._balanced_model

        def traced(odometry: LfOdometry) -> LfDynamics | None:
            """The balance at a dead reckoning's start, and what it was made from."""
            last = odometry._last_output  # noqa: SLF001 - the last tracking estimate
            if last is not None:
                std = np.sqrt(np.diag(last.twist_cov))
                slow = odometry._slow_twist  # noqa: SLF001
                print(f'  balance at t={last.stamp:.0f}: twist {np.round(last.twist, 3)}, '
                      f'low-passed {None if slow is None else np.round(slow, 3)}, published '
                      f'twist std {np.round(std, 3)}')
            memory = odometry.memory
            if memory is not None and memory.model is not None:
                model = memory.model
                print(f'  model: 1/damping rate {np.round(-1.0 / np.diag(model.damping), 1)} s, '
                      f'thrust gain {np.diag(model.input_gain)} (known: {memory.known_gain})')
            return original(odometry)

        LfOdometry._balanced_model = traced  # type: ignore[method-assign, assignment]
        run = ob._odometry_loop(scenario, seed, DURATION, params, odometry,  # noqa: SLF001
                                dropouts, log)
        record = run.record
        print(f'{scenario_name}:{seed} dropouts (start, length) {dropouts}')
        for start, length in dropouts:
            estimates = [o for o in log if start <= o.stamp <= start + length + 1]
            print(f'  dropout {start:.0f}–{start + length:.0f} s: dead reckoner '
                  f'{estimates[0].reckoner if estimates else None}')
            for out in estimates[::10]:
                k = int(np.argmin(np.abs(record.t - out.stamp)))
                std = np.sqrt(np.diag(out.pose_cov))
                print(f'    t={out.stamp:.0f} estimate {np.round(out.pose, 2)} truth '
                      f'{np.round(record.truth_lf_pose[k], 2)} twist {np.round(out.twist, 3)} '
                      f'std {np.round(std, 2)}')

    torch.set_num_threads(1)
    for scenario_name, seed in cases:
        one(scenario_name, seed)
    return 0


if __name__ == '__main__':
    sys.exit(main())
