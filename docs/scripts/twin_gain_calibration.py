"""The motion gate twin term's slope against the truth over its slope against the reference.

    OMP_NUM_THREADS=1 python docs/scripts/twin_gain_calibration.py rao_supply:1 rao_supply:231 \
        supply_closed_loop:1 threedof_open_loop:1 onedof_feedback:1

Tuning and lf_odom calibration seeds only (1, 2, 231–236; issue 14, thirty-third session, sixth
rule). Per SCENARIO:SEED, on the fair recording (`method_probe.fair_case`, 1500 s, the
benchmark's schedule spread), `LfStateEstimator` with the shipped defaults runs inline with
`lf_state.calibrate` wrapped to keep each calibration window's published history (with the
untaken twin offset's excess the odometry published, `Published.twin_excess`) and reference.
For every window and DOF with at least 60 estimates whose excess is > 0 and a positive slope
against the reference (where `pose_twin_fit` gives C > 0), the least-squares slope of e² on
the excess is computed against the reference and against the true LF pose; one line per such
(window, DOF), then the median of truth / reference over all of them, per scenario and pooled.
Windows overlap (each calibration's window slides by Δ), so a long-lived window counts often.
"""
from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
import sys
from typing import Any

import numpy as np
from numpy.typing import NDArray
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from method_probe import case_arguments, fair_case  # noqa: E402 - the sibling script

from lf_predictor_ros.benchmark.baseline_tuning import TUNING_SEEDS  # noqa: E402
from lf_predictor_ros.benchmark.benchmark import SCHEDULE_SPREAD  # noqa: E402
from lf_predictor_ros.benchmark.estimators import predictor_params  # noqa: E402
from lf_predictor_ros.core import lf_state  # noqa: E402
from lf_predictor_ros.core.heading import wrap_angle  # noqa: E402
from lf_predictor_ros.core.odometry_params import OdometryParams  # noqa: E402
from lf_predictor_ros.core.published_columns import Published  # noqa: E402

FloatArray = NDArray[np.float64]
DURATION = 1500.0  # [s] as the odometry benchmark's development runs
CALIBRATION_SEEDS = (*TUNING_SEEDS, *range(231, 237))
MIN_EXCESS_SAMPLES = 60  # as OdometryParams.min_calibration_samples
Window = tuple[list[Published], FloatArray, FloatArray]  # history, target times, reference


def _slope(x: FloatArray, y: FloatArray) -> float:
    dx = x - x.mean()
    return float(np.sum(dx * (y - y.mean())) / np.sum(dx * dx))


def windows(scenario_name: str, seed: int) -> tuple[int, float, FloatArray, FloatArray,
                                                    list[Window]]:
    """(ndof, h, times, truth, every calibration window) of one run."""
    captured: list[Window] = []
    name = 'calibrate'  # lf_state's own import of error_models.calibrate, wrapped for this run
    original = getattr(lf_state, name)

    def keep(history: Sequence[Published], times: Any, targets: Any, *args: Any,
             **kwargs: Any) -> Any:
        captured.append((list(history), np.array(times), np.array(targets)))
        return original(history, times, targets, *args, **kwargs)

    scenario, _, _, recording = fair_case(scenario_name, seed, DURATION, SCHEDULE_SPREAD)
    data = recording.data()
    params = predictor_params(scenario, {})
    setattr(lf_state, name, keep)
    estimator = lf_state.LfStateEstimator(params, OdometryParams(), background=False)
    try:
        for k in range(len(data['t']) - 1):
            estimator.update(float(data['t'][k]), data['y'][k], data['u'][k])
    finally:
        estimator.close()
        setattr(lf_state, name, original)
    return params.ndof, params.sample_time, data['t'], data['truth'], captured


def window_errors(rows: Sequence[Published], times: FloatArray, reference: FloatArray,
                  t: FloatArray, truth: FloatArray, n: int, h: float
                  ) -> tuple[list[Published], FloatArray, FloatArray, FloatArray]:
    """(estimates, run indices, errors vs reference, errors vs truth) of one window.

    The published estimates at inner target instants, as `calibrate` matches them; the heading
    error wrapped.
    """
    stamps = np.array([p.stamp for p in rows])
    index = np.round((stamps - times[0]) / h).astype(np.int64)
    ok = (index >= 1) & (index < len(times) - 1)
    kept = [p for p, good in zip(rows, ok, strict=True) if good]
    pose = np.array([p.pose for p in kept]).reshape(-1, n)
    at = np.round((stamps[ok] - t[0]) / h).astype(np.int64)
    e_ref, e_truth = pose - reference[index[ok]], pose - truth[at][:, :n]
    if n == 3:
        e_ref[:, 2], e_truth[:, 2] = wrap_angle(e_ref[:, 2]), wrap_angle(e_truth[:, 2])
    return kept, at, e_ref, e_truth


def ratios(scenario_name: str, seed: int) -> list[tuple[float, int, float, float]]:
    """(window end, DOF, reference slope, truth slope) of every qualifying (window, DOF)."""
    n, h, t, truth, captured = windows(scenario_name, seed)
    out = []
    for history, times, reference in captured:
        rows, _, e_ref, e_truth = window_errors(
            [p for p in history if p.twin_excess is not None], times, reference, t, truth, n, h)
        if not rows:
            continue
        excess = np.array([p.twin_excess for p in rows])
        for i in range(n):
            if np.count_nonzero(excess[:, i] > 0.0) < MIN_EXCESS_SAMPLES:
                continue
            ref = _slope(excess[:, i], e_ref[:, i] ** 2)
            if ref > 0.0:
                out.append((float(times[-1]), i, ref, _slope(excess[:, i], e_truth[:, i] ** 2)))
    return out


def main(argv: Sequence[str] | None = None) -> int:
    cases = case_arguments(argv, (__doc__ or '').splitlines()[0], CALIBRATION_SEEDS,
                           f'calibration seeds: {CALIBRATION_SEEDS}')
    torch.set_num_threads(1)
    per_scenario: dict[str, list[float]] = defaultdict(list)
    for scenario, seed in cases:
        for end, dof, ref, truth in ratios(scenario, seed):
            print(f'{scenario} {seed} window_end {end:.0f} dof {dof} ref {ref:.3f} truth '
                  f'{truth:.3f} ratio {truth / ref:.3f}', flush=True)
            per_scenario[scenario].append(truth / ref)
    pooled = [r for values in per_scenario.values() for r in values]
    for scenario, values in per_scenario.items():
        print(f'{scenario}: {len(values)} (window, DOF), median ratio {np.median(values):.3f}')
    if pooled:
        print(f'pooled: {len(pooled)} (window, DOF), median ratio {np.median(pooled):.3f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
