"""Exploratory: the motion gate also opens on the thrust's LF change (the larger of two gains).

    OMP_NUM_THREADS=1 python docs/scripts/thrust_gate_precheck.py --scenarios rao_supply \
        --seeds 361 362 363 364 --closed-loop --loops-only --variant "tgate="

`method_probe.py` with three functions patched in this process only (nothing in the package
changes). The predictor's `_gated` leaves the sample's thrust in the earth frame
(`AdaptivePredictor._force_channels`: north, east, yaw moment) for its gate, and
`MotionGate.update` runs a second gate with the same constants on that thrust: its 'velocity' is
the thrust's change per sample low-passed over the gate's time (10 s), compared with its median
over the window. The published gain per DOF is the larger of the two. The idea: in a setpoint
move the DP controller's thrust changes at once, before the vessel has moved far enough for the
twin's velocity to open the gate (about 24 s on rao_supply, thirty-second session), while the
swell's wave groups, which a faster velocity gate opens on, move the thrust mostly in the wave
band, which the low-pass takes out. `THRUST_GATE_TIME` (s, default: the gate's own) sets the
second gate's low-pass. Every variant of the run gets the patched gate (run the default rows from
another process). Development seeds only, as `method_probe.py`. docs/BENCHMARKS.md,
thirty-fourth session.
"""
from __future__ import annotations

import os
from pathlib import Path
import sys
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import method_probe  # noqa: E402 - the sibling script

import lf_predictor_ros.core.motion_gate as motion_gate  # noqa: E402
import lf_predictor_ros.core.predictor as predictor  # noqa: E402

_THRUST: dict[str, Any] = {}
_gated = predictor.AdaptivePredictor._gated
_update = motion_gate.MotionGate.update
_restart = motion_gate.MotionGate.restart
TIME = float(os.environ.get('THRUST_GATE_TIME', '0'))  # [s] 0: the velocity gate's own


def _keeping_thrust(self: Any, t: float, out: Any, pose: Any, force: Any) -> Any:
    _THRUST['force'] = self._force_channels(np.asarray(force, dtype=np.float64),
                                            float(pose[2]))
    return _gated(self, t, out, pose, force)


def _thrust_gate(gate: motion_gate.MotionGate) -> motion_gate.MotionGate:
    """The second gate of ``gate`` (created at first use; the predictor's h is 1 s here)."""
    second = getattr(gate, '_thrust_gate', None)
    if second is None:
        time_constant = TIME if TIME > 0.0 else 1.0 / gate._alpha
        second = motion_gate.MotionGate(gate.ndof, 1.0, time_constant=time_constant,
                                        window=float(gate._squares.shape[0]), ratio=gate.ratio)
        setattr(gate, '_thrust_gate', second)  # noqa: B010 - an attribute of this probe only
    return second


def _both_gates(self: motion_gate.MotionGate, moving: Any) -> Any:
    gain = _update(self, moving)
    force = _THRUST.pop('force', None)
    if force is None:
        return gain
    return np.maximum(gain, _update(_thrust_gate(self), force[:self.ndof]))


def _restart_both(self: motion_gate.MotionGate) -> None:
    _restart(self)
    second = getattr(self, '_thrust_gate', None)
    if second is not None:
        _restart(second)


if __name__ == '__main__':
    setattr(predictor.AdaptivePredictor, '_gated', _keeping_thrust)  # noqa: B010
    setattr(motion_gate.MotionGate, 'update', _both_gates)  # noqa: B010
    setattr(motion_gate.MotionGate, 'restart', _restart_both)  # noqa: B010
    sys.exit(method_probe.main(sys.argv[1:]))
