"""Exploratory: what a dead reckoning starts from in lf_odom's loop, against the truth.

    OMP_NUM_THREADS=1 python docs/scripts/start_twist_log.py rao_swell:1225 rao_supply:1217 \
        [--moves 10 60 | --spread 500] [--odometry FIELD=VALUE …] -o starts.json

Runs only lf_odom's dropout loop of `odometry_bench` (the dropouts of ``--moves`` or
``--spread``, `move_dropout_probe.dropouts_of`) and records at each dropout start, per DOF
(body frame): the current twist (the last published), the start twist the odometry chose, the
wave-averaged twist mean(T) and mean(2T) (`SpanMean`, kept whatever the start option: the
averaging windows are filled for the log), the holding and the published twist std, the
moving DOFs, and the true LF body velocity; the environment force the dead reckoning starts
from (G⁻¹ B β(ψ) of the balanced model, as `dropout_start_probe.py`) and that model's thrust
gains and damping rates (diagonals of G and F) and, on the supply vessel,
the truth's (M ν̇ + D ν − τ over the 30 s before); plus lf_odom's heading error 59 s in and
the heading std it published then. The list is written as JSON for offline comparison of start
rules (the start's yaw-rate error times the yaw time constant is most of a dropout's heading
error). Development seeds only; the sixty-second session's section of docs/BENCHMARKS.md.
"""
from __future__ import annotations

import json
from pathlib import Path
import sys
from typing import Any

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
import dropout_start_probe as probe  # noqa: E402
import move_dropout_probe as mdp  # noqa: E402

from lf_predictor_ros.benchmark import odometry_bench as ob  # noqa: E402
from lf_predictor_ros.benchmark.estimators import predictor_params  # noqa: E402
from lf_predictor_ros.core.lf_dynamics import LfDynamics, body_velocity  # noqa: E402
from lf_predictor_ros.core.odometry import LfOdometry, OdometryEstimate  # noqa: E402
from lf_predictor_ros.core.odometry_params import OdometryParams  # noqa: E402
from sim_ros.simulation import load_scenario  # noqa: E402

FloatArray = np.ndarray
SUPPLY_SCENARIOS = ('rao_supply', 'rao_swell')  # the vessel of `probe.true_environment`


def _listed(value: FloatArray | None) -> list[float] | None:
    return None if value is None else [float(v) for v in value]


def one(name: str, seed: int, spread: float, moves: list[float] | None,
        odometry: OdometryParams) -> list[dict[str, Any]]:
    """The dropout starts of one case (``spread``, ``moves``: `mdp.dropouts_of`)."""
    scenario = load_scenario(name)
    params = predictor_params(scenario, None)
    drops = mdp.dropouts_of(scenario, params, seed, spread, moves)
    starts: list[dict[str, Any]] = []
    original_start = LfOdometry._start_twist
    original_double = LfOdometry._uses_double_span
    original_balanced = LfOdometry._balanced_model
    environments: dict[float, list[float]] = {}
    models: dict[float, dict[str, list[float] | None]] = {}

    def balanced(self: LfOdometry) -> LfDynamics | None:
        model = original_balanced(self)
        x, last = self._x, self._last_output  # noqa: SLF001
        if model is not None and x is not None and last is not None and self.ndof == 3:
            environment = probe.start_environment(model, float(x[2]))
            environments[float(last.stamp)] = _listed(environment) or []
            models[float(last.stamp)] = {'input_gain': _listed(np.diag(model.input_gain)),
                                         'damping': _listed(np.diag(model.damping))}
        return model

    def traced(self: LfOdometry, state: FloatArray) -> FloatArray:
        chosen = original_start(self, state)
        last = self._last_output  # noqa: SLF001
        n = self.ndof
        moving = self._moving_dofs(np.ones(n, dtype=bool))  # noqa: SLF001
        starts.append({
            'stamp': None if last is None else float(last.stamp),
            'current': _listed(state[n:]), 'start': _listed(chosen),
            'average': _listed(self._wave_averaged_twist()),  # noqa: SLF001
            'average_double': _listed(self._wave_twist_double.mean()),  # noqa: SLF001
            'holding_std': _listed(self._holding_twist_std()),  # noqa: SLF001
            'published_std': None if last is None else
            _listed(np.sqrt(np.diag(last.twist_cov)[:n])),
            'moving': None if moving is None else [bool(m) for m in moving]})
        return chosen

    LfOdometry._start_twist = traced  # type: ignore[method-assign]
    LfOdometry._uses_double_span = lambda self: True  # type: ignore[method-assign]
    LfOdometry._balanced_model = balanced  # type: ignore[method-assign]
    log: list[OdometryEstimate] = []
    try:
        run = ob._odometry_loop(scenario, seed, mdp.DURATION, params, odometry,  # noqa: SLF001
                                drops, log)
    finally:
        LfOdometry._start_twist = original_start  # type: ignore[method-assign]
        LfOdometry._uses_double_span = original_double  # type: ignore[method-assign]
        LfOdometry._balanced_model = original_balanced  # type: ignore[method-assign]
    record = run.record
    h = float(record.t[1] - record.t[0])
    nu = body_velocity(record.truth_lf_pose, h)
    out = []
    for entry in starts:
        if entry['stamp'] is None:
            continue
        k = int(np.argmin(np.abs(record.t - entry['stamp'])))
        end = entry['stamp'] + 59.0
        late = next((o for o in log if abs(o.stamp - end) < 0.6), None)
        heading_error = heading_std = None
        if late is not None:
            heading_std = float(np.sqrt(late.pose_cov[2, 2]))
            j = int(np.argmin(np.abs(record.t - end)))
            heading_error = float(np.angle(np.exp(1j * (late.pose[2] -
                                                        record.truth_lf_pose[j, 2]))))
        true_env = _listed(probe.true_environment(record, entry['stamp'])[0]) \
            if scenario.name in SUPPLY_SCENARIOS else None
        out.append({'scenario': name, 'seed': seed, **entry, 'true': _listed(nu[k]),
                    'environment': environments.get(entry['stamp']),
                    'model': models.get(entry['stamp']),
                    'true_environment': true_env, 'heading_error_59': heading_error,
                    'heading_std_59': heading_std})
    return out


def main(argv: list[str] | None = None) -> int:
    """Entry point."""
    parser = mdp.dropout_parser(__doc__)
    parser.add_argument('-o', '--output', required=True, help='JSON file of the starts')
    args, cases, overrides = mdp.parse_dropout_args(parser, argv)
    odometry = OdometryParams(**overrides)
    torch.set_num_threads(1)
    rows: list[dict[str, Any]] = []
    for name, seed in cases:
        rows.extend(one(name, seed, args.spread, args.moves, odometry))
        print(f'{name}:{seed}: {len(rows)} starts so far', flush=True)
    with open(args.output, 'w', encoding='utf-8') as stream:
        json.dump(rows, stream, indent=1)
    return 0


if __name__ == '__main__':
    sys.exit(main())
