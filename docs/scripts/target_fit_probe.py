"""Where the learned filter's open-loop error comes from: targets, window, or the fit (issue 13).

    OMP_NUM_THREADS=1 python docs/scripts/target_fit_probe.py --scenarios supply_closed_loop \
        rao_supply --seeds 1 2

A diagnostic, tuning seeds only. Per (scenario, seed), on the fair recording (`suite`, 1800 s),
RMSE per DOF against the true LF pose from the benchmark's first scored sample, of:

- ``targets narrow`` / ``wide``: the predictor's own zero-phase target filter (`smooth_poses`
  with its notch and low-pass settings at the scenario's true ω0; the notch ``notch_zeta`` or, as
  the predictor uses in a broadband sea, ``notch_zeta_broadband``) run over the whole record: the
  targets' own error; the two rows below are given for each;
- ``lin truth``: the linear limit (`benchmark.linear_limit`, in-sample least squares of the
  predictor's regressors on the truth);
- ``lin targets``: the same causal linear filter fitted in-sample on those targets instead of the
  truth: what a perfect fit to whole-run targets gives;
- ``lin sliding``: the same filter refitted every Δ on the newest training window's targets
  (`smooth_poses` over that window alone, the newest ε samples left out as the predictor does)
  and applied causally over the next Δ: a linear ARX with the method's windows;
- ``lin sliding wide +h``: the same with the wide notch, fitted and scored one step ahead (the LF
  pose at k + 1 from the data up to k), as the predictor predicts;
- ``lin growing wide``: the same at t, refitted every Δ on all the data so far (targets of the
  whole past, filtered at once): what a memory of every past manoeuvre would give;
- ``adaptive``: the shipped predictor (one step ahead, as the benchmark scores it).

The gaps between the rows split the adaptive filter's error into the targets', the window's and
the fit's. Nothing is tuned here.
"""
from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
import sys
from typing import Any

import numpy as np
from numpy.typing import NDArray
import torch

from lf_predictor_ros.benchmark.baseline_tuning import TUNING_SEEDS, smoother_settings
from lf_predictor_ros.benchmark.estimators import predictor_params
from lf_predictor_ros.benchmark.linear_limit import (
    linear_limit,
    regressor_design,
    scaled_least_squares,
)
from lf_predictor_ros.benchmark.suite import make_recording, make_setup, scored_start
from lf_predictor_ros.core.baselines.smoother import smooth_poses
from lf_predictor_ros.core.heading import wrap_angle
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.predictor import AdaptivePredictor
from lf_predictor_ros.core.retraining import first_training_samples
from sim_ros.simulation import load_scenario

FloatArray = NDArray[np.float64]


Fit = Callable[[FloatArray, FloatArray], FloatArray]


def least_squares_fit(design: FloatArray, goal: FloatArray) -> FloatArray:
    """Coefficients c of goal ≈ design @ c, least squares on unit-std columns."""
    coef, scale = scaled_least_squares(design, goal)
    return np.asarray(coef / scale[:, None], dtype=np.float64)


def sliding(y: FloatArray, u: FloatArray, params: PredictorParams, omega: float,
            settings: dict[str, Any], ahead: int = 0, growing: bool = False,
            fit: Fit = least_squares_fit) -> FloatArray:
    """Causal estimate (n, ndof): a linear ARX refitted every Δ on the window's own targets.

    Row k estimates the LF pose at k + ``ahead`` from the data up to k. ``growing``: the window
    is all the data so far (a memory of every past manoeuvre) instead of the training window.
    ``fit(design, goal)`` gives each window's coefficients (least squares; `ridge_probe.py`
    passes penalized fits).
    """
    n, ndof, nu, ny = y.shape[0], params.ndof, params.nu, params.ny
    window, delta, eps = params.training_samples, params.retrain_samples, params.transient_samples
    if growing:
        window = n
    out = np.array(y[:, :ndof], dtype=np.float64)
    for k0 in range(first_training_samples(params), n, delta):
        first = max(0, k0 - window - eps)  # the window grows to its length, as the predictor's
        targets = smooth_poses(y[first:k0], params.sample_time, omega, ndof, **settings)
        rows = np.arange(first + max(nu, ny), k0 - eps - ahead)
        design, newest = regressor_design(y, u, rows, ndof, nu, ny)
        goal = targets[rows + ahead - first, :ndof] - newest
        if ndof == 3:  # targets come wrapped, the poses here are continuous
            goal[:, 2] = wrap_angle(goal[:, 2])
        coef = fit(design, goal)
        apply = np.arange(k0, min(k0 + delta, n))
        design, newest = regressor_design(y, u, apply, ndof, nu, ny)
        out[apply] = newest + design @ coef
    return out


def rmse(estimate: FloatArray, truth: FloatArray, ndof: int, start: int) -> list[float]:
    error = np.array(estimate[:, :ndof] - truth[:, :ndof], dtype=np.float64)
    if ndof == 3:
        error[:, 2] = wrap_angle(error[:, 2])
    return [float(v) for v in np.sqrt(np.mean(error[start:] ** 2, axis=0))]


def run(scenario_name: str, seed: int) -> None:
    scenario = load_scenario(scenario_name)
    params = predictor_params(scenario)
    setup = make_setup(scenario, seed, params)
    recording = make_recording(scenario, seed, 1800.0, setup)
    data = recording.data()
    t, y, u, truth = data['t'], data['y'], data['u'], data['truth']
    ndof, omega = params.ndof, setup.wave_peak_freq
    y_c, truth_c = np.array(y, dtype=np.float64), np.array(truth, dtype=np.float64)
    y_c[:, 2], truth_c[:, 2] = np.unwrap(y[:, 2]), np.unwrap(truth[:, 2])
    start = scored_start(params, len(t))
    narrow = smoother_settings({}, 'smoother_targets', params)
    rows: dict[str, list[float]] = {
        'lin truth': rmse(linear_limit(y, u, truth, ndof, params.nu, params.ny, start),
                          truth, ndof, start)}
    wide = dict(narrow, notch_zeta=params.notch_zeta_broadband)
    for label, settings in (('narrow', narrow), ('wide', wide)):
        targets = smooth_poses(y_c, params.sample_time, omega, ndof, **settings)
        rows[f'targets {label}'] = rmse(targets, truth_c, ndof, start)
        rows[f'lin targets {label}'] = rmse(
            linear_limit(y, u, _wrapped(targets, y), ndof, params.nu, params.ny, start), truth,
            ndof, start)
        rows[f'lin sliding {label}'] = rmse(sliding(y_c, u, params, omega, settings), truth_c,
                                            ndof, start)
    ahead = sliding(y_c, u, params, omega, wide, ahead=1)
    rows['lin sliding wide +h'] = rmse(ahead[:-1], truth_c[1:], ndof, start)
    rows['lin growing wide'] = rmse(sliding(y_c, u, params, omega, wide, growing=True), truth_c,
                                    ndof, start)
    predictor = AdaptivePredictor(params, background=False)
    estimate = np.array([predictor.update(t[k], y[k], u[k]) for k in range(len(t))])
    rows['adaptive'] = rmse(estimate[:-1], truth[1:], ndof, start)
    for name, values in rows.items():
        print(f'{scenario_name:20s} {seed} {name:19s} ' + ' '.join(f'{v:.4f}' for v in values),
              flush=True)


def _wrapped(targets: FloatArray, y: FloatArray) -> FloatArray:
    """Targets as a (n, 3) pose series with the heading wrapped (east/yaw of y for 1 DOF)."""
    out = np.array(y, dtype=np.float64)
    out[:, :targets.shape[1]] = targets
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def tuning_seed_cli(description: str | None, case: Callable[[str, int], None],
                    argv: Sequence[str] | None = None) -> int:
    """``--scenarios … --seeds …`` (tuning seeds only): ``case(scenario, seed)`` for each."""
    parser = argparse.ArgumentParser(description=description,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--scenarios', nargs='+', required=True)
    parser.add_argument('--seeds', nargs='+', type=int, default=list(TUNING_SEEDS))
    args = parser.parse_args(argv)
    if set(args.seeds) - set(TUNING_SEEDS):
        parser.error(f'a diagnostic on the tuning seeds {TUNING_SEEDS} only')
    torch.set_num_threads(1)
    for scenario_name in args.scenarios:
        for seed in args.seeds:
            case(scenario_name, seed)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    return tuning_seed_cli(__doc__, run, argv)


if __name__ == '__main__':
    sys.exit(main())
