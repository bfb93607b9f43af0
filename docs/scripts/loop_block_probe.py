"""The adaptive predictor in its own DP loop, block by block: where a loop loses its position.

    python docs/scripts/loop_block_probe.py rao_supply 177 default 1080 1300
    python docs/scripts/loop_block_probe.py rao_supply 102 motion_gate_yaw:true 1100 1320 \
        --block 10

One loop per call, set up by `own_loop_band_probe.loop_case` (the seed's scenario with its
scheduled events delayed as `method_probe.py` delays them, the shipped predictor with the
override, the PID on its estimate every h). Printed per block of ``--block`` seconds between
the two times: the RMS error of the estimate the PID acted on (north, east [m], heading [rad])
against the true LF pose (`suite._timed_loop_estimate_error`), the largest horizontal distance
of the true LF pose from the ideal loop's track [m], the share of the estimates the cascade
served (the network's prediction was missing or tripped the distance guard), the predictor's
ω0 [rad/s], the true heading [rad] and the motion gate's mean gain g per DOF (north, east,
heading; 0: the holding network, 1: the twin; `AdaptivePredictor.motion_gain`, all 0 with the
gate off). A baseline's name as the variant (``observer``, ``oracle_kf``, …) runs that
estimator's loop instead (cascade share 0, ω0 nan). ``--bias`` adds the mean error per DOF,
``--rate`` the RMS rate of the error between consecutive estimates (what the PID's D term sees
of it), ``--force`` the mean applied thrust (earth-frame north/east, yaw moment). The
twenty-sixth session used it to find that the failing first turns of rao_supply lag in
heading, the twenty-seventh to look at the yaw gate in a move, the forty-fourth to follow the
turn excursions second by second (docs/BENCHMARKS.md).
"""
from __future__ import annotations

import argparse
from pathlib import Path
import sys

import numpy as np
import torch

from lf_predictor_ros.benchmark import stability
from lf_predictor_ros.benchmark.estimators import make_estimator
from lf_predictor_ros.benchmark.recordings import run_loop
from lf_predictor_ros.benchmark.suite import (
    _loop_reference,
    _run_loop,
    _timed_loop_estimate_error,
)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from own_loop_band_probe import DURATION, loop_case  # noqa: E402 - the sibling script


def main(argv: list[str]) -> None:
    """Run one loop and print its blocks (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('scenario')
    parser.add_argument('seed', type=int)
    parser.add_argument('variant', help="'default' or field:value[;field:value]")
    parser.add_argument('start', type=float, help='first block start [s]')
    parser.add_argument('end', type=float, help='last block end [s]')
    parser.add_argument('--block', type=float, default=20.0, help='block length [s]')
    parser.add_argument('--rate', action='store_true',
                        help='also print the RMS rate of the error per DOF per block '
                             '(its finite difference between consecutive estimates [m/s, rad/s]: '
                             "what the PID's D term sees of it)")
    parser.add_argument('--force', action='store_true',
                        help='also print the mean applied thrust per block: earth-frame north, '
                             'east [kN] (the body force turned by the measured heading) and '
                             'the yaw moment [MN·m]')
    parser.add_argument('--bias', action='store_true',
                        help='also print the mean error per DOF (estimate − truth) per block')
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    case = loop_case(args.scenario, args.seed, args.variant)
    stream = make_estimator(case.estimator, case.setup)
    # (t, the network served, ω0, the motion gate's g per DOF) per call
    log: list[tuple[float, bool, float, np.ndarray]] = []
    forces: list[np.ndarray] = []  # per call: earth-frame north, east [N], yaw moment [N·m]

    def step(t: float, pose: np.ndarray, force: np.ndarray, wave_peak_freq: float) -> np.ndarray:
        out = stream.step(t, pose, force, wave_peak_freq)
        c, s = np.cos(pose[2]), np.sin(pose[2])
        forces.append(np.array([c * force[0] - s * force[1], s * force[0] + c * force[1],
                                force[2]]))
        gain = getattr(stream.estimator, 'motion_gain', np.zeros(3))  # the adaptive predictor's
        if case.estimator == 'adaptive':
            status = stream.estimator.status()
            log.append((t, status.state == 'trained', status.wave_peak_freq or np.nan, gain))
        else:  # a baseline (its variant's name): no cascade share, no ω0 of its own
            log.append((t, True, np.nan, gain))
        return out

    run = run_loop(case.scenario, args.seed, DURATION, case.setup.sample_time, step)
    outcome = _run_loop(case.estimator, case.scenario, args.seed, DURATION, case.setup, case.ideal,
                        recorded=run)
    record = outcome.record
    offset = stability.pose_offset(record.truth_lf_pose,
                                   _loop_reference(case.scenario, record, case.ideal), 3)
    times, error = _timed_loop_estimate_error(outcome, 3, args.start)
    rate = np.diff(error, axis=0) / np.diff(times)[:, None]  # row k: from estimate k to k + 1
    calls = np.array([row[0] for row in log])
    network = np.array([row[1] for row in log])
    freq = np.array([row[2] for row in log], dtype=np.float64)
    gain = np.array([row[3] for row in log], dtype=np.float64)
    print(f'{args.scenario} seed {args.seed}, events delayed {case.shift:.1f} s; '
          f'variant {args.variant}')
    print(' block [s]  error N [m]  E [m]  heading [rad]  |offset| max [m]  cascade  ω0  ψ true'
          '  gate g N / E / ψ')
    for start in np.arange(args.start, args.end, args.block):
        rows = (times >= start) & (times < start + args.block)
        steps = (calls >= start) & (calls < start + args.block)
        samples = (record.t >= start) & (record.t < start + args.block)
        if not rows.any():
            continue
        rms = np.sqrt(np.mean(error[rows] ** 2, axis=0))
        omega = (float(np.nanmean(freq[steps])) if np.isfinite(freq[steps]).any()
                 else np.nan)  # a baseline's loop has no ω0 of its own
        worst = float(np.max(np.hypot(offset[samples, 0], offset[samples, 1])))
        print(f'{start:9.0f} {rms[0]:12.3f} {rms[1]:6.3f} {rms[2]:14.4f} {worst:17.2f} '
              f'{1.0 - network[steps].mean():8.2f} {omega:6.3f} '
              f'{record.truth_lf_pose[samples, 2].mean():6.3f}  '
              + ' / '.join(f'{g:.2f}' for g in gain[steps].mean(axis=0))
              + ('  mean ' + ' / '.join(f'{m:+.3f}' for m in error[rows].mean(axis=0))
                 if args.bias else '')
              + ('  force {:.0f} / {:.0f} kN / {:.2f} MNm'.format(
                  *(np.mean(np.asarray(forces)[steps], axis=0) / [1e3, 1e3, 1e6]))
                 if args.force else '')
              + ('  rate ' + ' / '.join(f'{r:.3f}' for r in np.sqrt(np.mean(
                  rate[rows[1:]] ** 2, axis=0))) if args.rate else ''))


def probe_main(argv: list[str]) -> int:
    """A patching probe's entry: ``--blocks`` first runs `main`, else `method_probe.main`.

    The probes that patch the predictor in their own process (`guard_per_dof_probe.py`,
    `turn_thrust_hold_probe.py`, ...) call this after patching.
    """
    if argv[:1] == ['--blocks']:
        main(argv[1:])
        return 0
    import method_probe  # the sibling script (imported here: the block probe alone needs none)
    return int(method_probe.main(argv))


if __name__ == '__main__':
    main(sys.argv[1:])
