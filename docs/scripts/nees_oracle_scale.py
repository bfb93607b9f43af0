"""Runs inside their NEES bounds at the shipped scale and at the scale the runs themselves ask for.

    python docs/scripts/nees_oracle_scale.py dev_default.json dev_candidate.json

For each `odometry_bench run` JSON: the four vessels' mean joint pose NEES, the spread of their
logs and the runs whose joint NEES lies inside its own 95 % bounds, once as published and once
with every covariance multiplied by the geometric mean of the file's per-DOF NEES (the global
scale these very runs would calibrate to). The NEES bounds depend only on the normalized error's
autocorrelation, which a common factor does not change, so the second line is exact. A
diagnostic: it separates a candidate's effect on the spread between vessels from the level the
calibration seeds set (docs/BENCHMARKS.md, twenty-fifth session). Never a choice of scale.
"""
from __future__ import annotations

import json
import math
import statistics
import sys
from typing import Any


def _cases(path: str) -> list[dict[str, Any]]:
    with open(path, encoding='utf-8') as stream:
        data = json.load(stream)
    return list(data['cases'] if isinstance(data, dict) and 'cases' in data else data)


def summary(cases: list[dict[str, Any]], factor: float) -> tuple[dict[str, float], float, int]:
    """Vessel means of the joint NEES with the covariances × ``factor``, their spread, inside."""
    inside = 0
    by_vessel: dict[str, list[float]] = {}
    for case in cases:
        joint = case['tracking']['pose']['joint']
        nees = joint['mean_nees'] / factor
        inside += int(joint['low'] <= nees <= joint['high'])
        by_vessel.setdefault(case['scenario'], []).append(nees)
    means = {name: sum(v) / len(v) for name, v in sorted(by_vessel.items())}
    spread = statistics.pstdev([math.log(v) for v in means.values()])
    return means, spread, inside


def main(paths: list[str]) -> None:
    for path in paths:
        cases = _cases(path)
        dofs = [d['mean_nees'] for c in cases for d in c['tracking']['pose']['dof']]
        level = math.exp(sum(math.log(v) for v in dofs) / len(dofs))
        for factor in (1.0, level):
            means, spread, inside = summary(cases, factor)
            shown = ', '.join(f'{name} {value:.2f}' for name, value in means.items())
            print(f'{path} covariance × {factor:.3f}: {shown}; spread {spread:.3f}; '
                  f'inside {inside}/{len(cases)}')


if __name__ == '__main__':
    main(sys.argv[1:])
