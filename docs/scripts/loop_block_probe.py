"""The adaptive predictor in its own DP loop, block by block: where a loop loses its position.

    python docs/scripts/loop_block_probe.py rao_supply 177 default 1080 1300
    python docs/scripts/loop_block_probe.py rao_supply 102 motion_gate_yaw:true 1100 1320 \
        --block 10

One loop per call, as `own_loop_band_probe.py` runs it (the seed's scenario with its scheduled
events delayed as `method_probe.py` delays them, the shipped predictor with the override, the
PID on its estimate every h). Printed per block of ``--block`` seconds between the two times:
the RMS error of the estimate the PID acted on (north, east [m], heading [rad]) against the true
LF pose, the largest horizontal distance of the true LF pose from the ideal loop's track [m],
the share of the estimates the cascade served (the network's prediction was missing or tripped
the distance guard), the predictor's ω0 [rad/s] and the true heading [rad]. The twenty-sixth
session used it to find that the failing first turns of rao_supply lag in heading
(docs/BENCHMARKS.md).
"""
from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path
import sys

import numpy as np
import torch

from lf_predictor_ros.benchmark import stability
from lf_predictor_ros.benchmark.benchmark import SCHEDULE_SPREAD
from lf_predictor_ros.benchmark.estimators import make_estimator, predictor_params
from lf_predictor_ros.benchmark.recordings import run_loop
from lf_predictor_ros.benchmark.suite import (
    _loop_reference,
    make_recording,
    make_setup,
    schedule_shift_for_seed,
)
from lf_predictor_ros.core.heading import wrap_angle
from sim_ros.simulation import load_scenario, scenario_with_schedule_shift, simulate

sys.path.insert(0, str(Path(__file__).resolve().parent))
from method_probe import parse_variant  # noqa: E402 - the sibling script

DURATION = 1800.0  # [s] as method_probe


def main(argv: list[str]) -> None:
    """Run one loop and print its blocks (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('scenario')
    parser.add_argument('seed', type=int)
    parser.add_argument('variant', help="'default' or field:value[;field:value]")
    parser.add_argument('start', type=float, help='first block start [s]')
    parser.add_argument('end', type=float, help='last block end [s]')
    parser.add_argument('--block', type=float, default=20.0, help='block length [s]')
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    shift = schedule_shift_for_seed(args.seed, SCHEDULE_SPREAD)
    scenario = scenario_with_schedule_shift(load_scenario(args.scenario), shift)
    overrides = None if args.variant == 'default' else parse_variant(f'v={args.variant}')[1]
    setup = make_setup(scenario, args.seed, predictor_params(scenario, None))
    make_recording(scenario, args.seed, DURATION, setup)  # as method_probe: the fair recording
    setup = replace(setup, params=predictor_params(scenario, overrides))
    ideal = simulate(scenario, seed=args.seed, duration=DURATION, controller=True,
                     feedback='truth_lf')
    stream = make_estimator('adaptive', setup)
    log: list[tuple[float, bool, float, np.ndarray]] = []

    def step(t: float, pose: np.ndarray, force: np.ndarray, wave_peak_freq: float) -> np.ndarray:
        out = stream.step(t, pose, force, wave_peak_freq)
        status = stream.estimator.status()
        log.append((t, status.state == 'trained', status.wave_peak_freq, out[:3].copy()))
        return out

    record = run_loop(scenario, args.seed, DURATION, setup.sample_time, step).record
    offset = stability.pose_offset(record.truth_lf_pose, _loop_reference(scenario, record, ideal),
                                   3)
    times = np.array([row[0] for row in log])
    network = np.array([row[1] for row in log])
    freq = np.array([row[2] for row in log], dtype=np.float64)
    estimate = np.array([row[3] for row in log])
    # the truth at the sample each estimate was returned at (as suite._loop_estimate_error)
    index = np.clip(np.searchsorted(record.t, times - 1e-9), 0, len(record.t) - 1)
    truth = record.truth_lf_pose[index]
    error = estimate - truth
    error[:, 2] = wrap_angle(error[:, 2])
    print(f'{args.scenario} seed {args.seed}, events delayed {shift:.1f} s; '
          f'variant {args.variant}')
    print(' block [s]  error N [m]  E [m]  heading [rad]  |offset| max [m]  cascade  ω0  ψ true')
    for start in np.arange(args.start, args.end, args.block):
        rows = (times >= start) & (times < start + args.block)
        samples = (record.t >= start) & (record.t < start + args.block)
        if not rows.any():
            continue
        rms = np.sqrt(np.mean(error[rows] ** 2, axis=0))
        worst = float(np.max(np.hypot(offset[samples, 0], offset[samples, 1])))
        print(f'{start:9.0f} {rms[0]:12.3f} {rms[1]:6.3f} {rms[2]:14.4f} {worst:17.2f} '
              f'{1.0 - network[rows].mean():8.2f} {np.nanmean(freq[rows]):6.3f} '
              f'{truth[rows, 2].mean():6.3f}')


if __name__ == '__main__':
    main(sys.argv[1:])
