"""Per-variant summary of `method_probe.py --closed-loop` output: the numbers screen rules use.

    python docs/scripts/loop_screen_summary.py \
        docs/results/method_probe/spread60_retrain_period_*.txt

For each scenario (seeds with a default row): the default loop's position RMSE over the
observer loop's (mean, median) and its stable count; for each other variant, per seed, its
position RMSE over the default's (mean, median, range, seeds better), over the observer's
(mean), the paired statistic of the per-seed log ratios (mean ± its standard error, as a
ratio, and t = mean / standard error: on rao_swell a change that should not matter has a
per-seed SD of 0.17 in log, so a bare mean over ten seeds decides nothing; docs/BENCHMARKS.md,
twenty-second session), the mean of the per-seed wave-band thrust share ratios to the default per
DOF (and its paired form, the exponential of the mean per-seed log ratio, which one seed's
2.5× cannot carry), the stable count and, where the lines carry them, the paired ratios of the
error of the estimate each loop acted on (in all, in the control band, between the bands; per
DOF). Every earlier session rewrote this in /tmp; the
screens' rules ("mean per-seed position ratio ≤ 0.97, thrust ≤ 1.05 per DOF, all stable") read
these columns.
"""
from __future__ import annotations

import argparse
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
import math
import re
import statistics
import sys

LINE = re.compile(
    r'loop (?P<scenario>\S+)\s+(?P<seed>\d+) (?P<name>.+?)\s+position (?P<position>[\d.]+) m '
    r'heading \S+ rad max (?P<excursion>[\d.]+) m thrust WF % raw (?P<thrust>[\d.]+(?: / '
    r'[\d.]+)*) stable (?P<stable>True|False)')
NUMBERS = r'[\d.eE+-]+(?: / [\d.eE+-]+)*'
# the tail method_probe prints since the twenty-fourth session (between: twenty-fifth)
ESTIMATE = re.compile(rf'; estimate (?P<rmse>{NUMBERS}) \(control band (?P<control>{NUMBERS})'
                      rf'(?:; between (?P<between>{NUMBERS}))?\)')
DEFAULT = 'adaptive default'
PARTS = ('rmse', 'control', 'between')  # the estimate error: in all, control band, between


@dataclass(frozen=True)
class Loop:
    """One loop line of method_probe's output."""

    position: float  # [m] position RMSE
    thrust: tuple[float, ...]  # wave-band thrust share of the raw loop's per DOF [%]
    stable: bool
    # the error of the estimate the loop acted on per DOF, by part (PARTS), where printed
    estimate: tuple[tuple[float, ...] | None, ...] = (None, None, None)


def parse(lines: Sequence[str]) -> dict[tuple[str, int], dict[str, Loop]]:
    """{(scenario, seed): {loop name: Loop}} of every loop line."""
    rows: dict[tuple[str, int], dict[str, Loop]] = defaultdict(dict)
    for line in lines:
        match = LINE.search(line)
        if match is None:
            continue
        thrust = tuple(float(v) for v in match['thrust'].split(' / '))
        tail = ESTIMATE.search(line)
        estimate = tuple(None if tail is None or tail[part] is None else
                         tuple(float(v) for v in tail[part].split(' / ')) for part in PARTS)
        rows[(match['scenario'], int(match['seed']))][match['name'].strip()] = Loop(
            float(match['position']), thrust, match['stable'] == 'True', estimate)
    return rows


def estimate_ratios(loops: Sequence[Loop], default: Sequence[Loop]) -> str:
    """'; estimate / default (paired) all …; control …; between …' where every loop has it."""
    parts = []
    for k, part in enumerate(PARTS):
        pairs = [(a, b) for v, d in zip(loops, default, strict=True)
                 if (a := v.estimate[k]) is not None and (b := d.estimate[k]) is not None]
        if not pairs or len(pairs) < len(loops):
            continue
        ratios = [statistics.geometric_mean([a[i] / b[i] for a, b in pairs])
                  for i in range(len(pairs[0][0]))]
        parts.append(f'{part} ' + ' / '.join(f'{r:.2f}' for r in ratios))
    return '; estimate / default (paired) ' + '; '.join(parts) if parts else ''


def paired_ratio(ratios: Sequence[float]) -> str:
    """'paired G ×/÷ S, t T': geometric mean of per-seed ratios, its SE factor, t of the logs."""
    logs = [math.log(r) for r in ratios]
    error = statistics.stdev(logs) / math.sqrt(len(logs)) if len(logs) > 1 else math.inf
    return (f'paired {math.exp(statistics.mean(logs)):.3f} ×/÷ {math.exp(error):.3f}, '
            f't {statistics.mean(logs) / error:+.1f}' if error > 0.0 else 'paired: identical')


def summary(rows: dict[tuple[str, int], dict[str, Loop]]) -> list[str]:
    """The report lines (module docstring)."""
    out: list[str] = []
    for scenario in sorted({key[0] for key in rows}):
        seeds = sorted(seed for (name, seed), loops in rows.items()
                       if name == scenario and DEFAULT in loops and 'observer' in loops)
        if not seeds:
            continue
        default = [rows[(scenario, s)][DEFAULT] for s in seeds]
        observer = [rows[(scenario, s)]['observer'].position for s in seeds]
        versus = [d.position / o for d, o in zip(default, observer, strict=True)]
        out.append(f'{scenario}: {len(seeds)} seeds; default / observer mean '
                   f'{statistics.mean(versus):.3f} median {statistics.median(versus):.3f}; '
                   f'stable {sum(d.stable for d in default)}/{len(default)}')
        names = sorted({n for s in seeds for n in rows[(scenario, s)]
                        if n.startswith('adaptive') and n != DEFAULT})
        for name in names:
            found = [rows[(scenario, s)].get(name) for s in seeds]
            loops = [loop for loop in found if loop is not None]
            if len(loops) < len(found):
                out.append(f'  {name}: not on every seed, skipped')
                continue
            ratio = [v.position / d.position for v, d in zip(loops, default, strict=True)]
            # per DOF, the per-seed wave-band thrust ratios: their mean and their paired form
            thrust_ratios = [[v.thrust[i] / d.thrust[i] for v, d in zip(loops, default,
                                                                          strict=True)]
                             for i in range(len(default[0].thrust))]
            thrust = [statistics.mean(r) for r in thrust_ratios]
            thrust_paired = [statistics.geometric_mean(r) for r in thrust_ratios]
            over_observer = statistics.mean(v.position / o for v, o in
                                            zip(loops, observer, strict=True))
            paired = paired_ratio(ratio)
            out.append(
                f'  {name}: position / default mean {statistics.mean(ratio):.3f} median '
                f'{statistics.median(ratio):.3f} range {min(ratio):.2f}–{max(ratio):.2f}, '
                f'better on {sum(r < 1.0 for r in ratio)}/{len(ratio)}, {paired}; / observer '
                f'{over_observer:.3f}; thrust / default ' +
                ' / '.join(f'{t:.3f}' for t in thrust) +
                ' (paired ' + ' / '.join(f'{t:.3f}' for t in thrust_paired) + ')' +
                f'; stable {sum(v.stable for v in loops)}/{len(loops)}' +
                estimate_ratios(loops, default))
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """CLI (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('files', nargs='+', help='method_probe outputs')
    args = parser.parse_args(argv)
    lines: list[str] = []
    for name in args.files:
        with open(name, encoding='utf-8') as handle:
            lines += handle.readlines()
    print('\n'.join(summary(parse(lines))))
    return 0


if __name__ == '__main__':
    sys.exit(main())
