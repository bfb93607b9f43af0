"""Does the motion gate's untaken twin offset tell how far the LF estimate is off? (issue 14)

    OMP_NUM_THREADS=1 python docs/scripts/twin_offset_probe.py rao_supply:101 \
        supply_closed_loop:101 threedof_open_loop:101

A diagnostic, tuning and development seeds only. Per SCENARIO:SEED, on the fair recording
(`method_probe.fair_case`, 1500 s, the benchmark's schedule spread), `LfStateEstimator` with the
shipped defaults runs inline and every calibrated estimate is kept with the predictor's
`untaken_twin_offset` m (what the gate left out of the output of the ramp-invariant twin's offset)
and the error e against the true LF pose. Printed, from the 481st such estimate on:

- per DOF, the correlation of e² with m² and the least-squares slope of e² on m² (a slope of
  1 means m² is the squared error);
- the joint pose NEES per DOF (e P⁻¹ e / n) and the per-DOF NEES with the shipped covariance P,
  and with P + diag(f(m)) afterwards for f = m² ('full', `pose_twin_gain` 1 applied to m² as it
  is) and f = max(0, m² − k L) for k = 2 and 4 ('excess'), L the level of m² low-passed over
  `odometry.TWIN_LEVEL_TIME` from the first calibrated estimate on (the shipped
  `pose_twin_gain` excess form is k = `TWIN_LEVEL_FACTOR`, its level updated after the sample).

docs/BENCHMARKS.md, thirty-second session.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
import sys

import numpy as np
from numpy.typing import NDArray

sys.path.insert(0, str(Path(__file__).resolve().parent))
from method_probe import (  # noqa: E402 - the sibling script
    DEVELOPMENT_SEEDS,
    fair_case,
    run_cases,
)

from lf_predictor_ros.benchmark.baseline_tuning import TUNING_SEEDS  # noqa: E402
from lf_predictor_ros.benchmark.benchmark import SCHEDULE_SPREAD  # noqa: E402
from lf_predictor_ros.benchmark.estimators import predictor_params  # noqa: E402
from lf_predictor_ros.core.heading import wrap_angle  # noqa: E402
from lf_predictor_ros.core.lf_state import LfStateEstimator  # noqa: E402
from lf_predictor_ros.core.odometry import TWIN_LEVEL_TIME  # noqa: E402
from lf_predictor_ros.core.odometry_params import OdometryParams  # noqa: E402

FloatArray = NDArray[np.float64]
DURATION = 1500.0  # [s] as the odometry benchmark's development runs
SKIP = 480  # calibrated estimates left out at the start (about the benchmark's warm-up)
Row = tuple[FloatArray, FloatArray, FloatArray, FloatArray]  # e, P, m², level


def collect(scenario_name: str, seed: int) -> tuple[int, list[Row]]:
    """(ndof, rows of (error, pose covariance, m², level of m²)) of one run."""
    scenario, _, _, recording = fair_case(scenario_name, seed, DURATION, SCHEDULE_SPREAD)
    data = recording.data()
    t, truth = data['t'], data['truth']
    params = predictor_params(scenario, {})
    n = params.ndof
    estimator = LfStateEstimator(params, OdometryParams(), background=False)
    rows: list[Row] = []
    level: FloatArray | None = None
    weight = params.sample_time / TWIN_LEVEL_TIME
    try:
        for k in range(len(t) - 1):
            odom = estimator.update(float(t[k]), data['y'][k], data['u'][k])[1]
            m2 = np.square(estimator.predictor.untaken_twin_offset[:n])
            if odom is None or not odom.calibrated:
                continue
            level = m2.copy() if level is None else level + weight * (m2 - level)
            error = odom.pose[:3] - truth[k + 1]  # the estimate of update k is for t[k + 1]
            error[2] = wrap_angle(float(error[2]))
            rows.append((error[:n], odom.pose_cov[:n, :n], m2, level.copy()))
    finally:
        estimator.close()
    return n, rows[SKIP:]


def forms() -> dict[str, Callable[[FloatArray, FloatArray], FloatArray]]:
    """The added variance per DOF, from (m², level)."""
    return {'none': lambda m2, level: np.zeros_like(m2),
            'full': lambda m2, level: m2,
            'excess2': lambda m2, level: np.maximum(0.0, m2 - 2.0 * level),
            'excess4': lambda m2, level: np.maximum(0.0, m2 - 4.0 * level)}


def report(name: str, n: int, rows: list[Row]) -> None:
    """Print the correlation and slope of e² on m², and the NEES of every form."""
    e2 = np.array([row[0] ** 2 for row in rows])
    m2 = np.array([row[2] for row in rows])
    parts = []
    for i in range(n):
        corr = float(np.corrcoef(e2[:, i], m2[:, i])[0, 1]) if np.std(m2[:, i]) > 0 else 0.0
        slope = float(np.polyfit(m2[:, i], e2[:, i], 1)[0]) if np.std(m2[:, i]) > 0 else 0.0
        parts.append(f'corr {corr:.2f} slope {slope:.2f}')
    print(f'{name}: e² on m² per DOF: ' + '; '.join(parts), flush=True)
    for form, added in forms().items():
        joint, per_dof = [], np.zeros(n)
        for error, cov, square, level in rows:
            total = cov + np.diag(added(square, level))
            joint.append(float(error @ np.linalg.solve(total, error)) / n)
            per_dof += error ** 2 / np.diag(total)
        print(f'{name}: {form:8s} joint NEES per DOF {np.mean(joint):.2f}, per DOF '
              + ' / '.join(f'{v:.2f}' for v in per_dof / len(rows)), flush=True)


def probe(scenario: str, seed: int) -> None:
    """Collect one run and print its report."""
    n, rows = collect(scenario, seed)
    report(f'{scenario} {seed}', n, rows)


def main(argv: Sequence[str] | None = None) -> int:
    return run_cases(argv, (__doc__ or '').splitlines()[0], {*TUNING_SEEDS, *DEVELOPMENT_SEEDS},
                     'only tuning and development seeds', probe)


if __name__ == '__main__':
    sys.exit(main())
