"""The numbers a dropout-loop adoption rule reads (rules Q–S, docs/BENCHMARKS.md), per row.

    python docs/scripts/dropout_rule_verdict.py loops BASE.json CANDIDATE.json [MORE BASE CAND]
    python docs/scripts/dropout_rule_verdict.py open-loop BASE.json CANDIDATE.json

``loops``: `odometry_bench run --dropout-loops` files, given in (base, candidate) pairs (several
rows pooled, e.g. the turn-inside and the moves row). Printed: the dropouts whose
``during_heading`` exceeds 0.5 rad in each arm with the worst and those above 1.0 rad; per
scenario and pooled, the geometric mean of the paired per-run ratios candidate / base of the
per-run means of ``during``, ``during_heading``, ``after`` and ``after_heading`` with its 95 %
t-interval (pooled over the 3-DOF scenarios, as `dropout_loop_compare.py` and the rules, and
over all); aborted lf_odom loops; ``adaptive_odom_d``'s paired position RMSE ratio and its
unstable loops; per scenario the mean fraction of each dropout's time with the truth inside
lf_odom's 95 % ellipse (``coverage``). ``open-loop``: `odometry_bench run --no-loops
--dead-reckoning-commands` files; per scenario the dropouts whose horizontal error at 120 s
exceeds 100 m and the mean error at 120 s over the others. Development tool; the rules written
in docs/BENCHMARKS.md decide, this script only counts.
"""
from __future__ import annotations

import argparse
from collections import defaultdict
import json
import math
from pathlib import Path
import sys
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from dropout_loop_compare import ratio_cell  # noqa: E402

FAILURE = 0.5  # heading failure of a dropout [rad]
CATASTROPHE = 1.0  # twice the failure [rad]
KEYS = ('during', 'during_heading', 'after', 'after_heading')
DIVERGED = 100.0  # an open-loop dead reckoning farther than this at 120 s diverged [m]


def load(path: str) -> list[dict[str, Any]]:
    with open(path, encoding='utf-8') as stream:
        cases: list[dict[str, Any]] = json.load(stream)
    return cases


def by_case(cases: list[dict[str, Any]]) -> dict[tuple[str, int], dict[str, Any]]:
    return {(case['scenario'], int(case['seed'])): case for case in cases}


def ratio(pairs: list[tuple[float, float]]) -> str:
    """`dropout_loop_compare.ratio_cell` of (base, candidate) pairs."""
    return ratio_cell([b for b, _ in pairs], [c for _, c in pairs])


def run_mean(case: dict[str, Any], key: str) -> float:
    rows = case['closed_loop']['dropout_loops']['lf_odom']['with_dropouts']
    values = [row.get(key, math.nan) for row in rows]
    return float(np.mean(values)) if values else math.nan


def heading_failures(cases: list[dict[str, Any]]) -> list[tuple[float, str, int, float]]:
    out = []
    for case in cases:
        loops = case.get('closed_loop', {}).get('dropout_loops')
        if not loops:
            continue
        for row in loops['lf_odom']['with_dropouts']:
            if row.get('during_heading', 0.0) > FAILURE:
                out.append((float(row['during_heading']), case['scenario'], int(case['seed']),
                            float(row['start'])))
    return sorted(out, reverse=True)


def loops(pairs: list[tuple[str, str]]) -> None:
    base_cases: list[dict[str, Any]] = []
    cand_cases: list[dict[str, Any]] = []
    for base_path, cand_path in pairs:
        base_cases += load(base_path)
        cand_cases += load(cand_path)
    for name, cases in (('base', base_cases), ('candidate', cand_cases)):
        fails = heading_failures(cases)
        worst = f'{fails[0][0]:.3f} rad ({fails[0][1]} {fails[0][2]} at {fails[0][3]:.0f} s)' \
            if fails else '–'
        above = sum(f[0] > CATASTROPHE for f in fails)
        print(f'{name}: {len(fails)} dropouts with during_heading > {FAILURE} rad, worst {worst}, '
              f'{above} above {CATASTROPHE} rad')
        for fail in fails:
            print(f'    {fail[0]:.3f} rad  {fail[1]} {fail[2]} at {fail[3]:.1f} s')
    base, cand = by_case(base_cases), by_case(cand_cases)
    common = [k for k in base if k in cand
              and base[k].get('closed_loop', {}).get('dropout_loops')
              and cand[k].get('closed_loop', {}).get('dropout_loops')]
    scenarios = sorted({k[0] for k in common})
    for key in KEYS:
        per: dict[str, list[tuple[float, float]]] = defaultdict(list)
        keys: dict[str, list[tuple[str, int]]] = defaultdict(list)
        for k in common:
            per[k[0]].append((run_mean(base[k], key), run_mean(cand[k], key)))
            keys[k[0]].append(k)
        three = [p for s in scenarios for p, k in zip(per[s], keys[s], strict=True)
                 if base[k]['ndof'] == 3]
        pooled = [p for s in scenarios for p in per[s]]
        cells = '; '.join(f'{s} {ratio(per[s])}' for s in scenarios)
        print(f'{key}: pooled 3-DOF {ratio(three)}, pooled all {ratio(pooled)} | {cells}')
    for name, group in (('base', base), ('candidate', cand)):
        aborted = sum(group[k]['closed_loop']['dropout_loops']['lf_odom']['aborted_at']
                      is not None for k in common)
        print(f'{name}: aborted lf_odom loops {aborted} of {len(common)}')
    rmse = [(base[k]['closed_loop']['adaptive_odom_d']['position_rmse'],
             cand[k]['closed_loop']['adaptive_odom_d']['position_rmse'])
            for k in common if 'adaptive_odom_d' in base[k]['closed_loop']
            and 'adaptive_odom_d' in cand[k]['closed_loop']]
    unstable = [sum(not g[k]['closed_loop']['adaptive_odom_d']['stable'] for k in common
                    if 'adaptive_odom_d' in g[k]['closed_loop']) for g in (base, cand)]
    print(f'adaptive_odom_d: position RMSE {ratio(rmse)}, unstable {unstable[0]} -> '
          f'{unstable[1]}')
    for s in scenarios:
        inside = []
        for group in (base, cand):
            fractions = [c['inside'] for k in common if k[0] == s
                         for c in group[k]['closed_loop']['dropout_loops']['lf_odom']
                         .get('coverage', [])]
            inside.append(float(np.mean(fractions)) if fractions else math.nan)
        print(f'trust {s}: truth in the 95 % ellipse {inside[0]:.3f} -> {inside[1]:.3f}')


def error_at(case: dict[str, Any], elapsed: str = '120.0') -> list[float]:
    out = []
    for dropout in case.get('dead_reckoning', {}).get('dropouts', []):
        at = dropout['times'].get(elapsed)
        if at is None or not at.get('published', False):
            out.append(math.nan)
            continue
        error = at['error']
        out.append(abs(error[0]) if case['ndof'] == 1 else math.hypot(error[0], error[1]))
    return out


def open_loop(base_path: str, cand_path: str) -> None:
    base, cand = by_case(load(base_path)), by_case(load(cand_path))
    for s in sorted({k[0] for k in base}):
        keys = [k for k in base if k[0] == s and k in cand]
        b = np.array([e for k in keys for e in error_at(base[k])])
        c = np.array([e for k in keys for e in error_at(cand[k])])
        keep = (b <= DIVERGED) & (c <= DIVERGED)
        changed = int(np.sum(np.abs(b - c) > 1e-9))
        print(f'{s}: diverged (> {DIVERGED:.0f} m at 120 s) {int(np.sum(b > DIVERGED))} -> '
              f'{int(np.sum(c > DIVERGED))}, unpublished {int(np.sum(np.isnan(b)))} -> '
              f'{int(np.sum(np.isnan(c)))}; mean over the others {np.mean(b[keep]):.3f} -> '
              f'{np.mean(c[keep]):.3f} m ({np.mean(c[keep]) / np.mean(b[keep]):.3f}x); '
              f'{changed} of {b.size} changed')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('kind', choices=('loops', 'open-loop'))
    parser.add_argument('files', nargs='+', help='BASE CANDIDATE [BASE CANDIDATE …]')
    args = parser.parse_args()
    if len(args.files) % 2:
        parser.error('give the files in (base, candidate) pairs')
    if args.kind == 'loops':
        loops(list(zip(args.files[::2], args.files[1::2], strict=True)))
    else:
        if len(args.files) != 2:
            parser.error('open-loop takes one base and one candidate file')
        open_loop(*args.files)


if __name__ == '__main__':
    main()
