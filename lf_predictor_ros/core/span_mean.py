"""The running mean of a stamped vector series over a time span (a boxcar; O(1) per sample).

Over one wave period 2π/ω0 the boxcar has a zero of its frequency response at ω0 (and at
its multiples), so the mean of a velocity over one period keeps the LF part and drops the
wave-band part at the peak frequency with a lag of half a period. The odometry uses it for the
twist a dead reckoning starts from and for the motion gate (``OdometryParams``'s
``dead_reckoning_moving_twist_start`` and ``dead_reckoning_moving_gate_averaged``).
"""
from __future__ import annotations

from collections import deque
import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


class SpanMean:
    """The mean of the samples stamped within ``span`` of the newest (see the module docstring).

    A sample stamped t is in the window of the newest stamp t_n when t > t_n − span + h/2 (h
    the sample time), so a uniform series at h holds span / h samples. The mean is given only
    once a sample older than the window was dropped (the window reaches back over the whole
    span); a new span takes effect at the next sample (a longer one fills within one span).
    """

    def __init__(self, sample_time: float) -> None:
        """Create for samples about ``sample_time`` [s] apart (the half-sample tolerance)."""
        if not (math.isfinite(sample_time) and sample_time > 0.0):
            raise ValueError(f'sample_time must be a finite time > 0 [s], got {sample_time}')
        self.sample_time = sample_time
        self.clear()

    def clear(self) -> None:
        """Forget every sample."""
        self._samples: deque[tuple[float, FloatArray]] = deque()
        self._sum: FloatArray | None = None
        self._reached = False

    def add(self, stamp: float, value: FloatArray, span: float | None) -> None:
        """A new sample (stamps increasing) and the span [s] it ends; None: off (cleared)."""
        if span is None:
            if self._sum is not None:
                self.clear()
            return
        if not (math.isfinite(span) and span > 0.0):
            raise ValueError(f'span must be None or a finite time > 0 [s], got {span}')
        sample = np.array(value, dtype=np.float64)
        if self._sum is None or self._sum.shape != sample.shape:
            self.clear()
            self._sum = np.zeros_like(sample)
        self._samples.append((stamp, sample))
        self._sum = self._sum + sample
        oldest = stamp - span + 0.5 * self.sample_time
        while len(self._samples) > 1 and self._samples[0][0] < oldest:  # the newest stays
            _, dropped = self._samples.popleft()
            self._sum = self._sum - dropped
            self._reached = True
        if len(self._samples) == 1:  # everything else dropped: no rounding carried over
            self._sum = sample.copy()

    def mean(self) -> FloatArray | None:
        """The mean over the window (a new array), None until it reaches back over the span."""
        if not self._reached or self._sum is None or not self._samples:
            return None
        return self._sum / len(self._samples)
