"""Where the adaptive DP loop's LF estimate errs in turns: the published output, the cascade, raw.

    python docs/scripts/turn_error_probe.py rao_supply 2 3

Runs the adaptive predictor (shipped defaults, inline training) in the scenario's DP loop
(`recordings.run_loop`, 1800 s) and records, per grid sample, its published output (valid at
t + h), its own cascade fallback's estimate and the measured pose (both at t), and where the
output came from (the holding network alone, with the motion gate open, or the fallback). For
each setpoint event before 1700 s it prints the horizontal (north/east) and heading RMSE of the
three against the true LF pose over the 120 s after the event and the event's share of the
output's squared horizontal error after 481 s; then the same over every sample after 481 s whose
true yaw rate exceeds 0.005 rad/s (the turns); then per source and window (holding / the 200 s
after an event) the share of the time, the RMSE and the share of the squared error; last, where
the motion gate acts on north/east, the horizontal RMSE of the holding network's output before
the gate, of the gated output and of the gate's twin alone (and over all scored samples).
Tuning and development seeds only (1–10). Diagnostic for issue 13 (docs/BENCHMARKS.md,
sixteenth session).
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
import math
import sys

import numpy as np
import torch

from lf_predictor_ros.benchmark.benchmark import FIRST_HELD_OUT_SEED
from lf_predictor_ros.benchmark.estimators import predictor_params
from lf_predictor_ros.benchmark.recordings import run_loop
from lf_predictor_ros.core.heading import wrap_angle
from lf_predictor_ros.core.predictor import AdaptivePredictor
from sim_ros.simulation import load_scenario

FloatArray = np.ndarray
TURN_RATE = 0.005  # [rad/s] a sample counts as turning above this true yaw rate
EVENT_WINDOW = 120.0  # [s] scored after each setpoint event
AFTER_EVENT = 200.0  # [s] the sources' 'after an event' window
SCORED_FROM = 481.0  # [s] the benchmark's first scored sample


def _rms(error: FloatArray, rows: FloatArray, columns: list[int]) -> float:
    return math.sqrt(float(np.mean(np.sum(error[rows][:, columns] ** 2, axis=1))))


def probe(scenario_name: str, seed: int) -> None:
    """One loop; print the event and turn tables (module docstring)."""
    scenario = load_scenario(scenario_name)
    params = predictor_params(scenario)
    predictor = AdaptivePredictor(params, background=False)
    cascade: list[FloatArray] = []
    fallback_update = predictor._fallback.update  # noqa: SLF001 - diagnostic: log its output

    def logged_fallback(t: float, pose: FloatArray, force: FloatArray) -> FloatArray:
        out = fallback_update(t, pose, force)
        cascade.append(np.array(out, dtype=np.float64))
        return out

    predictor._fallback.update = logged_fallback  # type: ignore[method-assign]  # noqa: SLF001
    stamps: list[float] = []
    outputs: list[FloatArray] = []
    measured: list[FloatArray] = []
    sources: list[str] = []
    holding: list[FloatArray] = []  # the output before the motion gate
    twin: list[FloatArray] = []  # the gate's twin's own output
    gate = predictor._gated  # noqa: SLF001 - diagnostic: log the gate's input
    moving = predictor._moving  # noqa: SLF001
    if moving is not None:
        twin_update = moving.update

        def logged_twin(t: float, pose: FloatArray, force: FloatArray) -> FloatArray:
            out = twin_update(t, pose, force)
            twin.append(np.array(out, dtype=np.float64))
            return out

        moving.update = logged_twin  # type: ignore[method-assign]

    def logged_gate(t: float, out: FloatArray, pose: FloatArray, force: FloatArray
                    ) -> FloatArray:
        holding.append(np.array(out, dtype=np.float64))
        return gate(t, out, pose, force)

    predictor._gated = logged_gate  # type: ignore[method-assign]  # noqa: SLF001

    def step(t: float, pose: FloatArray, force: FloatArray, true_omega: float) -> FloatArray:
        out = predictor.update(t, pose, force)
        gate = np.asarray(predictor._gain)  # noqa: SLF001 - diagnostic: the gate's gains
        sources.append('fallback' if not predictor.using_network else
                       'gate open' if np.any(gate > 0.0) else 'network')
        stamps.append(t)
        outputs.append(np.array(out, dtype=np.float64))
        measured.append(np.array(pose, dtype=np.float64))
        return out

    record = run_loop(scenario, seed, 1800.0, params.sample_time, step).record
    t = np.array(stamps)

    def truth(at: FloatArray) -> FloatArray:
        return np.column_stack([np.interp(at, record.t, record.truth_lf_pose[:, i])
                                for i in range(3)])

    errors = {}
    for name, values, at in (('output', outputs, t + params.sample_time),
                             ('cascade', cascade, t), ('raw', measured, t)):
        error = np.array(values) - truth(at)
        error[:, 2] = wrap_angle(error[:, 2])
        errors[name] = error
    true_now = truth(t)
    rate = np.abs(np.gradient(np.unwrap(true_now[:, 2]), t))
    scored = t + params.sample_time >= SCORED_FROM
    squared = np.sum(errors['output'][:, :2] ** 2, axis=1)
    total = float(squared[scored].sum())
    events = [float(row[0]) for row in scenario.controller.setpoint_schedule
              if float(row[0]) <= 1700.0]
    after = np.zeros(t.shape, dtype=bool)
    for start in events:
        rows = (t >= start) & (t < start + EVENT_WINDOW)
        after |= (t >= start) & (t < start + AFTER_EVENT)
        cells = ' '.join(f'{n} {_rms(e, rows, [0, 1]):.3f}' for n, e in errors.items())
        yaw = ' '.join(f'{n} {_rms(e, rows, [2]):.4f}' for n, e in errors.items())
        share = 100.0 * float(squared[rows & scored].sum()) / total
        print(f'{scenario_name} {seed} event {start:.0f} s (largest true yaw rate '
              f'{rate[rows].max():.4f} rad/s): north/east [m] {cells} | heading [rad] {yaw} | '
              f'{share:.1f} % of the squared error')
    rows = (rate > TURN_RATE) & (t >= SCORED_FROM)
    cells = ' '.join(f'{n} {_rms(e, rows, [0, 1]):.3f}' for n, e in errors.items())
    yaw = ' '.join(f'{n} {_rms(e, rows, [2]):.4f}' for n, e in errors.items())
    print(f'  turning ({100 * rows.mean():.1f} % of the samples): north/east [m] {cells} | '
          f'heading [rad] {yaw}')
    origin = np.array(sources)
    for source in ('network', 'gate open', 'fallback'):
        for window, mask in (('holding', ~after), ('after an event', after)):
            rows = scored & (origin == source) & mask
            if rows.any():
                print(f'  {source:9s} {window:14s}: {100 * rows.sum() / scored.sum():5.1f} % of '
                      f'the time, {_rms(errors["output"], rows, [0, 1]):.3f} m, '
                      f'{100 * float(squared[rows].sum()) / total:5.1f} % of the squared error')
    print(f'  guard trips {predictor.counters["guard_trips"]}', flush=True)
    if len(twin) != len(t) or len(holding) != len(t):
        return
    at = t + params.sample_time
    before = np.array(holding)[:, :2] - truth(at)[:, :2]
    alone = np.array(twin)[:, :2] - truth(at)[:, :2]
    gated = errors['output'][:, :2]
    acting = scored & np.any(np.abs(np.array(outputs)[:, :2] - np.array(holding)[:, :2]) > 1e-9,
                             axis=1)
    for name, rows in (('where the gate acts', acting), ('all scored samples', scored)):
        print(f'  {name} ({100 * rows.sum() / scored.sum():.1f} %): holding '
              f'{_rms(before, rows, [0, 1]):.3f} m, gated {_rms(gated, rows, [0, 1]):.3f} m, '
              f'twin alone {_rms(alone, rows, [0, 1]):.3f} m', flush=True)


def main(argv: Sequence[str] | None = None) -> int:
    """CLI (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('scenario')
    parser.add_argument('seeds', nargs='+', type=int)
    args = parser.parse_args(argv)
    if any(not 1 <= s < FIRST_HELD_OUT_SEED for s in args.seeds):
        parser.error('tuning and development seeds only (1-10)')
    torch.set_num_threads(1)
    for seed in args.seeds:
        probe(args.scenario, seed)
    return 0


if __name__ == '__main__':
    sys.exit(main())
