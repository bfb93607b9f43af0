"""Where a DP loop loses position: holding station vs the time after each setpoint event.

    OMP_NUM_THREADS=1 python docs/scripts/loop_error_where_probe.py rao_supply 1 2 3 \
        [--after 240] [--schedule-spread 60]

Per seed (tuning or development seeds only): the fair recording (its loop closed on the tuned
observer, 1800 s, setpoint events delayed by the seed's draw as `benchmark` does), the observer
loop and the shipped predictor's loop (`suite.run_closed_loops`, scored from the benchmark's
first scored sample). Prints, per loop, the horizontal position error RMS [m] (true LF pose
against the ideal loop's LF track) while holding station and in the ``--after`` seconds after
each setpoint event, and the share of the loop's mean squared error made after the events
(docs/BENCHMARKS.md, twenty-second session). ``--per-event`` adds a line per event inside the
run: each loop's RMS in the ``--after`` seconds after it and that window's share of the loop's
squared error (seventieth session: the first manoeuvre, while the motion gate is still shut).
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
import sys

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from method_probe import DEVELOPMENT_SEEDS, fair_case  # noqa: E402 - the sibling script

from lf_predictor_ros.benchmark.baseline_tuning import TUNING_SEEDS  # noqa: E402
from lf_predictor_ros.benchmark.benchmark import SCHEDULE_SPREAD  # noqa: E402
from lf_predictor_ros.benchmark.suite import run_closed_loops, scored_start  # noqa: E402
from sim_ros.simulation import simulate  # noqa: E402

DURATION = 1800.0  # [s] as method_probe
LOOPS = ('observer', 'adaptive')


def split_error(t: np.ndarray, offset: np.ndarray, events: Sequence[float], after: float,
                ) -> tuple[float, float, float]:
    """(holding RMS, after-event RMS, after-event share of the MSE) of the N/E offset [m]."""
    squared = offset[:, 0] ** 2 + offset[:, 1] ** 2
    near = np.zeros(t.shape, dtype=bool)
    for event in events:
        near |= (t >= event) & (t < event + after)
    hold = float(np.sqrt(squared[~near].mean())) if np.any(~near) else float('nan')
    moved = float(np.sqrt(squared[near].mean())) if np.any(near) else float('nan')
    return hold, moved, float(squared[near].sum() / squared.sum())


def event_errors(t: np.ndarray, offset: np.ndarray, events: Sequence[float], after: float,
                 ) -> list[tuple[float, float, float]]:
    """Per event inside ``t``: (event time, N/E offset RMS after it [m], its share of the MSE)."""
    squared = offset[:, 0] ** 2 + offset[:, 1] ** 2
    total = float(squared.sum())
    out = []
    for event in events:
        near = (t >= event) & (t < event + after)
        if np.any(near):
            out.append((event, float(np.sqrt(squared[near].mean())),
                        float(squared[near].sum()) / total))
    return out


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('scenario')
    parser.add_argument('seeds', nargs='+', type=int)
    parser.add_argument('--after', type=float, default=240.0, help='s after each event')
    parser.add_argument('--schedule-spread', type=float, default=SCHEDULE_SPREAD)
    parser.add_argument('--per-event', action='store_true', help='a line per event')
    args = parser.parse_args(argv)
    if set(args.seeds) - set(TUNING_SEEDS) - set(DEVELOPMENT_SEEDS):
        parser.error('only tuning and development seeds (held-out seeds: `benchmark`)')
    torch.set_num_threads(1)
    for seed in args.seeds:
        scenario, base, setup, recording = fair_case(args.scenario, seed, DURATION,
                                                     args.schedule_spread)
        t = recording.data()['t']
        start = float(t[scored_start(base, len(t))])
        ideal = simulate(scenario, seed=seed, duration=DURATION, controller=True,
                         feedback='truth_lf')
        recorded = {'observer': recording.loop_run} if recording.loop_run is not None else None
        _, series = run_closed_loops(scenario, seed, DURATION, setup, LOOPS, ideal, start,
                                     recorded)
        events = [float(row[0]) for row in scenario.controller.setpoint_schedule]
        parts = []
        for name in LOOPS:
            keep = series[name].t >= start
            hold, moved, share = split_error(series[name].t[keep], series[name].offset[keep],
                                             events, args.after)
            parts.append(f'{name}: hold {hold:.3f} m, after events {moved:.3f} m, share of MSE '
                         f'after events {share:.2f}')
        print(f'{args.scenario} {seed} events {[round(e) for e in events]} ' + ' | '.join(parts),
              flush=True)
        if args.per_event:
            per_loop = {}
            for name in LOOPS:
                keep = series[name].t >= start
                per_loop[name] = event_errors(series[name].t[keep], series[name].offset[keep],
                                              events, args.after)
            for rows in zip(*per_loop.values(), strict=True):
                print(f'  event at {rows[0][0]:6.0f} s: ' + ' | '.join(
                    f'{name} {rms:.3f} m ({share:.2f} of its MSE)'
                    for name, (_, rms, share) in zip(LOOPS, rows, strict=True)), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
