"""Paired summary of `odometry_bench run --dropout-loops` JSON files: candidates against a base.

    python docs/scripts/dropout_loop_summary.py BASE.json CANDIDATE.json [CANDIDATE.json ...]

Per (scenario, seed) run of the lf_odom dropout loop, the mean over its dropouts of the worst
distance in the 120 s after (`after`), of the worst distance during dropouts 2 and later
(`during23`: the first one cannot differ when only the reacquisition changes), of the peak
horizontal thrust after (`after_thrust`) and the first dropout's `after`. Printed: the paired
ratio candidate / base (geometric mean of the per-run ratios, ×/÷ its standard error), t of the
log ratios, how many runs got better, runs that abort only with the candidate, and the plain
means per scenario. The twenty-fourth session's `reacquire_blend_time` screen used it.
"""
from __future__ import annotations

import json
from pathlib import Path
import sys
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from loop_screen_summary import paired_ratio  # noqa: E402 - the sibling script

METRICS = ('after', 'during23', 'after_thrust', 'first_after')


def load(path: str) -> dict[tuple[str, int], dict[str, Any]]:
    """Per (scenario, seed): the lf_odom dropout-loop metrics of one JSON file."""
    with open(path) as f:
        cases = json.load(f)
    out: dict[tuple[str, int], dict[str, Any]] = {}
    for case in cases:
        loops = case['closed_loop']['dropout_loops']['lf_odom']
        rows = loops['with_dropouts']
        out[(case['scenario'], case['seed'])] = {
            'after': float(np.nanmean([r['after'] for r in rows])),
            'during23': float(np.nanmean([r['during'] for r in rows[1:]])),
            'after_thrust': float(np.nanmean([r['after_thrust'] for r in rows])),
            'first_after': float(rows[0]['after']),
            'aborted': loops['aborted_at']}
    return out


def paired(base: dict[tuple[str, int], dict[str, Any]],
           candidate: dict[tuple[str, int], dict[str, Any]], metric: str) -> str:
    """One line: paired ratio ×/÷ SE, t (`loop_screen_summary.paired_ratio`), runs better."""
    ratios = [candidate[k][metric] / base[k][metric] for k in sorted(base)
              if k in candidate and candidate[k][metric] > 0 and base[k][metric] > 0]
    return (f'{metric:13s} {paired_ratio(ratios)}; '
            f'better {sum(r < 1.0 for r in ratios)}/{len(ratios)}')


def main(argv: list[str]) -> None:
    """Print the summary of every candidate file against the first file."""
    base = load(argv[0])
    for path in argv[1:]:
        candidate = load(path)
        print(path)
        for metric in METRICS:
            print('  ' + paired(base, candidate, metric))
        aborted = [k for k in candidate
                   if candidate[k]['aborted'] is not None and base[k]['aborted'] is None]
        print(f'  aborted only with the candidate: {aborted}')
        for scenario in sorted({k[0] for k in base}):
            keys = [k for k in base if k[0] == scenario and k in candidate]
            print(f'  {scenario}: after {np.mean([base[k]["after"] for k in keys]):.2f} → '
                  f'{np.mean([candidate[k]["after"] for k in keys]):.2f} m; peak thrust after '
                  f'{np.mean([base[k]["after_thrust"] for k in keys]) / 1e3:.0f} → '
                  f'{np.mean([candidate[k]["after_thrust"] for k in keys]) / 1e3:.0f} kN')


if __name__ == '__main__':
    main(sys.argv[1:])
