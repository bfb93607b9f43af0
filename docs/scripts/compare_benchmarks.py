"""Paired comparison of one estimator across two `benchmark --json` runs (same seeds).

    python docs/scripts/compare_benchmarks.py docs/results/benchmark/default_held_out.json.gz \
        docs/results/benchmark/motion_gate_held_out.json.gz [--estimator adaptive] \
        [--reference observer]

Per scenario, over the seeds both runs share: the closed-loop position RMSE, heading RMSE and
wave-band thrust power per DOF of the estimator's loop in each run, their per-seed ratio new /
base (mean [95 % Student-t interval], `benchmark.scoring.interval`), the same against the
reference loop of the new run, and the stable loops; then the open-loop RMSE per DOF with the
per-seed ratio. Prints a markdown table. Nothing is fitted or tuned here.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
import gzip
import json
import math
import sys
from typing import Any

from lf_predictor_ros.benchmark.benchmark import section_name
from lf_predictor_ros.benchmark.scoring import interval, ratios

DOFS = ('north', 'east', 'yaw')


def cases(path: str) -> dict[tuple[str, int], dict[str, Any]]:
    """(section, seed) → case of a benchmark JSON (gzip-compressed if it ends in .gz).

    The section is the scenario, with its run length for a scenario's long run
    (`benchmark.section_name`: ``supply_closed_loop, 7200 s runs``).
    """
    if path.endswith('.gz'):
        with gzip.open(path, 'rt', encoding='utf-8') as compressed:
            data = json.load(compressed)
    else:
        with open(path, encoding='utf-8') as handle:
            data = json.load(handle)
    return {(section_name(case['scenario'], float(case['duration'])), int(case['seed'])): case
            for case in data['cases']}


def cell(values: Sequence[float]) -> str:
    """Mean [95 % interval] of the finite values (`scoring.Interval.cell`); '–' when none."""
    return interval(values).cell(lambda value: f'{value:.3g}')


def loop_rows(scenario: str, pairs: list[tuple[dict[str, Any], dict[str, Any]]], estimator: str,
              reference: str) -> list[str]:
    """Closed-loop lines of one scenario (none when it has no loops)."""
    loops = [(b['closed_loop'], n['closed_loop']) for b, n in pairs
             if estimator in b.get('closed_loop', {}) and estimator in n.get('closed_loop', {})]
    if not loops:
        return []
    rows = []
    for key, label in (('position_rmse', 'position RMSE'), ('heading_rmse', 'heading RMSE')):
        base = [b[estimator].get(key, math.nan) for b, _ in loops]
        new = [n[estimator].get(key, math.nan) for _, n in loops]
        ref = [n[reference].get(key, math.nan) for _, n in loops]
        rows.append(f'| {scenario} | loop {label} | {cell(base)} | {cell(new)} | '
                    f'{cell(ratios(new, base))} | {cell(ratios(new, ref))} |')
    dofs = list(loops[0][0][estimator]['thrust_wave_band_power'])
    for dof in dofs:
        base = [b[estimator]['thrust_wave_band_power'][dof] for b, _ in loops]
        new = [n[estimator]['thrust_wave_band_power'][dof] for _, n in loops]
        ref = [n[reference]['thrust_wave_band_power'][dof] for _, n in loops]
        rows.append(f'| {scenario} | loop wave-band thrust {dof} | {cell(base)} | {cell(new)} | '
                    f'{cell(ratios(new, base))} | {cell(ratios(new, ref))} |')
    stable = [(b[estimator]['stability']['stable'], n[estimator]['stability']['stable'])
              for b, n in loops]
    rows.append(f'| {scenario} | loops stable | {sum(s for s, _ in stable)}/{len(stable)} | '
                f'{sum(s for _, s in stable)}/{len(stable)} | | |')
    return rows


def open_rows(scenario: str, pairs: list[tuple[dict[str, Any], dict[str, Any]]], estimator: str,
              reference: str) -> list[str]:
    """Open-loop RMSE lines of one scenario."""
    rows = []
    for dof in DOFS:
        if dof not in pairs[0][0]['metrics'][estimator]:
            continue
        base = [b['metrics'][estimator][dof]['rmse'] for b, _ in pairs]
        new = [n['metrics'][estimator][dof]['rmse'] for _, n in pairs]
        ref = [n['metrics'][reference][dof]['rmse'] for _, n in pairs
               if reference in n['metrics']]
        rows.append(f'| {scenario} | open-loop RMSE {dof} | {cell(base)} | {cell(new)} | '
                    f'{cell(ratios(new, base))} | '
                    f'{cell(ratios(new, ref)) if len(ref) == len(new) else "–"} |')
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    """CLI (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('base')
    parser.add_argument('new')
    parser.add_argument('--estimator', default='adaptive')
    parser.add_argument('--reference', default='observer')
    args = parser.parse_args(argv)
    base, new = cases(args.base), cases(args.new)
    shared = sorted(set(base) & set(new))
    print(f'| scenario | quantity | base | new | new / base | new / {args.reference} (new run) |')
    print('|---|---|---|---|---|---|')
    for scenario in sorted({name for name, _ in shared}):
        pairs = [(base[key], new[key]) for key in shared if key[0] == scenario]
        for line in loop_rows(scenario, pairs, args.estimator, args.reference) + \
                open_rows(scenario, pairs, args.estimator, args.reference):
            print(line)
    return 0


if __name__ == '__main__':
    sys.exit(main())
