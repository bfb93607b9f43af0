"""Exploratory: start-twist rules scored offline on `start_twist_log.py` files, per row.

    python docs/scripts/start_twist_rules.py moves=a.json,b.json inside=c.json spread=d.json

For every dropout start logged (3-DOF cases with both wave averages known) the start each rule
would have chosen, against the true LF body velocity; printed per row: the yaw-rate error's
mean, RMS, largest and count above 0.015 rad/s, and the surge and sway errors' mean and
largest. Rules: ``base`` (what the logged run chose), ``A<k>`` (the moving DOFs' current twist
kept within k holding std of the span between mean(T) and 2 mean(T) − mean(2T), as
``dead_reckoning_moving_twist_clamp`` k; the others as logged), ``B<k>`` (every DOF from that
clamped current twist) and ``current`` (every DOF from the current twist). The yaw-rate error
at the start times the yaw time constant (about 12 s) is most of a dropout's heading error
(correlation 0.70 in the development moves row). Development tool: a closed-loop rule decides.
"""
from __future__ import annotations

import json
import sys
from typing import Any

import numpy as np

FloatArray = np.ndarray
KS_MOVING = (2, 4, 8, 16, 32)
KS_EVERY = (2, 4, 16)


def load(paths: list[str]) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = []
    for path in paths:
        with open(path, encoding='utf-8') as stream:
            rows.extend(json.load(stream))
    return [r for r in rows if r['average'] is not None and r['average_double'] is not None
            and len(r['current']) == 3]


def rules(rows: list[dict[str, Any]]) -> tuple[dict[str, FloatArray], FloatArray]:
    """(the start per rule, the true twist), one row per dropout start."""
    def column(key: str) -> FloatArray:
        return np.array([r[key] for r in rows], dtype=float)

    current, chosen, average, double, hold, true = map(column, (
        'current', 'start', 'average', 'average_double', 'holding_std', 'true'))
    moving = np.array([r['moving'] or [False] * 3 for r in rows], dtype=bool)
    ahead = 2.0 * average - double
    low, high = np.minimum(average, ahead), np.maximum(average, ahead)
    out = {'base': chosen}
    for k in KS_MOVING:
        out[f'A{k}'] = np.where(moving, np.clip(current, low - k * hold, high + k * hold), chosen)
    for k in KS_EVERY:
        out[f'B{k}'] = np.clip(current, low - k * hold, high + k * hold)
    out['current'] = current
    return out, true


def main(argv: list[str]) -> int:
    """Entry point."""
    if not argv:
        print(__doc__)
        return 2
    for item in argv:
        name, _, paths = item.partition('=')
        rows = load(paths.split(','))
        starts, true = rules(rows)
        print(f'== {name}: {len(rows)} starts')
        for rule, start in starts.items():
            e = np.abs(start - true)
            rms = np.sqrt((e[:, 2] ** 2).mean())
            print(f'{rule:8s} yaw mean {e[:, 2].mean():.4f} rms {rms:.4f}'
                  f' max {e[:, 2].max():.4f} n>0.015 {int((e[:, 2] > 0.015).sum()):2d} | surge '
                  f'{e[:, 0].mean():.3f} max {e[:, 0].max():.2f} | sway {e[:, 1].mean():.3f} max '
                  f'{e[:, 1].max():.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
