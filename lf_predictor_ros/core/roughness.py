"""Roughness guard: an LF estimate is smoother than the measurement it filters (issue 13).

A low-frequency estimate moves with the vessel's LF motion and a little residual wave motion; the
measured pose carries the whole wave motion. So the estimate's second differences are much
smaller than the measurement's (≈ 0.1× in normal operation at ω0 h ≈ 0.8). A network with the
thrust among its regressors can, in a DP loop, close a limit cycle with the controller's D term:
its estimate alternates sign every sample, the thrust answers, and the network turns the thrust
into the next jump (docs/BENCHMARKS.md, "Eighteenth session": ±1.2 m per sample on a 1-DOF
vessel whose LF speed was 0.02 m/s). Its second differences are then larger than the
measurement's: not an LF estimate.

`RoughnessGuard` keeps, per DOF, exponentially weighted means (weight ``alpha`` per sample, i.e.
time constant h / alpha) of the squared second differences of the prediction and of the
measurement; ``update`` returns true while the prediction's exceeds ``ratio`` (default
`ROUGHNESS_RATIO`) times the measurement's in any DOF. Why 50 and not 1: on a swell measured as
1 s interval means the adaptive estimate is normally rougher than the measurement (median ratio
1.1–2.6, max 14 on rao_swell development seed 1), while the limit cycle reaches 100–400
(docs/BENCHMARKS.md, "Eighteenth session").
Heading differences are wrapped. A missing prediction (None) forgets the prediction's history
(the next three predictions start it again); a non-finite value is skipped.
"""
from __future__ import annotations

from collections import deque
import math

import numpy as np
from numpy.typing import NDArray

from lf_predictor_ros.core.heading import wrap_angle

FloatArray = NDArray[np.float64]
ROUGHNESS_RATIO = 50.0  # [-] mean-square ratio, prediction / measurement, that trips the guard


class _SecondDifference:
    """Running EWMA of the squared second difference of one pose stream.

    Plain floats, per DOF: the same IEEE operations as the array form, without numpy's per-call
    cost on the per-sample path (`AdaptivePredictor.update`).
    """

    def __init__(self, ndof: int, alpha: float) -> None:
        self.ndof, self.alpha = ndof, alpha
        self.history: deque[list[float]] = deque(maxlen=3)
        self.mean_square: list[float] | None = None

    def clear(self) -> None:
        self.history.clear()
        self.mean_square = None

    def add(self, pose: list[float]) -> None:
        self.history.append(pose[:self.ndof])
        if len(self.history) < 3:
            return
        a, b, c = self.history
        second = [(c_i - b_i) - (b_i - a_i) for a_i, b_i, c_i in zip(a, b, c, strict=True)]
        if self.ndof == 3:
            second[2] = wrap_angle(c[2] - b[2]) - wrap_angle(b[2] - a[2])
        square = [d * d for d in second]
        mean = self.mean_square
        alpha = self.alpha
        self.mean_square = square if mean is None else \
            [m + alpha * (s - m) for m, s in zip(mean, square, strict=True)]


class RoughnessGuard:
    """Is the network's prediction rougher than the measurement? (module docstring)."""

    def __init__(self, ndof: int, sample_time: float, time_constant: float,
                 ratio: float = ROUGHNESS_RATIO) -> None:
        """``time_constant`` T [s] > sample_time [s] > 0: EWMA weight alpha = h / T; ratio > 0."""
        if not (sample_time > 0.0 and time_constant > sample_time):
            raise ValueError(f'roughness guard needs time_constant > sample_time > 0 s, got '
                             f'{time_constant} and {sample_time}')
        if not ratio > 0.0:
            raise ValueError(f'roughness guard ratio must be > 0, got {ratio}')
        self.ratio = float(ratio)
        alpha = sample_time / time_constant
        self._measured = _SecondDifference(ndof, alpha)
        self._predicted = _SecondDifference(ndof, alpha)

    def reset(self) -> None:
        """Forget both histories."""
        self._measured.clear()
        self._predicted.clear()

    def update(self, measured: FloatArray, predicted: FloatArray | None) -> bool:
        """Add one sample; True while the prediction is ``ratio`` × rougher than measured."""
        measured_values = np.asarray(measured, dtype=np.float64).tolist()
        if all(map(math.isfinite, measured_values)):
            self._measured.add(measured_values)
        if predicted is None:
            self._predicted.clear()
            return False
        predicted_values = np.asarray(predicted, dtype=np.float64).tolist()
        if all(map(math.isfinite, predicted_values)):
            self._predicted.add(predicted_values)
        ref, own = self._measured.mean_square, self._predicted.mean_square
        if ref is None or own is None:
            return False
        ratio = self.ratio
        return any(o > ratio * r for o, r in zip(own, ref, strict=True))
