"""Summarize `learned_observer_probe.py` outputs: per row, the seeds' means and paired ratios.

    python docs/scripts/learned_observer_summary.py \
        docs/results/method_probe/learned_observer_*.txt

Per file and row (``adaptive``, ``obs_truth``, ``obs_targets``, ``obs_learned`` and the optional
``obs_wrong_tg`` / ``observer_mistuned``): the mean loop position RMSE [m], its paired geometric
mean ratio to the adaptive loop's (t of the log ratios) and to ``obs_truth``'s, the stable loops,
the mean wave-band thrust share of the raw loop's per DOF (and over the adaptive loop's), and
for the observers the mean open-loop RMSE per DOF over ``obs_truth``'s (seventy-first session,
docs/BENCHMARKS.md).
"""
from __future__ import annotations

from collections.abc import Sequence
import math
import re
import sys
from typing import Any

import numpy as np

LINE = re.compile(r'\s+(\S+) (\d+) (\S+)\s+position ([\d.]+) m stable (\S+) thrust WF share '
                  r'([\d.]+) / ([\d.]+) / ([\d.]+)'
                  r'(?: open ([\d.e-]+) / ([\d.e-]+) / ([\d.e-]+))?')


def read_rows(path: str) -> dict[str, dict[int, dict[str, Any]]]:
    """{row name: {seed: {'pos', 'stable', 'thrust', 'open'}}} of one probe output."""
    rows: dict[str, dict[int, dict[str, Any]]] = {}
    with open(path, encoding='utf-8') as lines:
        for line in lines:
            match = LINE.match(line)
            if match is None:
                continue
            groups = match.groups()
            rows.setdefault(groups[2], {})[int(groups[1])] = {
                'pos': float(groups[3]), 'stable': groups[4] == 'True',
                'thrust': np.array([float(v) for v in groups[5:8]]),
                'open': None if groups[8] is None else np.array([float(v) for v in groups[8:11]])}
    return rows


def summary(path: str) -> list[str]:
    """The lines printed for one file (module docstring)."""
    rows = read_rows(path)
    adaptive, truth = rows['adaptive'], rows['obs_truth']
    seeds = sorted(adaptive)
    out = [f'{path}: {len(seeds)} seeds']
    for name, by_seed in rows.items():
        keep = [s for s in seeds if s in by_seed]
        pos = np.array([by_seed[s]['pos'] for s in keep])
        log_ratio = np.log(pos / np.array([adaptive[s]['pos'] for s in keep]))
        spread = float(np.std(log_ratio, ddof=1)) if len(keep) > 1 else 0.0
        t = float(np.mean(log_ratio)) / (spread / math.sqrt(len(keep))) if spread > 0 else math.nan
        truth_pos = np.array([truth[s]['pos'] for s in keep])
        to_truth = math.exp(float(np.mean(np.log(pos / truth_pos))))
        thrust = np.mean([by_seed[s]['thrust'] for s in keep], axis=0)
        thrust_adaptive = np.mean([adaptive[s]['thrust'] for s in keep], axis=0)
        text = (f'  {name:17s} position {pos.mean():.3f} m, / adaptive '
                f'{math.exp(float(np.mean(log_ratio))):.3f} (t {t:+.1f}), / obs_truth '
                f'{to_truth:.3f}; stable {sum(by_seed[s]["stable"] for s in keep)}/{len(keep)}; '
                f'thrust share {" / ".join(f"{v:.4f}" for v in thrust)} (/ adaptive '
                f'{" / ".join(f"{v:.2f}" for v in thrust / thrust_adaptive)})')
        if by_seed[keep[0]]['open'] is not None:
            rmse = np.mean([by_seed[s]['open'] for s in keep], axis=0)
            rmse_truth = np.mean([truth[s]['open'] for s in keep], axis=0)
            text += (f'; open {" / ".join(f"{v:.4g}" for v in rmse)} (/ obs_truth '
                     f'{" / ".join(f"{v:.3f}" for v in rmse / rmse_truth)})')
        out.append(text)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    for path in (sys.argv[1:] if argv is None else argv):
        print('\n'.join(summary(path)))
    return 0


if __name__ == '__main__':
    sys.exit(main())
