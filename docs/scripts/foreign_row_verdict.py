"""Rule Y's criterion 1: the foreign-controller row, base against candidate, per dropout.

    python docs/scripts/foreign_row_verdict.py BASE.json CANDIDATE.json

Both JSON files from `odometry_bench run … --no-loops --no-tracking --dead-reckoning-commands`
(the recorded thrust fed as the DP controller's commands: the stand-in for a replayed log whose
loop ran on another estimator). Prints, per dropout, the horizontal (1 DOF: the north) error of
lf_odom's dead reckoning 120 s in, base → candidate (``*``: changed), the dropouts above 10 m
in each arm and those more than 10 % and 0.5 m worse in the candidate (docs/BENCHMARKS.md,
sixty-fifth session's rule).
"""
from __future__ import annotations

import json
import math
from pathlib import Path
import sys
from typing import Any

Key = tuple[str, int, float]


def errors_at_120(cases: list[dict[str, Any]]) -> dict[Key, float]:
    """(scenario, seed, dropout start) → horizontal error [m] 120 s into the dropout."""
    out: dict[Key, float] = {}
    for case in cases:
        for dropout in case['dead_reckoning']['dropouts']:
            error = dropout['times'].get('120.0', {}).get('error')
            if not error:
                value = math.nan
            elif len(error) >= 2:
                value = math.hypot(error[0], error[1])
            else:
                value = abs(error[0])
            out[(case['scenario'], case['seed'], dropout['start'])] = value
    return out


def main(argv: list[str]) -> int:
    """Print the table and the verdict; 0 when criterion 1 holds, 1 otherwise."""
    base, cand = (errors_at_120(json.loads(Path(p).read_text())) for p in argv[:2])
    for key in sorted(base):
        mark = '  *' if abs(cand[key] - base[key]) > 1e-12 else ''
        print(key, f'{base[key]:.3f} -> {cand[key]:.3f}{mark}')
    above_base = sum(1 for v in base.values() if v > 10.0)
    above_cand = sum(1 for v in cand.values() if v > 10.0)
    worse = [key for key in base if cand[key] > 1.1 * base[key] and cand[key] - base[key] > 0.5]
    changed = sum(1 for key in base if abs(cand[key] - base[key]) > 1e-12)
    print(f'dropouts above 10 m at 120 s: base {above_base}, candidate {above_cand} of '
          f'{len(base)}; changed {changed}; more than 10 % and 0.5 m worse: {worse}')
    holds = above_cand < above_base and not worse
    print('criterion 1:', 'holds' if holds else 'fails')
    return 0 if holds else 1


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
