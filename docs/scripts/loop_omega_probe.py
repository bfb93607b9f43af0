"""The predictor's ω0 in its own DP loop against ω0 estimated on parts of the same loop's data.

    python docs/scripts/loop_omega_probe.py rao_swell 3 [--open-loop]

Runs the adaptive predictor (shipped defaults, inline training) in the scenario's DP loop
(`recordings.run_loop`, 1800 s) and logs the measured poses it was fed. Every 120 s from the
first training on it prints the ω0 in use and `retraining.estimate_frequency` (the γ-window
estimate of Algorithm 4.1) on: all samples so far (what the predictor does), the samples after
360 s or 480 s (the start-up, when the loop runs on the fallback, left out), and the newest
300 s; then on all samples of y − ŷ (ŷ the predictor's estimate for that sample, made one
step before) and of y − LP(ŷ) (ŷ through a 2nd-order Butterworth low-pass at 0.15 rad/s, below
the wave band): the LF motion removed instead of the start-up. A '?' marks an estimate without a
clear peak. ``--open-loop``: the same predictor over the fair recording instead (the DP loop
closed on the tuned observer, `suite.make_recording`), no loop of its own. Tuning and
development seeds only (1–10). Diagnostic for issue 13 (docs/BENCHMARKS.md, sixteenth session).
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
import sys

import numpy as np
from scipy import signal
import torch

from lf_predictor_ros.benchmark import suite
from lf_predictor_ros.benchmark.benchmark import FIRST_HELD_OUT_SEED
from lf_predictor_ros.benchmark.estimators import predictor_params
from lf_predictor_ros.benchmark.recordings import run_loop
from lf_predictor_ros.core.predictor import AdaptivePredictor
from lf_predictor_ros.core.retraining import estimate_frequency
from sim_ros.simulation import load_scenario

FloatArray = np.ndarray


def main(argv: Sequence[str] | None = None) -> int:
    """CLI (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('scenario')
    parser.add_argument('seed', type=int)
    parser.add_argument('--open-loop', action='store_true',
                        help='over the fair recording (loop on the tuned observer)')
    args = parser.parse_args(argv)
    if not 1 <= args.seed < FIRST_HELD_OUT_SEED:
        parser.error('tuning and development seeds only (1-10)')
    torch.set_num_threads(1)
    scenario = load_scenario(args.scenario)
    params = predictor_params(scenario)
    predictor = AdaptivePredictor(params, background=False)
    poses: list[FloatArray] = []
    outputs: list[FloatArray] = []
    in_use: list[float] = []

    def step(t: float, pose: FloatArray, force: FloatArray, true_omega: float) -> FloatArray:
        out = predictor.update(t, pose, force)
        poses.append(np.array(pose, dtype=np.float64))
        outputs.append(np.array(out, dtype=np.float64))
        in_use.append(predictor.wave_peak_freq or 0.0)
        return out

    if args.open_loop:
        recording = suite.make_recording(scenario, args.seed, 1800.0,
                                         suite.make_setup(scenario, args.seed, params))
        for k in range(recording.t.shape[0]):
            step(float(recording.t[k]), recording.y[k], recording.u[k], 0.0)
    else:
        run_loop(scenario, args.seed, 1800.0, params.sample_time, step)
    y = np.array(poses)
    y[:, 2] = np.unwrap(y[:, 2])
    estimates = np.array(outputs)
    estimates[:, 2] = np.unwrap(estimates[:, 2])
    y_hat = np.vstack([y[:1], estimates[:-1]])  # the estimate for sample k was made at k − 1
    lowpass = signal.butter(2, 0.15, fs=2.0 * np.pi / params.sample_time, output='sos')
    y_hat_lf = signal.sosfilt(lowpass, y_hat - y_hat[0], axis=0) + y_hat[0]
    series = {'y': y, 'y − ŷ': y - y_hat, 'y − LP(ŷ)': y - y_hat_lf}
    print(f'{args.scenario} seed {args.seed}: generator peak {scenario.waves.peak_freq(0.0):.3f} '
          f'rad/s, γ = {params.estimation_samples} samples')
    for k in range(360, y.shape[0] + 1, 120):
        cells = []
        for name, data, start in (('all', 'y', 0), ('after 360 s', 'y', 360),
                                  ('after 480 s', 'y', 480), ('newest 300 s', 'y', k - 300),
                                  ('y − ŷ', 'y − ŷ', 0), ('y − LP(ŷ)', 'y − LP(ŷ)', 0)):
            if k - start < 180:
                cells.append(f'{name} –')
                continue
            est = estimate_frequency(params, series[data][start:k], None)
            cells.append(f'{name} {est.wave_peak_freq:.3f}{"" if est.confident else "?"}')
        print(f'{k:5d} s: in use {in_use[k - 1]:.3f} | ' + ' | '.join(cells), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
