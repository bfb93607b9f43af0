"""A candidate network replaces the one in service only if it is better by a margin.

    OMP_NUM_THREADS=1 python docs/scripts/accept_margin_probe.py --margin 0.98 -- \
        --scenarios onedof_feedback --seeds 515 516 --duration 7200 --closed-loop \
        --loops-only --variant margin

An exploratory pre-check for issue 13 (docs/BENCHMARKS.md, thirty-eighth session), not part of
the package. Everything after ``--`` is `method_probe.py`'s command line; this script only
replaces `retraining._judge` in its process, for **every** variant it runs: run the default in
a plain `method_probe.py` process on the same seeds and give `loop_screen_summary.py` both
outputs (a variant without overrides, ``--variant margin``, is the shipped parameters with
this judge).

The package accepts a candidate unless its loss on the window's targets is more than 2 % above
the network in service's on the same targets (`retraining.ACCEPT_LOSS_RATIO` = 1.02). Here it
must also be *below* ``--margin`` times that loss: a window that does not fit clearly better
than the network in service already does keeps that network (hysteresis). Every other test of
`retraining._judge` (finite weights and loss, no divergence) and of `run_retraining` (no worse
than the causal cascade) stays; the first network, with none in service, is judged as before.
"""
from __future__ import annotations

import argparse
from collections import Counter
from collections.abc import Sequence
import math
from pathlib import Path
import sys

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

import method_probe  # noqa: E402

from lf_predictor_ros.core import retraining  # noqa: E402

_ORIGINAL_JUDGE = retraining._judge
SETTINGS: dict[str, float] = {'margin': 1.0}
VERDICTS: Counter[str] = Counter()


def judge(loss: float, objective: float, initial_objective: float,
          incumbent_loss: float | None, state: dict[str, torch.Tensor]) -> tuple[bool, str]:
    """`retraining._judge`, then: no better than ``margin`` × the incumbent's loss → rejected."""
    accepted, reason = _ORIGINAL_JUDGE(loss, objective, initial_objective, incumbent_loss, state)
    if accepted and incumbent_loss is not None and math.isfinite(incumbent_loss) and \
            loss > SETTINGS['margin'] * incumbent_loss:
        accepted, reason = False, (f'candidate not better than the network in service by the '
                                   f'margin ({loss:.3g} > {SETTINGS["margin"]:g} × '
                                   f'{incumbent_loss:.3g})')
    VERDICTS['accepted' if accepted else reason.split(' (')[0]] += 1
    return accepted, reason


def main(argv: Sequence[str] | None = None) -> int:
    """CLI (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--margin', type=float, required=True,
                        help='a candidate must have at most this × the loss of the network in '
                        'service on the window (< 1)')
    parser.add_argument('rest', nargs=argparse.REMAINDER, help='-- method_probe arguments')
    args = parser.parse_args(argv)
    if not 0.0 < args.margin <= 1.0:
        parser.error(f'--margin must be in (0, 1], got {args.margin}')
    SETTINGS['margin'] = args.margin
    retraining._judge = judge
    return method_probe.main_counting(args.rest, VERDICTS,
                                      'verdicts (holding and twin, all loops)')


if __name__ == '__main__':
    sys.exit(main())
