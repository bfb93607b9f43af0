"""Exploratory: the network's north/east thrust inputs held at their value while the vessel turns.

    OMP_NUM_THREADS=1 python docs/scripts/turn_thrust_hold_probe.py --scenarios rao_supply \
        --seeds 671 672 --closed-loop --loops-only --variant "th="
    OMP_NUM_THREADS=1 python docs/scripts/turn_thrust_hold_probe.py --blocks rao_supply 675 \
        default 1130 1260 --block 4 --bias --rate

`method_probe.py` (or, with ``--blocks`` first, `loop_block_probe.py`) with, in this process
only (nothing in the package changes), `AdaptivePredictor`'s prediction fed a held north/east
thrust while the measured heading turns. Why (docs/BENCHMARKS.md, forty-fourth session): in
rao_supply's 45° turn the per-DOF network's north/east estimates drift 0.2–0.4 m off the still
vessel, which they do not without thrust inputs (``nu`` 0); the guard then hands all DOFs to the
cascade and the jump kicks the PID's D term, and the vessel leaves its track by about 4 m.

The patch: the measured heading (unwrapped, one sample per h) gives a turn rate r̂, the mean of
its newest ``TURN_MEAN`` samples minus the mean of those ``TURN_SPAN`` samples before, over
``TURN_SPAN`` h. While |r̂| > ``TURN_RATE`` rad/s, and for ``TURN_HANGOVER`` s after, the thrust
rows the prediction reads that were appended since the turn was detected carry, in the earth-
frame north and east channels, the row before the detection (the yaw moment is not held: the
heading row follows the turn through it). The training buffer keeps the true thrust. The twin of
the motion gate is an `AdaptivePredictor` too and gets the same hold. Environment variables set
the constants. Every variant of the run gets the patch (run the rows without it from another
process). Development seeds only, as `method_probe.py`.
"""
from __future__ import annotations

from collections import deque
import os
from pathlib import Path
import sys
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import loop_block_probe  # noqa: E402 - the sibling script

from lf_predictor_ros.core.heading import ContinuousHeading  # noqa: E402
from lf_predictor_ros.core.predictor import AdaptivePredictor  # noqa: E402

TURN_RATE = float(os.environ.get('TURN_RATE', '0.005'))  # [rad/s]
TURN_SPAN = int(os.environ.get('TURN_SPAN', '10'))  # [samples]
TURN_MEAN = int(os.environ.get('TURN_MEAN', '5'))  # [samples]
TURN_HANGOVER = float(os.environ.get('TURN_HANGOVER', '30'))  # [s]
HELD_CHANNELS = (0, 1)  # earth-frame north and east thrust

_FORCE_CHANNELS = AdaptivePredictor._force_channels
_PREDICT_WITH = AdaptivePredictor._predict_with


def _force_channels_tracking_turns(self: Any, force: np.ndarray, yaw: float) -> np.ndarray:
    """The shipped channels; the turn state (module docstring) advanced by this sample."""
    u: np.ndarray = _FORCE_CHANNELS(self, force, yaw)
    if self.ndof != 3:
        return u
    if not hasattr(self, 'probe_heading'):
        self.probe_heading = deque(maxlen=TURN_SPAN + TURN_MEAN)
        self.probe_unwrap = ContinuousHeading()
        self.probe_hold_left = 0
        self.probe_held = None  # the held row (north/east thrust), None: no turn
        self.probe_held_rows = 0
        self.probe_last_u = None  # the previous sample's channels
        self.probe_turn_samples = 0
    headings = self.probe_heading
    headings.append(self.probe_unwrap.update(yaw))
    turning = False
    if len(headings) == headings.maxlen:
        values = np.asarray(headings)
        rate = (values[-TURN_MEAN:].mean() - values[:TURN_MEAN].mean()) / (
            TURN_SPAN * self.params.sample_time)
        turning = abs(rate) > TURN_RATE
    if turning:
        if self.probe_held is None and self.probe_last_u is not None:
            self.probe_held = self.probe_last_u.copy()
            self.probe_held_rows = 0
        self.probe_hold_left = int(round(TURN_HANGOVER / self.params.sample_time))
        self.probe_turn_samples += 1
    elif self.probe_hold_left > 0:
        self.probe_hold_left -= 1
    else:
        self.probe_held = None
    if self.probe_held is not None:
        self.probe_held_rows += 1
    self.probe_last_u = u
    return u


class _HeldThrustRows:
    """The predictor's thrust rows as its prediction reads them: the held rows replaced."""

    def __init__(self, rows: Any, held: np.ndarray, held_rows: int) -> None:
        self._rows, self._held, self._held_rows = rows, held, held_rows

    def __len__(self) -> int:
        return len(self._rows)

    def newest(self, count: int) -> np.ndarray:
        """The package's newest rows, a copy with the held channels of the held rows set."""
        rows = np.array(self._rows.newest(count))
        n = min(self._held_rows, rows.shape[0])
        if n > 0:
            rows[-n:, HELD_CHANNELS] = self._held[list(HELD_CHANNELS)]
        return rows


def predict_with_held_thrust(self: Any, model: Any) -> np.ndarray | None:
    """The package's `_predict_with` over the thrust rows with the held ones replaced."""
    held = getattr(self, 'probe_held', None)
    if held is None:
        return _PREDICT_WITH(self, model)
    rows = self._u
    self._u = _HeldThrustRows(rows, held, self.probe_held_rows)
    try:
        result: np.ndarray | None = _PREDICT_WITH(self, model)
    finally:
        self._u = rows  # the training buffer keeps the true thrust
    return result

if __name__ == '__main__':
    setattr(AdaptivePredictor, '_force_channels',  # noqa: B010 - the patch
            _force_channels_tracking_turns)
    setattr(AdaptivePredictor, '_predict_with', predict_with_held_thrust)  # noqa: B010
    print(f'# turn thrust hold: TURN_RATE {TURN_RATE} rad/s, TURN_SPAN {TURN_SPAN}, '
          f'TURN_MEAN {TURN_MEAN}, TURN_HANGOVER {TURN_HANGOVER} s', flush=True)
    sys.exit(loop_block_probe.probe_main(sys.argv[1:]))
