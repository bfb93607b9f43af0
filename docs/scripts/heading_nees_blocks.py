"""Exploratory: where lf_odom's heading covariance is too small, block by block (issue 14).

    OMP_NUM_THREADS=1 python docs/scripts/heading_nees_blocks.py rao_supply 755 [--block 60] \
        [--param FIELD=VALUE ...]

The fair recording of `odometry_bench` (`suite.make_recording`), replayed open loop into
`LfStateEstimator` as `odometry_bench`'s tracking item does; per block of ``--block`` s from the
scored start: the heading error RMS against the true LF heading [rad], the published heading std
RMS [rad], the mean heading NEES e²/σ², the largest single-sample e²/σ², the true yaw rate RMS
[rad/s], the predictor's heading gate gain (mean), the fraction of samples from the network
(else the cascade fallback) and the guard trips in the block. ``--steps N`` also lists the N
largest one-sample steps of the published heading (the benchmark's output-step target compares
them with the largest true LF step) with the heading gate gain before and after each. Why
(docs/BENCHMARKS.md, forty-fifth session): with the heading gated by the yaw moment the held-out
heading NEES of rao_supply rose 1.36 → 2.13 while its heading error fell to 0.28×, and its
largest heading output step rose 2.5 → 3.36× the largest true LF step. Development seeds only
(`method_probe.DEVELOPMENT_SEEDS`; the recording is `method_probe.fair_case`'s, events
undelayed as in `odometry_bench`).
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
import math
from pathlib import Path
import sys

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import method_probe  # noqa: E402 - the sibling script

from lf_predictor_ros.benchmark.estimators import param_overrides, predictor_params  # noqa: E402
from lf_predictor_ros.benchmark.suite import scored_start  # noqa: E402
from lf_predictor_ros.core.heading import unwrap_heading, wrap_angle  # noqa: E402
from lf_predictor_ros.core.lf_state import LfStateEstimator  # noqa: E402
from lf_predictor_ros.core.odometry_params import OdometryParams  # noqa: E402


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('scenario')
    parser.add_argument('seed', type=int)
    parser.add_argument('--block', type=float, default=60.0, help='block length [s]')
    parser.add_argument('--duration', type=float, default=1500.0, help='simulated s')
    parser.add_argument('--from', dest='first', type=float, default=0.0,
                        help='first block start [s] (default: the scored start)')
    parser.add_argument('--to', dest='last', type=float, default=math.inf,
                        help='last block end [s]')
    parser.add_argument('--param', action='append', default=[], metavar='FIELD=VALUE')
    parser.add_argument('--steps', type=int, default=0,
                        help='also list this many largest one-sample heading output steps')
    args = parser.parse_args(argv)
    if args.seed not in method_probe.DEVELOPMENT_SEEDS:
        parser.error(f'seed {args.seed} is not a development seed (method_probe.py)')
    scenario, _, _, recording = method_probe.fair_case(args.scenario, args.seed, args.duration)
    params = predictor_params(scenario, param_overrides(args.param) if args.param else None)
    data = recording.data()
    begin = scored_start(params, len(data['t']))
    estimator = LfStateEstimator(params, OdometryParams(), background=False)
    # (t, error, std, gain, on network, guard trips so far) per sample from the scored start,
    # the estimate of update k being for t[k + 1]
    rows = []
    headings = []  # (t + h, published heading, heading gate gain) of every sample
    try:
        for k in range(len(data['t']) - 1):
            lf_pose, odom = estimator.update(float(data['t'][k]), data['y'][k], data['u'][k])
            predictor = estimator.predictor
            gain = predictor.motion_gain
            headings.append((float(data['t'][k + 1]), float(lf_pose[2]),
                             float(gain[2]) if len(gain) == 3 else math.nan))
            if k + 1 < begin or odom is None:
                continue
            error = wrap_angle(float(odom.pose[2] - data['truth'][k + 1][2]))
            rows.append((float(data['t'][k + 1]), error, math.sqrt(float(odom.pose_cov[2, 2])),
                         float(gain[2]) if len(gain) == 3 else math.nan,
                         float(predictor.using_network), float(predictor.counters['guard_trips'])))
    finally:
        estimator.close()
    table = np.array(rows)
    truth_yaw = unwrap_heading(data['truth'][:, 2])
    rate = np.gradient(truth_yaw, data['t'])
    print(f'{args.scenario} seed {args.seed}, {args.param or "default"}; heading NEES over the '
          f'run {np.mean((table[:, 1] / table[:, 2]) ** 2):.2f}')
    print(' block [s]  error RMS  std RMS  NEES mean  NEES max  true rate RMS  gate g_psi  '
          'network  trips')
    start = max(table[0, 0], args.first)
    while start < min(table[-1, 0], args.last):
        inside = (table[:, 0] >= start) & (table[:, 0] < start + args.block)
        block = table[inside]
        rates = rate[(data['t'] >= start) & (data['t'] < start + args.block)]
        nees = (block[:, 1] / block[:, 2]) ** 2
        print(f'{start:9.0f}  {math.sqrt(np.mean(block[:, 1] ** 2)):9.5f}  '
              f'{math.sqrt(np.mean(block[:, 2] ** 2)):7.5f}  {np.mean(nees):9.2f}  '
              f'{np.max(nees):8.1f}  {math.sqrt(np.mean(rates ** 2)):13.5f}  '
              f'{np.mean(block[:, 3]):10.2f}  {np.mean(block[:, 4]):7.2f}  '
              f'{block[-1, 5] - block[0, 5]:5.0f}')
        start += args.block
    if args.steps:
        _print_steps(np.array(headings), data['t'], data['truth'][:, 2], begin, args.steps)
    return 0


def _print_steps(headings: np.ndarray, t: np.ndarray, truth_yaw: np.ndarray, begin: int,
                 count: int) -> None:
    """The ``count`` largest one-sample steps of the published heading from the scored start."""
    scored = headings[max(begin - 1, 0):]
    steps = np.abs(wrap_angle(np.diff(scored[:, 1])))
    true_steps = np.abs(wrap_angle(np.diff(truth_yaw[begin:])))
    print(f'largest true LF heading step from the scored start: {np.max(true_steps):.5f} rad')
    print(' t [s]  step [rad]  / largest true  gate g_psi before → after')
    for i in np.argsort(steps)[::-1][:count]:
        print(f'{scored[i + 1, 0]:6.0f}  {steps[i]:10.5f}  {steps[i] / np.max(true_steps):14.2f}'
              f'  {scored[i, 2]:.2f} → {scored[i + 1, 2]:.2f}')


if __name__ == '__main__':
    sys.exit(main())
