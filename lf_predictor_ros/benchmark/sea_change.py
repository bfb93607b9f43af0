"""What the adaptive predictor does around a change of sea state (docs/BENCHMARKS.md, round 3).

    python -m lf_predictor_ros.benchmark.sea_change "{'wave_augmentation': 1.0}" --seed 1

Runs the predictor (inline training, deterministic) over a scenario with an ω0 schedule
(default ``omega_steps``, thesis Fig. 4.1 as steps) and prints, per Δ window, the RMSE of the LF
estimate vs the true LF pose (north) and the ω0 in use; at the ``--gain-times`` it prints the gain
|ŷLF| / |y| of the network in service for a pure sinusoidal y at each of ``--omegas`` (no force):
the learned filter's frequency response. ``--no-restart`` keeps the old training window across a
detected sea change (the behaviour before round 2), for comparison only.
"""
from __future__ import annotations

import argparse
import ast
from collections.abc import Sequence
import math
import sys

import numpy as np
from numpy.typing import NDArray

from lf_predictor_ros.benchmark.estimators import predictor_params
from lf_predictor_ros.benchmark.recordings import decimate, grid_stride
from lf_predictor_ros.core import retraining
from lf_predictor_ros.core.network import NumpyNnarmax
from lf_predictor_ros.core.predictor import AdaptivePredictor
from lf_predictor_ros.core.regressors import build_regressors
from sim_ros.simulation import load_scenario, simulate

FloatArray = NDArray[np.float64]
SINE_AMPLITUDE = 0.3  # [m] of the probe sinusoid (small: the tanh part stays near linear)


def sine_gain(model: NumpyNnarmax, omega: float, samples: int = 600) -> float:
    """|ŷLF| / |y| of ``model`` for y = 0.3 m · sin(ω k h), h = 1 sample, forces zero."""
    t = np.arange(samples, dtype=np.float64)
    y = np.zeros((samples, model.spec.n_outputs))
    y[:, 0] = SINE_AMPLITUDE * np.sin(omega * t)
    x, first = build_regressors(np.zeros((samples, model.spec.n_inputs_u)), y, y, model.spec)
    out = model.forward(x)[:, 0]
    tt = t[first:] + 1.0  # row k predicts sample k + 1
    half = slice(len(tt) // 2, None)  # after the regressors have filled
    design = np.column_stack([np.sin(omega * tt[half]), np.cos(omega * tt[half])])
    coef, *_ = np.linalg.lstsq(design, out[half], rcond=None)
    return float(math.hypot(coef[0], coef[1]) / SINE_AMPLITUDE)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: one line per Δ, gains at the requested times."""
    parser = argparse.ArgumentParser(prog='sea_change', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('overrides', nargs='?', default='{}', help='PredictorParams dict literal')
    parser.add_argument('--scenario', default='omega_steps')
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--duration', type=float, default=None, help='simulated s')
    parser.add_argument('--gain-times', type=float, nargs='*', default=[3590.0, 7190.0],
                        metavar='T', help='[s] when to print the network gains')
    parser.add_argument('--omegas', type=float, nargs='*', default=[0.1, 0.3, 0.8, 1.25, 2.0],
                        metavar='W', help='[rad/s] probe frequencies')
    parser.add_argument('--no-restart', action='store_true',
                        help='do not restart the training window at a sea change')
    args = parser.parse_args(argv)
    overrides = ast.literal_eval(args.overrides)
    if not isinstance(overrides, dict):
        parser.error(f'{args.overrides!r} is not a dict literal')
    original = retraining.sea_state_changed
    if args.no_restart:  # for this run only: the module is restored below
        retraining.sea_state_changed = lambda *_: False
    try:
        _report(args, overrides)
    finally:
        retraining.sea_state_changed = original
    return 0


def _report(args: argparse.Namespace, overrides: dict[str, object]) -> None:
    """Run the predictor over the scenario and print the gains and the per-Δ table."""
    scenario = load_scenario(args.scenario)
    params = predictor_params(scenario, overrides)
    record = simulate(scenario, seed=args.seed, duration=args.duration)
    data = decimate(record, grid_stride(scenario, params.sample_time))
    predictor = AdaptivePredictor(params, background=False)
    t = data['t']
    estimate = np.empty((len(t), 3))
    omega_used = np.full(len(t), math.nan)
    pending = sorted(args.gain_times)
    for k in range(len(t)):
        estimate[k] = predictor.update(float(t[k]), data['y'][k], data['u'][k])
        omega_used[k] = predictor.wave_peak_freq or math.nan
        while pending and t[k] >= pending[0]:
            model = predictor.model
            gains = ['—' if model is None else f'{sine_gain(model, w):.3f}' for w in args.omegas]
            print(f'gain at t = {pending.pop(0):g} s, ω = {args.omegas} rad/s: {gains}')
    error = np.vstack([estimate[:1], estimate[:-1]])[:, 0] - data['truth'][:, 0]
    window = params.retrain_period
    print(f'{"t [s]":>8} {"RMSE [m]":>9} {"ω0 used":>8} {"ω0 true":>8}')
    for start in np.arange(0.0, t[-1], window):
        keep = (t >= start) & (t < start + window)
        if keep.any():
            print(f'{start:8.0f} {math.sqrt(float(np.mean(error[keep] ** 2))):9.3f} '
                  f'{omega_used[keep][-1]:8.3f} {data["omega"][keep][-1]:8.3f}')
    print(f'counters: {predictor.counters}')
    predictor.close()


if __name__ == '__main__':
    sys.exit(main())
