"""`method_probe.py` with a count of the training window's sea-change restarts (issue 13).

    OMP_NUM_THREADS=1 python docs/scripts/loop_restart_probe.py --scenarios rao_swell \
        --seeds 1 2 3 4 5 6 7 8 9 10 --variant default --closed-loop --loops-only

Takes `method_probe.py`'s arguments and runs it unchanged, with the predictor's
`run_retraining` wrapped: every retraining whose window restarted on a change of sea state
(`RetrainResult.restarted`) prints a line (the ω0 in service → the new one) as it happens, and
one that took the targets before a recent restart up again (`RetrainResult.reverted`,
``sea_change_revert``) prints a ``revert`` line; after each seed, the number of restarts over all
of that seed's predictors (the holding network's and the motion gate twin's trainings count one
each; with several variants they add up). Before the twenty-first session the script wrapped
`retraining.sea_state_changed` instead, which the revert check calls a second time: its logs
with ``sea_change_revert`` on over-count (docs/BENCHMARKS.md, twenty-first session). Run from a
worktree with `PYTHONPATH` set to compare two versions of the code. Tuning and development seeds
only, as `method_probe.py` (docs/BENCHMARKS.md, twentieth session).
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
import sys
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

import method_probe  # noqa: E402 - the sibling script, found through the path above

from lf_predictor_ros.core import predictor, retraining  # noqa: E402
from lf_predictor_ros.core.frequency import FrequencyEstimate  # noqa: E402
from lf_predictor_ros.core.retraining import RetrainResult  # noqa: E402

_count = {'restarts': 0}
_retrain = retraining.run_retraining
_run = method_probe.run


def _counted(*args: Any, **kwargs: Any) -> RetrainResult:
    result = _retrain(*args, **kwargs)
    previous = args[4] if len(args) > 4 else kwargs.get('previous_frequency')
    old = previous.wave_peak_freq if isinstance(previous, FrequencyEstimate) else previous
    new = result.frequency.wave_peak_freq
    if result.restarted:
        _count['restarts'] += 1
        print(f'    restart: {old:.3f} -> {new:.3f}', flush=True)
    elif result.reverted:
        print(f'    revert: {old:.3f} -> {new:.3f}', flush=True)
    return result


def _run_counted(*args: Any, **kwargs: Any) -> None:
    _count['restarts'] = 0
    _run(*args, **kwargs)
    print(f"  restarts {args[0]} {args[1]}: {_count['restarts']}", flush=True)


def main(argv: Sequence[str] | None = None) -> int:
    """Run `method_probe.main` with the counter installed."""
    vars(predictor)['run_retraining'] = _counted  # the name the predictor calls it by
    method_probe.run = _run_counted
    return method_probe.main(argv)


if __name__ == '__main__':
    sys.exit(main())
