"""Exploratory: the sanity guard falls back only in the DOFs that tripped it.

    OMP_NUM_THREADS=1 python docs/scripts/guard_per_dof_probe.py --scenarios rao_supply \
        --seeds 687 688 --closed-loop --loops-only --variant "pd="
    OMP_NUM_THREADS=1 python docs/scripts/guard_per_dof_probe.py --blocks rao_supply 675 \
        default 1100 1200 --block 4 --bias --rate

`method_probe.py` (or, with ``--blocks`` first, `loop_block_probe.py`) with, in this process
only (nothing in the package changes), the guard of `AdaptivePredictor.update` (`_plausible`)
made per DOF. Shipped: a prediction farther from the
newest measurement than ``GUARD_SPREADS`` RMS of the training window's wave motion plus a floor
in any DOF is not believed, and the cascade stands in for every DOF (and the feedback history is
re-seeded). In a RAO vessel's turn the network trips it on north, then on heading
(`turn_part_probe.py`, forty-second session), and the cascade, which lags a turn far more than
the network's other rows, serves all three DOFs for 10–15 s. Here the cascade's value replaces
only the DOFs outside their bound; the network keeps serving the others. A trip in every DOF is
the shipped full fallback. Each per-DOF trip counts once in ``guard_trips``.
Every variant of the run gets the patch (run the rows without it from another process; the
networks' feedback (``nfb`` > 0) gets the mixed value, as its output). Development seeds only,
as `method_probe.py`.
"""
from __future__ import annotations

from pathlib import Path
import sys
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import loop_block_probe  # noqa: E402 - the sibling script

from lf_predictor_ros.core.predictor import AdaptivePredictor  # noqa: E402

_INIT = AdaptivePredictor.__init__
_PLAUSIBLE = AdaptivePredictor._plausible


def _init_keeping_cascade(self: Any, *args: Any, **kwargs: Any) -> None:
    """`AdaptivePredictor.__init__`, then the cascade's newest output kept as ``probe_cascade``."""
    _INIT(self, *args, **kwargs)
    fallback = self._fallback
    cascade_update = fallback.update

    def update(t: float, pose: np.ndarray, force: np.ndarray) -> np.ndarray:
        cascade: np.ndarray = cascade_update(t, pose, force)
        fallback.probe_cascade = cascade
        return cascade

    fallback.update = update


def per_dof_plausible(self: Any, prediction: np.ndarray, y: np.ndarray) -> bool:
    """The shipped test; where it fails, the cascade's value in the DOFs out of their bound.

    Changes ``prediction`` in place (the array `_predict` made for this sample) and returns
    True unless every DOF is out of its bound.
    """
    if _PLAUSIBLE(self, prediction, y):
        return True
    bound = np.asarray(self._guard_bound[1])
    out = ~(np.abs(prediction - y) <= bound)
    if out.all():
        return False
    cascade = self._position(self._fallback.probe_cascade, update_heading=False)
    prediction[out] = cascade[out]
    self._guard_trips += 1
    return True


if __name__ == '__main__':
    setattr(AdaptivePredictor, '__init__', _init_keeping_cascade)  # noqa: B010 - the patch
    setattr(AdaptivePredictor, '_plausible', per_dof_plausible)  # noqa: B010 - the patch
    sys.exit(loop_block_probe.probe_main(sys.argv[1:]))
