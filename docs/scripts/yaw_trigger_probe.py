"""Where the adaptive heading errs in turns, and what the yaw moment trigger sees (issue 13).

    python docs/scripts/yaw_trigger_probe.py open rao_swell 1479 [--param FIELD=VALUE ...]
    python docs/scripts/yaw_trigger_probe.py loop rao_swell 1479 [--param FIELD=VALUE ...]

``open``: the fair recording (DP loop on the observer, 1800 s, the scheduled events delayed by
the seed's draw of U(0, ``--spread``) s, 60 by default as `benchmark`), the adaptive predictor
(inline training) and the baselines over it (`suite.run_open_loop`); the heading RMSE against
the true LF heading from the benchmark's first scored sample, split at a true LF yaw rate of
``TURN_RATE`` (holding / turning), the turning samples' share of the squared error, then the
adaptive and cascade heading error per 100 s block with the true heading and the largest true
yaw rate in it.

``loop``: the adaptive predictor in its own DP loop (`recordings.run_loop`, same seed and
schedule); every 20th sample from 300 to 700 s and from 1550 to 1750 s, the applied |N|, the
trigger's low-passed moment m, its level L, 5·L (the default ratio), its gain and whether it is
warm (`core.yaw_moment_trigger`).

``--param`` overrides a `PredictorParams` field (``true``/``false`` for flags). Development
seeds only (docs/BENCHMARKS.md, seventieth session).
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
import math
import sys
from typing import Any

import numpy as np

from lf_predictor_ros.benchmark.benchmark import FIRST_HELD_OUT_SEED, SCHEDULE_SPREAD
from lf_predictor_ros.benchmark.estimators import make_estimator, predictor_params
from lf_predictor_ros.benchmark.recordings import run_loop
from lf_predictor_ros.benchmark.suite import (
    make_recording,
    make_setup,
    run_open_loop,
    schedule_shift_for_seed,
    scored_start,
)
from lf_predictor_ros.core import yaw_moment_trigger
from lf_predictor_ros.core.heading import wrap_angle
from lf_predictor_ros.core.math_threads import use_one_math_thread
from sim_ros.simulation import load_scenario, scenario_with_schedule_shift

TURN_RATE = 0.002  # [rad/s] a scored sample counts as turning above this true LF yaw rate
DURATION = 1800.0  # [s]
OPEN_LOOP = ('adaptive', 'cascade', 'observer', 'oracle_kf', 'smoother_targets')
BLOCK = 100  # [samples] of the per-block table
LOG_WINDOWS = ((300, 700), (1550, 1750))  # [samples] of the loop's trigger log
LOG_EVERY = 20  # [samples]


def _overrides(items: Sequence[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for item in items:
        key, _, value = item.partition('=')
        out[key] = value == 'true' if value in ('true', 'false') else float(value)
    return out


def open_loop(name: str, seed: int, spread: float, overrides: dict[str, Any]) -> None:
    """Print the open-loop tables of the module docstring."""
    scenario = scenario_with_schedule_shift(load_scenario(name),
                                            schedule_shift_for_seed(seed, spread))
    params = predictor_params(scenario, overrides or None)
    setup = make_setup(scenario, seed, params)
    data = make_recording(scenario, seed, DURATION, setup).data()
    outputs = run_open_loop(data, setup, OPEN_LOOP, {})
    t, truth = data['t'], data['truth']
    begin = scored_start(params, len(t))
    rate = np.gradient(np.unwrap(truth[:, 2]), t)
    turning = (np.abs(rate) > TURN_RATE)[begin:]
    print(f'{name} {seed}: scored samples {len(t) - begin}, turning {int(turning.sum())}')
    for estimator in (*OPEN_LOOP, 'raw'):
        estimate = data['y'] if estimator == 'raw' else outputs[estimator]
        error = np.asarray(wrap_angle(estimate[:, 2] - truth[:, 2]))[begin:]
        total = float(np.sum(error**2))
        print(f'{estimator:17s} heading RMSE {math.sqrt(np.mean(error**2)):.5f} rad, holding '
              f'{math.sqrt(np.mean(error[~turning]**2)):.5f}, turning '
              f'{math.sqrt(np.mean(error[turning]**2)) if turning.any() else math.nan:.5f}, '
              f'turning share {float(np.sum(error[turning]**2)) / total:.2f}')
    adaptive = np.asarray(wrap_angle(outputs['adaptive'][:, 2] - truth[:, 2]))
    cascade = np.asarray(wrap_angle(outputs['cascade'][:, 2] - truth[:, 2]))
    for first in range(begin - begin % BLOCK, len(t) - BLOCK + 1, BLOCK):
        rows = slice(first, first + BLOCK)
        print(f'{t[first]:6.0f} s  adaptive {math.sqrt(np.mean(adaptive[rows]**2)):.4f} (mean '
              f'{np.mean(adaptive[rows]):+.4f})  cascade '
              f'{math.sqrt(np.mean(cascade[rows]**2)):.4f}  true heading '
              f'{math.degrees(float(np.mean(truth[rows, 2]))):7.1f}°  max |r| '
              f'{float(np.max(np.abs(rate[rows]))):.4f} rad/s')


def loop(name: str, seed: int, spread: float, overrides: dict[str, Any]) -> None:
    """Print the loop's trigger log of the module docstring."""
    scenario = scenario_with_schedule_shift(load_scenario(name),
                                            schedule_shift_for_seed(seed, spread))
    params = predictor_params(scenario, overrides or None)
    setup = make_setup(scenario, seed, params)
    log: list[tuple[float, float, float, float, bool]] = []
    update = yaw_moment_trigger.YawMomentTrigger.update

    def logged(self: yaw_moment_trigger.YawMomentTrigger, moment: float) -> float:
        gain = update(self, moment)
        log.append((moment, self._moment, self._level, gain, self.warm))  # noqa: SLF001
        return gain

    yaw_moment_trigger.YawMomentTrigger.update = logged  # type: ignore[method-assign]
    try:
        run_loop(scenario, seed, DURATION, setup.sample_time,
                 make_estimator('adaptive', setup).step)
    finally:
        yaw_moment_trigger.YawMomentTrigger.update = update  # type: ignore[method-assign]
    ratio = params.motion_gate_yaw_moment_ratio
    for first, last in LOG_WINDOWS:
        for k in range(first, min(last, len(log) - 1) + 1, LOG_EVERY):
            moment, low_passed, level, gain, warm = log[k]
            print(f'{k:5d} s  |N| {abs(moment) / 1e6:6.2f}  m {low_passed / 1e6:6.2f}  level '
                  f'{level / 1e6:6.2f}  {ratio:g}·level {ratio * level / 1e6:6.2f} MN·m  gain '
                  f'{gain:.2f}  warm {warm}')


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n', 1)[0])
    parser.add_argument('mode', choices=('open', 'loop'))
    parser.add_argument('scenario')
    parser.add_argument('seed', type=int)
    parser.add_argument('--param', action='append', default=[], metavar='FIELD=VALUE')
    parser.add_argument('--spread', type=float, default=SCHEDULE_SPREAD, metavar='SECONDS')
    args = parser.parse_args(argv)
    if FIRST_HELD_OUT_SEED <= args.seed < FIRST_HELD_OUT_SEED + 20:
        parser.error(f'seed {args.seed} is held out: reporting only')
    use_one_math_thread()
    (open_loop if args.mode == 'open' else loop)(args.scenario, args.seed, args.spread,
                                                 _overrides(args.param))
    return 0


if __name__ == '__main__':
    sys.exit(main())
