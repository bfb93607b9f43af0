"""Split `loop_block_probe.py` block outputs into manoeuvre and calm blocks, per scenario.

    python docs/scripts/manoeuvre_split.py docs/results/method_probe/blocks_771_778

Reads files named ``SCENARIO_SEED_ESTIMATOR.txt`` (``default`` and ``observer``), each the
output of ``loop_block_probe.py SCENARIO SEED ESTIMATOR 480 1800 --block 20``. A block is a
manoeuvre block when it overlaps the ``WINDOW`` seconds after a setpoint event of the scenario's
schedule (`sim_ros` scenario file, delayed by the seed's delay the file's first line prints);
else calm. Prints, per scenario, the share of the default loop's squared estimate error (north²
+ east², per block RMS squared) in manoeuvre blocks, the default / observer RMS ratio in each
class and over the run, and the run's ratio if either class were the observer's. The
forty-sixth session's eight-seed split (docs/BENCHMARKS.md).
"""
from __future__ import annotations

from collections import defaultdict
from pathlib import Path
import re
import sys

from sim_ros.simulation import load_scenario

WINDOW = 200.0  # [s] a manoeuvre's length after its setpoint event
BLOCK = re.compile(r'\s+(\d+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)')
NAME = re.compile(r'(?P<scenario>.+)_(?P<seed>\d+)_(?P<estimator>default|observer)\.txt')


def main(argv: list[str]) -> int:
    """Print the split of every scenario in the directory ``argv[0]``."""
    if len(argv) != 1 or not Path(argv[0]).is_dir():
        print('usage: manoeuvre_split.py DIRECTORY', file=sys.stderr)
        return 2
    # {scenario: {estimator: {'manoeuvre'|'calm': Σ (N² + E²)}}}
    sums: dict[str, dict[str, dict[str, float]]] = defaultdict(
        lambda: defaultdict(lambda: defaultdict(float)))
    for path in sorted(Path(argv[0]).glob('*.txt')):
        match = NAME.fullmatch(path.name)
        if match is None:
            continue
        text = path.read_text()
        delay = re.search(r'delayed ([\d.]+) s', text)
        shift = float(delay[1]) if delay else 0.0
        scenario = load_scenario(match['scenario'])
        events = [float(row[0]) + shift for row in scenario.controller.setpoint_schedule]
        for line in text.splitlines():
            row = BLOCK.match(line)
            if row is None:
                continue
            start = float(row[1])
            kind = 'manoeuvre' if any(e <= start + 20.0 and start < e + WINDOW
                                      for e in events) else 'calm'
            sums[match['scenario']][match['estimator']][kind] += \
                float(row[2]) ** 2 + float(row[3]) ** 2
    for name, by in sums.items():
        d, o = by['default'], by['observer']
        d_all, o_all = d['manoeuvre'] + d['calm'], o['manoeuvre'] + o['calm']
        print(f'{name}: default share in manoeuvres {d["manoeuvre"] / d_all:.2f} (observer '
              f'{o["manoeuvre"] / o_all:.2f}); default / observer RMS: manoeuvres '
              f'{(d["manoeuvre"] / o["manoeuvre"]) ** 0.5:.2f}, calm '
              f'{(d["calm"] / o["calm"]) ** 0.5:.2f}, all {(d_all / o_all) ** 0.5:.2f}; the '
              f"run if the manoeuvres were the observer's "
              f'{((o["manoeuvre"] + d["calm"]) / o_all) ** 0.5:.2f}, if the calm were '
              f'{((d["manoeuvre"] + o["calm"]) / o_all) ** 0.5:.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
