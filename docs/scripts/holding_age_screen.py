"""Exploratory: the holding balance with an age limit on the held thrust (a screen, no option).

    OMP_NUM_THREADS=1 python docs/scripts/holding_age_screen.py MAX_AGE rao_supply:771 ... \
        [--spread 500 | --moves 10 60] [--k 0]

`dropout_screen.py` with ``dead_reckoning_holding_balance: true`` and `LfOdometry._holding_force`
wrapped: when the group's newest holding sample is more than MAX_AGE seconds older than the
dead reckoning's start (the gate has been open that long: the move is no longer young, its
thrust is no longer only the move's), the current low-passed thrust is kept instead of the held
one. Tests the hypothesis of the fiftieth session's spread failure (rao_supply 824: a thrust
held 100 s earlier, before a turn). Development seeds only.
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
import sys

import numpy as np
from numpy.typing import NDArray

sys.path.insert(0, str(Path(__file__).resolve().parent))
import dropout_screen  # noqa: E402

from lf_predictor_ros.core.odometry import LfOdometry  # noqa: E402


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: MAX_AGE [s] first, then `dropout_screen.py`'s arguments."""
    args = list(sys.argv[1:] if argv is None else argv)
    max_age = float(args.pop(0))
    original = LfOdometry._holding_force  # noqa: SLF001

    def limited(self: LfOdometry, heading: float, dofs: NDArray[np.bool_]) -> NDArray[np.float64]:
        history = self._holding['horizontal']  # noqa: SLF001
        if history and self._t is not None and self._t - history[-1][0] > max_age:  # noqa: SLF001
            assert self._slow_force is not None  # noqa: SLF001
            return self._slow_force.copy()  # noqa: SLF001
        return original(self, heading, dofs)

    LfOdometry._holding_force = limited  # type: ignore[method-assign]  # noqa: SLF001
    return dropout_screen.main([*args, '--odometry', 'dead_reckoning_holding_balance=true'])


if __name__ == '__main__':
    sys.exit(main())
