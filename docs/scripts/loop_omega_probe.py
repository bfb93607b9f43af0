"""The predictor's ω0 in its own DP loop against ω0 estimated on parts of the same loop's data.

    python docs/scripts/loop_omega_probe.py rao_swell 3

Runs the adaptive predictor (shipped defaults, inline training) in the scenario's DP loop
(`recordings.run_loop`, 1800 s) and logs the measured poses it was fed. Every 120 s from the
first training on it prints the ω0 in use and `retraining.estimate_frequency` (the γ-window
estimate of Algorithm 4.1) on: all samples so far (what the predictor does), the samples after
360 s or 480 s (the start-up, when the loop runs on the fallback, left out), and the newest
300 s. A '?' marks an estimate without a clear peak. Tuning and development seeds only (1–10).
Diagnostic for issue 13 (docs/BENCHMARKS.md, sixteenth session).
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
import sys

import numpy as np
import torch

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
    args = parser.parse_args(argv)
    if not 1 <= args.seed < FIRST_HELD_OUT_SEED:
        parser.error('tuning and development seeds only (1-10)')
    torch.set_num_threads(1)
    scenario = load_scenario(args.scenario)
    params = predictor_params(scenario)
    predictor = AdaptivePredictor(params, background=False)
    poses: list[FloatArray] = []
    in_use: list[float] = []

    def step(t: float, pose: FloatArray, force: FloatArray, true_omega: float) -> FloatArray:
        out = predictor.update(t, pose, force)
        poses.append(np.array(pose, dtype=np.float64))
        in_use.append(predictor.wave_peak_freq or 0.0)
        return out

    run_loop(scenario, args.seed, 1800.0, params.sample_time, step)
    y = np.array(poses)
    y[:, 2] = np.unwrap(y[:, 2])
    print(f'{args.scenario} seed {args.seed}: generator peak {scenario.waves.peak_freq(0.0):.3f} '
          f'rad/s, γ = {params.estimation_samples} samples')
    for k in range(360, y.shape[0] + 1, 120):
        cells = []
        for name, start in (('all', 0), ('after 360 s', 360), ('after 480 s', 480),
                            ('newest 300 s', k - 300)):
            if k - start < 180:
                cells.append(f'{name} –')
                continue
            est = estimate_frequency(params, y[start:k], None)
            cells.append(f'{name} {est.wave_peak_freq:.3f}{"" if est.confident else "?"}')
        print(f'{k:5d} s: in use {in_use[k - 1]:.3f} | ' + ' | '.join(cells), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
