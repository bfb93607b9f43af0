"""The thrust weights refitted only on windows with excitation; the rest at every training.

    OMP_NUM_THREADS=1 python docs/scripts/thrust_hold_probe.py -- \
        --scenarios onedof_feedback --seeds 539 540 --duration 7200 --closed-loop \
        --loops-only --variant hold

An exploratory pre-check for issue 13, hypothesis 1 (docs/BENCHMARKS.md, thirty-eighth session),
not part of the package. Everything after ``--`` is `method_probe.py`'s command line; this script
wraps `run_retraining` (as the predictor calls it) in its process, for **every** variant it runs:
run the default in a plain `method_probe.py` process on the same seeds.

When a retraining's window shows no excitation (the conditions of `excitation_gate_probe.py`: a
network in service, the predictor has seen a full training window N of its segment, and the
newest N samples show no setpoint move or turn, `manoeuvre.manoeuvring`), the training runs with
``thrust_prior`` = ``HOLD_RIDGE``: the least-squares solve pulls the thrust weights towards the
warm start's (the network in service's) with a ridge so large that they stay where they are,
and fits the position weights and the bias given them. Otherwise it trains as the package does.
The candidate is then judged as the package judges it. So the thrust weights are those of the
last window with excitation (or of the start), and the wave-filter part keeps adapting.
(A window restarted for a new sea is not seen here before the training; its thrust weights are
held too unless it shows a manoeuvre.)
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from pathlib import Path
import sys
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from excitation_gate_probe import quiet_window  # noqa: E402
import method_probe  # noqa: E402

from lf_predictor_ros.core import predictor, retraining  # noqa: E402
from lf_predictor_ros.core.params import PredictorParams  # noqa: E402
from lf_predictor_ros.core.retraining import RetrainResult, Snapshot  # noqa: E402

# Ridge per row (standardized units) that holds the thrust weights at the warm start's: 1e6
# against the other columns' 1e-6 (`network.LINEAR_RIDGE`) and unit-variance regressors.
HOLD_RIDGE = 1e6
_ORIGINAL = retraining.run_retraining  # the function the predictor module imported
VERDICTS: Counter[str] = Counter()


def held_retraining(params: PredictorParams, snapshot: Snapshot, incumbent: Any,
                    *args: Any, **kwargs: Any) -> RetrainResult:
    """`run_retraining`, the thrust weights held on windows without excitation (docstring)."""
    hold = quiet_window(params, snapshot, incumbent)
    VERDICTS['held' if hold else 'free'] += 1
    used = params.replace(thrust_prior=HOLD_RIDGE) if hold else params
    return _ORIGINAL(used, snapshot, incumbent, *args, **kwargs)


def main(argv: Sequence[str] | None = None) -> int:
    """CLI (module docstring)."""
    predictor.run_retraining = held_retraining  # type: ignore[attr-defined]
    return method_probe.main_counting(sys.argv[1:] if argv is None else argv, VERDICTS,
                                      'thrust weights (holding and twin, all loops)')


if __name__ == '__main__':
    sys.exit(main())
