"""A network trained on a full window is replaced only when a newer window holds excitation.

    OMP_NUM_THREADS=1 python docs/scripts/excitation_gate_probe.py -- \
        --scenarios onedof_feedback --seeds 527 528 --duration 7200 --closed-loop \
        --loops-only --variant excited

An exploratory pre-check for issue 13, hypothesis 1 (closed-loop identification without
excitation; docs/BENCHMARKS.md, thirty-eighth session), not part of the package. Everything
after ``--`` is `method_probe.py`'s command line; this script only wraps `run_retraining` (as the
predictor calls it) in its process, for **every** variant it runs: run the default in a plain
`method_probe.py` process on the same seeds and give `loop_screen_summary.py` both outputs.

An accepted candidate is turned into a rejected one ("no excitation in the window") when all
hold: a network is in service; the window did not restart for a new sea; the predictor has seen
at least a full training window N of its segment; the newest N samples show no setpoint move or
turn (`retraining.without_excitation`, the package's `thrust_hold` test: two consecutive 60 s
block means apart by more than 2 m or 2°); and the network in service is no worse than the
causal cascade on the window's targets. So the
network in service is the last one trained on a window that held a manoeuvre (or the start's
transient), or the first one trained on a full window of station keeping, until a manoeuvre or
a new sea comes.
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
import sys
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

import method_probe  # noqa: E402

from lf_predictor_ros.core import predictor, retraining  # noqa: E402
from lf_predictor_ros.core.params import PredictorParams  # noqa: E402
from lf_predictor_ros.core.retraining import (  # noqa: E402
    RetrainResult,
    Snapshot,
    without_excitation,
)

_ORIGINAL = retraining.run_retraining  # the function the predictor module imported
VERDICTS: Counter[str] = Counter()


def gated_retraining(params: PredictorParams, snapshot: Snapshot, incumbent: Any,
                     *args: Any, **kwargs: Any) -> RetrainResult:
    """`run_retraining`, its candidate kept out of service without excitation (docstring)."""
    result = _ORIGINAL(params, snapshot, incumbent, *args, **kwargs)
    if not result.accepted:
        VERDICTS['rejected by the package'] += 1
        return result
    holds = (without_excitation(params, snapshot, incumbent) and not result.restarted
             and result.incumbent_loss is not None and result.baseline_loss is not None
             and result.incumbent_loss <= result.baseline_loss)
    if not holds:
        VERDICTS['accepted'] += 1
        return result
    VERDICTS['kept: no excitation'] += 1
    return replace(result, model=None, state_dict=None, accepted=False,
                   reason='no excitation in the window: the network in service is kept',
                   retire_incumbent=False)


def main(argv: Sequence[str] | None = None) -> int:
    """CLI (module docstring)."""
    predictor.run_retraining = gated_retraining  # type: ignore[attr-defined]
    return method_probe.main_counting(sys.argv[1:] if argv is None else argv, VERDICTS,
                                      'verdicts (holding and twin, all loops)')


if __name__ == '__main__':
    sys.exit(main())
