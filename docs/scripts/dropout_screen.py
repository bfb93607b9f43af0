"""Exploratory: lf_odom's loops through dropouts, lf_odom alone, and its trust against k offline.

    OMP_NUM_THREADS=1 python docs/scripts/dropout_screen.py rao_supply:771 ... \
        [--spread 500 | --moves 10 60] [--odometry dead_reckoning_holding_balance=true] \
        [--k 0 0.5 1 1.5 2]

A cheap screen of `odometry_bench run --dropout-loops`: only lf_odom's loop with the dropouts
is run (not the observer's loops nor the loops without dropouts, which an option of lf_odom's
dead reckoning cannot change), once per case, with ``dead_reckoning_excursion_std`` = 1e-9 (the
loop of k = 0 to within rounding; the miss term of a reckoner other than the model is in the
published covariance already; a loop with k > 0 differs from this one only after a
reacquisition: the first dropout of every run is the same). Per case it prints the bench's
lf_odom `during` (the mean over the dropouts of the worst horizontal distance of the true LF
pose from the loop's reference during each; `odometry_bench.dropout_deviation`), its worst
heading difference (`during_heading`) and whether the loop aborted. For every dead-reckoned
estimate it records the displacement the memory's model dead-reckoned since the
dropout began (the arguments of `odometry.excursion_covariance`) and recomputes, for each k of
``--k``, the published pose covariance with k² diag(|d_NE|², |d_NE|², d_ψ²) added: printed per
case and per scenario is the bench's trust measure, the mean over dropouts of the fraction of
dead-reckoned estimates with the truth inside the 95 % ellipse (`odometry_bench.
dropout_coverage`). The loop itself does not change with k here; in the bench a larger
covariance also lets a reacquisition through sooner. Development seeds only, as
`method_probe.py`.
"""
from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
import sys
from typing import Any

import numpy as np
from scipy import stats
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
import move_dropout_probe as probe  # noqa: E402

from lf_predictor_ros.benchmark import odometry_bench as ob  # noqa: E402
from lf_predictor_ros.benchmark.estimators import predictor_params  # noqa: E402
from lf_predictor_ros.benchmark.suite import _loop_reference  # noqa: E402
from lf_predictor_ros.core import odometry as odometry_module  # noqa: E402
from lf_predictor_ros.core.odometry import LfOdometry, OdometryEstimate  # noqa: E402
from lf_predictor_ros.core.odometry_params import OdometryParams  # noqa: E402
from sim_ros.simulation import load_scenario, simulate  # noqa: E402

DURATION = 3600.0  # [s] the odometry bench's loop length
TINY_K = 1e-9  # [-] the excursion term computed, not felt


def _spread(model_displacement: np.ndarray) -> np.ndarray:
    """diag(|d_NE|², |d_NE|², d_ψ²) (3 DOF) or d² (1 DOF): the k² term's matrix."""
    d = np.asarray(model_displacement, dtype=np.float64)
    values = d ** 2
    if d.size == 3:
        values[:2] = float(d[0] ** 2 + d[1] ** 2)
    return np.diag(values)


def one_case(scenario_name: str, seed: int, odometry: OdometryParams,
             spread: float, moves: tuple[float, float] | None,
             ks: Sequence[float]) -> tuple[list[list[float]], float, float, bool]:
    """One loop: (truth-in-ellipse fractions, mean `during` [m], heading [rad], aborted).

    The fractions: rows are dropouts, columns the values of ``ks``. The heading: the mean worst
    heading difference during the dropouts (`during_heading`; NaN in 1 DOF).
    """
    scenario = load_scenario(scenario_name)
    params = predictor_params(scenario, None)
    dropouts = probe.dropouts_of(scenario, params, seed, spread, moves)
    seen: dict[str, Any] = {}
    spreads: dict[float, np.ndarray] = {}
    original_cov = odometry_module.excursion_covariance
    original_dr = LfOdometry._dead_reckoned  # noqa: SLF001

    def recorded_cov(*args: Any, **kwargs: Any) -> tuple[np.ndarray, np.ndarray]:
        seen['model_displacement'] = np.array(args[1], dtype=np.float64)
        return original_cov(*args, **kwargs)

    def recorded_dr(self: LfOdometry, t: float, elapsed: float) -> OdometryEstimate:
        seen.pop('model_displacement', None)
        out = original_dr(self, t, elapsed)
        if 'model_displacement' in seen:
            spreads[round(out.stamp, 6)] = _spread(seen['model_displacement'])
        return out

    odometry_module.excursion_covariance = recorded_cov
    LfOdometry._dead_reckoned = recorded_dr  # type: ignore[method-assign]  # noqa: SLF001
    log: list[OdometryEstimate] = []
    try:
        run = ob._odometry_loop(scenario, seed, DURATION, params, odometry,  # noqa: SLF001
                                dropouts, log)
    finally:
        odometry_module.excursion_covariance = original_cov
        LfOdometry._dead_reckoned = original_dr  # type: ignore[method-assign]  # noqa: SLF001
    ndof = params.ndof
    chi2_95 = float(stats.chi2.ppf(ob.CONFIDENCE, ndof))
    rec = run.record
    rows = []
    for start, length in dropouts:
        inside: list[list[bool]] = [[] for _ in ks]
        for estimate in log:
            if not start <= estimate.stamp < start + length:
                continue
            k_sample = int(np.searchsorted(rec.t, estimate.stamp - 1e-9))
            if k_sample >= rec.t.size or abs(rec.t[k_sample] - estimate.stamp) > 1e-6:
                continue
            err = ob._wrap_error(estimate.pose, rec.truth_lf_pose[k_sample],  # noqa: SLF001
                                 ndof)
            base = estimate.pose_cov[:ndof, :ndof]
            extra = spreads.get(round(estimate.stamp, 6), np.zeros((3, 3)))[:ndof, :ndof]
            for j, k in enumerate(ks):
                cov = base + k ** 2 * extra
                inside[j].append(bool(err @ np.linalg.solve(cov, err) <= chi2_95))
        if inside[0]:
            rows.append([float(np.mean(values)) for values in inside])
    ideal = simulate(scenario, seed=seed, duration=DURATION, controller=True,
                     feedback='truth_lf')
    deviation = ob.dropout_deviation(run, _loop_reference(scenario, run.record, ideal), ndof,
                                     dropouts)
    during = float(np.mean([row['during'] for row in deviation]))
    heading = float(np.mean([row.get('during_heading', np.nan) for row in deviation]))
    return rows, during, heading, run.aborted_at is not None


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point."""
    parser = probe.dropout_parser(__doc__)
    parser.add_argument('--k', nargs='+', type=float, default=[0.0, 0.5, 1.0, 1.5, 2.0],
                        help='dead_reckoning_excursion_std values to score')
    args, cases, overrides = probe.parse_dropout_args(parser, argv)
    overrides['dead_reckoning_excursion_std'] = TINY_K
    odometry = OdometryParams(**overrides)
    moves = None if args.moves is None else (float(args.moves[0]), float(args.moves[1]))
    torch.set_num_threads(1)
    per_scenario: dict[str, list[list[float]]] = defaultdict(list)
    runs: dict[str, list[tuple[float, bool]]] = defaultdict(list)
    headings: dict[str, list[float]] = defaultdict(list)
    for scenario_name, seed in cases:
        rows, during, heading, aborted = one_case(scenario_name, seed, odometry, args.spread,
                                                  moves, args.k)
        per_scenario[scenario_name].extend(rows)
        runs[scenario_name].append((during, aborted))
        headings[scenario_name].append(heading)
        print(f'{scenario_name}:{seed}: during {during:.2f} m, heading {heading:.3f} rad'
              f'{" ABORTED" if aborted else ""}; '
              'trust ' + ', '.join(f'k={k:g} {np.mean([r[j] for r in rows]):.3f}'
                                   for j, k in enumerate(args.k)), flush=True)
    for scenario_name, rows in per_scenario.items():
        table = np.array(rows)
        durings = [d for d, _ in runs[scenario_name]]
        lost = sum(a for _, a in runs[scenario_name])
        print(f'{scenario_name}: during per run {np.nanmean(durings):.2f} m (runs not aborted), '
              f'heading {np.nanmean(headings[scenario_name]):.3f} rad, '
              f'{lost}/{len(durings)} aborted; {table.shape[0]} dropouts, trust ' + ', '.join(
                  f'k={k:g} {table[:, j].mean():.3f}' for j, k in enumerate(args.k)))
    return 0


if __name__ == '__main__':
    sys.exit(main())
