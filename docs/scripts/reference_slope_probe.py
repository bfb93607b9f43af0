"""Does the calibration reference see what the truth sees of the untaken twin offset? (issue 14)

    OMP_NUM_THREADS=1 python docs/scripts/reference_slope_probe.py rao_supply:101 \
        threedof_open_loop:101 supply_closed_loop:101

A diagnostic, tuning and development seeds only (the thirty-third session's first table). Per
SCENARIO:SEED, on the fair recording (`method_probe.fair_case`, 1500 s, the benchmark's schedule
spread), `LfStateEstimator` runs inline with the shipped defaults and the predictor's
`untaken_twin_offset` m is kept per sample; `lf_state.calibrate` is wrapped to keep each
calibration window's published history and reference. For the last window, per DOF: the RMS
error of the published pose against the reference and against the truth, and the least-squares
slope (with its correlation) of e² on m² and on the excess max(0, m² − 2 L) (L: m² low-passed
over `odometry.TWIN_LEVEL_TIME` from the first sample), against each.
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
import sys

import numpy as np
from numpy.typing import NDArray

sys.path.insert(0, str(Path(__file__).resolve().parent))
from method_probe import DEVELOPMENT_SEEDS, run_cases  # noqa: E402 - the sibling script
from twin_gain_calibration import window_errors, windows  # noqa: E402 - the sibling script

from lf_predictor_ros.benchmark.baseline_tuning import TUNING_SEEDS  # noqa: E402
from lf_predictor_ros.core.lf_state import LfStateEstimator  # noqa: E402
from lf_predictor_ros.core.odometry import TWIN_LEVEL_TIME  # noqa: E402

FloatArray = NDArray[np.float64]


def _fit(x: FloatArray, y: FloatArray) -> str:
    if np.std(x) <= 0.0:
        return 'no spread'
    return f'{np.polyfit(x, y, 1)[0]:.2f} (r {np.corrcoef(x, y)[0, 1]:.2f})'


def report(scenario: str, seed: int) -> None:
    """Print the last calibration window's slopes against the reference and the truth."""
    squares: list[FloatArray] = []
    update = LfStateEstimator.update

    def keep_offset(self: LfStateEstimator, t: float, pose: FloatArray,
                    force: FloatArray) -> object:
        out = update(self, t, pose, force)
        squares.append(np.square(self.predictor.untaken_twin_offset[:self.ndof]))
        return out

    LfStateEstimator.update = keep_offset  # type: ignore[method-assign,assignment]
    try:
        n, h, t, truth, captured = windows(scenario, seed)
    finally:
        LfStateEstimator.update = update  # type: ignore[method-assign]
    m2 = np.vstack([np.zeros((1, n)), np.array(squares)])  # update k's estimate is for t[k + 1]
    level = np.zeros_like(m2)
    level[0] = m2[0]
    for k in range(1, len(m2)):
        level[k] = level[k - 1] + min(1.0, h / TWIN_LEVEL_TIME) * (m2[k] - level[k - 1])
    excess = np.maximum(0.0, m2 - 2.0 * level)
    history, times, reference = captured[-1]
    rows, at, e_ref, e_truth = window_errors(history, times, reference, t, truth, n, h)
    print(f'{scenario} {seed}: last window {times[0]:.0f}–{times[-1]:.0f} s, {len(rows)} '
          'estimates', flush=True)
    for i in range(n):
        rms_ref, rms_truth = (float(np.sqrt(np.mean(e[:, i] ** 2))) for e in (e_ref, e_truth))
        print(f'  DOF {i}: rms e vs reference {rms_ref:.4f}, vs truth {rms_truth:.4f}; slope on '
              f'm² vs reference {_fit(m2[at, i], e_ref[:, i] ** 2)}, vs truth '
              f'{_fit(m2[at, i], e_truth[:, i] ** 2)}; on the excess vs reference '
              f'{_fit(excess[at, i], e_ref[:, i] ** 2)}, vs truth '
              f'{_fit(excess[at, i], e_truth[:, i] ** 2)}', flush=True)


def main(argv: Sequence[str] | None = None) -> int:
    return run_cases(argv, (__doc__ or '').splitlines()[0], {*TUNING_SEEDS, *DEVELOPMENT_SEEDS},
                     'only tuning and development seeds', report)


if __name__ == '__main__':
    sys.exit(main())
