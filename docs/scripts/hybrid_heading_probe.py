"""Diagnostic: the adaptive loop with one part of its estimate taken from the observer (issue 13).

    OMP_NUM_THREADS=1 python docs/scripts/hybrid_heading_probe.py --take heading \
        --scenarios rao_supply --seeds 636 --closed-loop --loops-only --variant "hh="

`method_probe.py` with `suite.make_estimator` patched in this process only (nothing in the
package changes): the 'adaptive' loop's estimator runs the shipped predictor and the tuned
passive observer (true model) side by side on the same samples, and the DP controller gets the
predictor's north/east with the observer's heading (``--take heading``) or the observer's
north/east with the predictor's heading (``--take position``). Not an estimator anyone could
ship (the observer knows the vessel): it says which part of the estimate the RAO vessels' loops
lose their position on. Every variant of the run gets the patch; the default and the observer
rows come from a plain `method_probe.py` run. Development seeds only.
"""
from __future__ import annotations

from pathlib import Path
import sys
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import method_probe  # noqa: E402 - the sibling script

from lf_predictor_ros.benchmark import suite  # noqa: E402

TAKE = 'heading'  # ``--take``: the part of the estimate that comes from the observer
_MAKE = suite.make_estimator


class HybridStream:
    """The predictor's stream with part of each estimate replaced by the observer's."""

    def __init__(self, setup: Any) -> None:
        self.adaptive = _MAKE('adaptive', setup)
        self.observer = _MAKE('observer', setup)
        self.estimator = self.adaptive.estimator  # counters, as the suite reads them

    def step(self, t: float, pose: np.ndarray, force: np.ndarray,
             wave_peak_freq: float) -> np.ndarray:
        """Both estimators on the sample; the DP controller gets the mix (module docstring)."""
        out = np.array(self.adaptive.step(t, pose, force, wave_peak_freq), dtype=np.float64)
        other = np.asarray(self.observer.step(t, pose, force, wave_peak_freq))
        if TAKE == 'heading':
            out[2] = other[2]
        else:
            out[:2] = other[:2]
        return out


def make_estimator(name: str, setup: Any) -> Any:
    """`suite.make_estimator`, the adaptive one hybrid."""
    return HybridStream(setup) if name == 'adaptive' else _MAKE(name, setup)


if __name__ == '__main__':
    argv = sys.argv[1:]
    if '--take' in argv:
        at = argv.index('--take')
        TAKE = argv[at + 1]
        del argv[at:at + 2]
    if TAKE not in ('heading', 'position'):
        raise SystemExit("--take must be 'heading' or 'position'")
    setattr(suite, 'make_estimator', make_estimator)  # noqa: B010 - the patch
    sys.exit(method_probe.main(argv))
