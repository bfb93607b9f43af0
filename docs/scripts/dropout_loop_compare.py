"""Paired comparison of two `odometry_bench run --dropout-loops` JSON files, per scenario.

    python docs/scripts/dropout_loop_compare.py BASE.json CANDIDATE.json

For every (scenario, seed) in both files: lf_odom's loop through the pose dropouts, per run the
mean over its dropouts of the worst horizontal distance from the reference during each dropout
('during') and in the 120 s after it ('after') [m] (1 DOF: |north|), and of the heading
difference after it [rad] (3 DOF). Printed per scenario: the mean of each in both files, the
geometric mean of the per-run ratios candidate / base with its 95 % t-interval, how many runs
changed at all, and aborted loops; then the same pooled over the 3-DOF scenarios. The rule of
the forty-seventh session (docs/BENCHMARKS.md) reads these lines.
"""
from __future__ import annotations

from collections import defaultdict
import json
import math
import sys
from typing import Any

import numpy as np
from scipy import stats

KEYS = ('during', 'after', 'after_heading')


def per_run(path: str) -> dict[tuple[str, int], dict[str, Any]]:
    """(scenario, seed) → per-run means of ``KEYS`` (NaN where absent), aborted, ndof."""
    with open(path, encoding='utf-8') as stream:
        cases = json.load(stream)
    out: dict[tuple[str, int], dict[str, Any]] = {}
    for case in cases:
        loops = case.get('closed_loop', {}).get('dropout_loops')
        if not loops:
            continue
        rows = loops['lf_odom']['with_dropouts']
        entry: dict[str, Any] = {key: float(np.mean([r.get(key, math.nan) for r in rows]))
                                 for key in KEYS}
        entry['aborted'] = loops['lf_odom']['aborted_at'] is not None
        entry['ndof'] = case['ndof']
        out[(case['scenario'], int(case['seed']))] = entry
    return out


def ratio_cell(base: list[float], cand: list[float]) -> str:
    """Geometric mean of cand / base with its 95 % t-interval; changed runs."""
    b, c = np.array(base), np.array(cand)
    keep = np.isfinite(b) & np.isfinite(c) & (b > 0) & (c > 0)
    logs = np.log(c[keep] / b[keep])
    changed = int(np.sum(np.abs(logs) > 1e-9))
    if logs.size < 2:
        return f'n/a ({logs.size} runs)'
    half = float(stats.t.ppf(0.975, logs.size - 1) * np.std(logs, ddof=1) / math.sqrt(logs.size))
    mean = float(np.mean(logs))
    return (f'{math.exp(mean):.3f} [{math.exp(mean - half):.3f}, {math.exp(mean + half):.3f}] '
            f'({changed}/{logs.size} changed)')


def report(base: dict[tuple[str, int], dict[str, Any]],
           cand: dict[tuple[str, int], dict[str, Any]]) -> None:
    """Print the per-scenario and pooled 3-DOF lines (module docstring)."""
    groups: dict[str, list[tuple[str, int]]] = defaultdict(list)
    for key in sorted(set(base) & set(cand)):
        groups[key[0]].append(key)
        if base[key]['ndof'] == 3:
            groups['all 3-DOF'].append(key)
    for name, keys in groups.items():
        print(f'{name}: {len(keys)} runs')
        for field in KEYS:
            b = [base[k][field] for k in keys]
            c = [cand[k][field] for k in keys]
            if not np.any(np.isfinite(b)):
                continue
            print(f'  {field:14s} mean {np.nanmean(b):.3f} -> {np.nanmean(c):.3f}; '
                  f'max {np.nanmax(b):.3f} -> {np.nanmax(c):.3f}; ratio {ratio_cell(b, c)}')
        aborted = (sum(base[k]['aborted'] for k in keys), sum(cand[k]['aborted'] for k in keys))
        print(f'  aborted {aborted[0]} -> {aborted[1]}')


def main(argv: list[str]) -> int:
    """CLI (module docstring)."""
    if len(argv) != 2:
        print('usage: dropout_loop_compare.py BASE.json CANDIDATE.json', file=sys.stderr)
        return 2
    report(per_run(argv[0]), per_run(argv[1]))
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
