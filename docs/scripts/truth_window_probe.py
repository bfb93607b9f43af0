"""Is it the targets or the window? A sliding linear ARX fitted on the *truth* (issue 13).

    OMP_NUM_THREADS=1 python docs/scripts/truth_window_probe.py --scenarios rao_supply \
        supply_closed_loop --seeds 1 2

A diagnostic (tuning and development seeds only). `target_fit_probe.py` split the learned
filter's open-loop error into the targets', the window's and the fit's; on the RAO vessels the
window was most of it (a causal linear ARX refitted every Δ on its window's zero-phase targets
had 4–7× the linear limit's error). This probe asks what is left if the labels are perfect: the
same causal ARX, refitted every Δ on the training window (N, the newest ε samples left out, as
the predictor does) with the **true LF pose** as its target, applied over the next Δ. If it is
near the linear limit (the same regressors fitted in-sample on the whole run's truth), better
targets would close the gap; if it is not, no target filter can, and the gap is what a linear
filter fitted on the past does with the next manoeuvre.

Rows per (scenario, seed), RMSE north / east [m] / yaw [rad] at t from the benchmark's first
scored sample (`suite.scored_start`), on the fair recording (`suite.make_recording`, 1800 s,
events not delayed):

- ``in-sample truth``: the linear limit (`benchmark.linear_limit`);
- ``sliding targets``: `target_fit_probe.sliding` with the broadband notch's targets (the
  method's linear analogue, for reference; like the linear limit, on the body-frame forces);
- ``<frame> <coupling> nu <n>``: the sliding ARX on the truth, in the earth frame or in the body
  frame of the newest heading (north/east position differences, forces and targets turned by
  −ψ(t), the estimate turned back; the forces are turned to the earth frame with each sample's
  heading first, as the predictor does), with every DOF's
  regressors in every output (``coupled``, the predictor's structure) or each output on its own
  DOF's positions and force channel only (``per-DOF``), with the predictor's n_u force lags or
  none. ``growing`` (with ``--growing``): the coupled earth-frame ARX on all the data so far.

Nothing is tuned here; no package code is changed.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
import sys

import numpy as np
from numpy.typing import NDArray
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from method_probe import DEVELOPMENT_SEEDS  # noqa: E402 - the sibling script
import target_fit_probe  # noqa: E402 - the sibling script

from lf_predictor_ros.benchmark.baseline_tuning import TUNING_SEEDS, smoother_settings  # noqa: E402
from lf_predictor_ros.benchmark.estimators import predictor_params  # noqa: E402
from lf_predictor_ros.benchmark.linear_limit import linear_limit  # noqa: E402
from lf_predictor_ros.benchmark.suite import (  # noqa: E402
    make_recording,
    make_setup,
    scored_start,
)
from lf_predictor_ros.core import regressors  # noqa: E402
from lf_predictor_ros.core.params import PredictorParams  # noqa: E402
from lf_predictor_ros.core.retraining import first_training_samples  # noqa: E402
from sim_ros.simulation import load_scenario  # noqa: E402

FloatArray = NDArray[np.float64]
IndexArray = NDArray[np.intp]


def into_body(values: FloatArray, heading: FloatArray) -> FloatArray:
    """(north, east) of every 3-channel block of each row turned by R(ψ)ᵀ, ψ per row."""
    return regressors.rotate_blocks(values, np.cos(heading), -np.sin(heading))


def designs(y: FloatArray, u: FloatArray, rows: IndexArray, nu: int, ny: int, body: bool,
            coupled: bool) -> tuple[list[FloatArray], FloatArray]:
    """One design per output DOF at ``rows`` and the newest poses (rows, 3).

    Columns: u[k], …, u[k − nu + 1], y[k − j] − y[k] for j = 1 … ny − 1 (turned into the body
    frame of ψ[k] with ``body``) and a constant; ``coupled``: every DOF's columns in every
    output, else only the output's own DOF.
    """
    newest = y[rows]
    differences = y[rows[:, None] - np.arange(1, ny)[None, :]] - newest[:, None, :]
    forces = u[rows[:, None] - np.arange(nu)[None, :], :3]  # earth frame: R(ψ(t − i)) τ(t − i)
    if body:  # as the predictor's body frame: R(ψ(t))ᵀ of every block
        differences = into_body(differences.reshape(rows.size, -1),
                                newest[:, 2]).reshape(differences.shape)
        forces = into_body(forces.reshape(rows.size, -1), newest[:, 2]).reshape(forces.shape)
    constant = np.ones((rows.size, 1))
    if coupled:
        shared = np.hstack([forces.reshape(rows.size, -1), differences.reshape(rows.size, -1),
                            constant])
        return [shared] * 3, newest
    return [np.hstack([forces[:, :, d], differences[:, :, d], constant]) for d in range(3)], \
        newest


def sliding_on_truth(y: FloatArray, u: FloatArray, truth: FloatArray, params: PredictorParams,
                     body: bool, coupled: bool, nu: int, growing: bool = False) -> FloatArray:
    """The causal estimate (n, 3): the ARX refitted every Δ on the window's truth."""
    n, ny = y.shape[0], params.ny
    window = n if growing else params.training_samples
    delta, eps = params.retrain_samples, params.transient_samples
    out = np.array(y[:, :3], dtype=np.float64)
    for k0 in range(first_training_samples(params), n, delta):
        rows = np.arange(max(0, k0 - window - eps) + max(nu, ny), k0 - eps)
        fit_designs, newest = designs(y, u, rows, nu, ny, body, coupled)
        goal = truth[rows] - newest
        if body:
            goal = into_body(goal, newest[:, 2])
        apply = np.arange(k0, min(k0 + delta, n))
        apply_designs, base = designs(y, u, apply, nu, ny, body, coupled)
        step = np.column_stack([
            apply_designs[d] @ target_fit_probe.least_squares_fit(fit_designs[d], goal[:, d:d + 1])
            for d in range(3)])
        if body:  # back to the earth frame: R(ψ)
            step = regressors.rotate_blocks(step, np.cos(base[:, 2]), np.sin(base[:, 2]))
        out[apply] = base + step
    return out


def run(scenario_name: str, seed: int, growing: bool) -> None:
    scenario = load_scenario(scenario_name)
    params = predictor_params(scenario)
    if params.ndof != 3:
        raise ValueError(f'{scenario_name} is a 1-DOF scenario: this probe compares 3-DOF '
                         'structures')
    setup = make_setup(scenario, seed, params)
    data = make_recording(scenario, seed, 1800.0, setup).data()
    y, u, truth = data['y'], data['u'], data['truth']
    y_c, truth_c = np.array(y, dtype=np.float64), np.array(truth, dtype=np.float64)
    y_c[:, 2], truth_c[:, 2] = np.unwrap(y[:, 2]), np.unwrap(truth[:, 2])
    # the forces turned to north/east with each sample's heading, u = R(ψ)τ, as the predictor
    # does for 3 DOF (`core.predictor`, Fossen 2011 §7.1)
    u_earth = regressors.rotate_blocks(u[:, :3], np.cos(y_c[:, 2]), np.sin(y_c[:, 2]))
    start = scored_start(params, y.shape[0])
    rows: dict[str, FloatArray] = {
        'in-sample truth': linear_limit(y, u, truth, 3, params.nu, params.ny, start)}
    wide = dict(smoother_settings({}, 'smoother_targets', params),
                notch_zeta=params.notch_zeta_broadband)
    rows['sliding targets'] = target_fit_probe.sliding(y_c, u, params, setup.wave_peak_freq,
                                                       wide)
    if growing:
        rows['growing earth coupled'] = sliding_on_truth(y_c, u_earth, truth_c, params, False,
                                                         True, params.nu, growing=True)
    for body in (False, True):
        for coupled in (True, False):
            for nu in (params.nu, 0):
                label = f'{"body" if body else "earth"} {"coupled" if coupled else "per-DOF"} ' \
                    f'nu {nu}'
                rows[label] = sliding_on_truth(y_c, u_earth, truth_c, params, body, coupled, nu)
    for label, estimate in rows.items():
        values = target_fit_probe.rmse(estimate, truth_c if label != 'in-sample truth' else truth,
                                       3, start)
        print(f'{scenario_name:20s} {seed} {label:22s} ' + ' '.join(f'{v:.4f}' for v in values),
              flush=True)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--scenarios', nargs='+', required=True)
    parser.add_argument('--seeds', nargs='+', type=int, default=list(TUNING_SEEDS))
    parser.add_argument('--growing', action='store_true', help='add the growing-window row')
    args = parser.parse_args(argv)
    allowed = set(TUNING_SEEDS) | set(DEVELOPMENT_SEEDS)
    if set(args.seeds) - allowed:
        parser.error(f'tuning and development seeds only, not {sorted(set(args.seeds) - allowed)}')
    torch.set_num_threads(1)
    for scenario_name in args.scenarios:
        for seed in args.seeds:
            run(scenario_name, seed, args.growing)
    return 0


if __name__ == '__main__':
    sys.exit(main())
