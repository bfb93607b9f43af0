"""After a sea change, the thrust weights of the network before it held while the window regrows.

    OMP_NUM_THREADS=1 python docs/scripts/regrow_hold_probe.py -- "{}" --seed 547 \
        --gain-times --omegas

An exploratory probe for issue 13, hypothesis 2 ("fast adaptation: only the wave part changes
with ω0"; docs/BENCHMARKS.md, thirty-ninth session), not part of the package. Everything after
``--`` is `benchmark.sea_change`'s command line; this script wraps `run_retraining` (as the
predictor calls it) in its process. Compare with a plain `sea_change` run on the same seed.

After a detected change of sea state the training window restarts on the newest samples and
grows back to N; every network of that regrowth is fitted on a short window, all its weights
free. Here a retraining whose targets are shorter than N although the predictor has seen at
least N samples of its segment (the window is regrowing after a restart) and that has a network
in service is trained again with the thrust weights held exactly at the warm start's
(`PredictorParams.thrust_hold`'s solve, forced): so through the regrowth they stay those of the
network trained on a full window of the old sea, and only the position weights (the wave
filter) and the bias are fitted on the short window of the new one.
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
import sys
from typing import Any

from lf_predictor_ros.benchmark import sea_change
from lf_predictor_ros.core import predictor, retraining
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.retraining import RetrainResult, Snapshot

_ORIGINAL = retraining.run_retraining  # the function the predictor module imported
_THRUST_HELD = retraining.thrust_held
VERDICTS: Counter[str] = Counter()


def regrowing(params: PredictorParams, snapshot: Snapshot, incumbent: Any,
              result: RetrainResult) -> bool:
    """A network in service, N samples of the segment seen, and targets shorter than N."""
    window = params.training_samples
    return (incumbent is not None and snapshot.end_index >= window
            and len(result.targets) < window)


def held_regrowth(params: PredictorParams, snapshot: Snapshot, incumbent: Any,
                  *args: Any, **kwargs: Any) -> RetrainResult:
    """`run_retraining`, redone with the thrust weights held while the window regrows."""
    result = _ORIGINAL(params, snapshot, incumbent, *args, **kwargs)
    if not regrowing(params, snapshot, incumbent, result):
        VERDICTS['free'] += 1
        return result
    VERDICTS['held'] += 1
    retraining.thrust_held = lambda *_: True
    try:
        return _ORIGINAL(params.replace(thrust_hold=True), snapshot, incumbent, *args, **kwargs)
    finally:
        retraining.thrust_held = _THRUST_HELD


def main(argv: Sequence[str] | None = None) -> int:
    """CLI (module docstring)."""
    rest = [a for a in (sys.argv[1:] if argv is None else argv) if a != '--']
    predictor.run_retraining = held_regrowth  # type: ignore[attr-defined]
    try:
        return sea_change.main(rest)
    finally:
        predictor.run_retraining = _ORIGINAL  # type: ignore[attr-defined]
        print(f'# thrust weights (holding and twin): {dict(VERDICTS)}')


if __name__ == '__main__':
    sys.exit(main())
