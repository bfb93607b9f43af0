"""Zero-phase offline smoother: the non-causal reference (thesis §4.2.2).

Filters a whole recorded series at once, forward and backward, with the notch + low-pass wave
filter at a given ω0 (`filters.zero_phase`). No lag, but it needs the future: it is the upper
bound a causal estimator can approach, and what the thesis uses to make training targets. Its
error grows near both ends of the series (edge transients, thesis Fig. 4.9).
"""
from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lf_predictor_ros.core.estimator import EstimatorStatus, check_ndof
from lf_predictor_ros.core.filters import (
    DEFAULT_LOWPASS_OFFSET,
    DEFAULT_LOWPASS_ORDER,
    DEFAULT_NOTCH_DEPTH,
    DEFAULT_NOTCH_ZETA,
    design_wave_filter,
    zero_phase,
)
from lf_predictor_ros.core.heading import wrap_angle

FloatArray = NDArray[np.float64]
_YAW = 2  # index of heading in a pose


def smooth_poses(
    pose: ArrayLike,
    sample_time: float,
    wave_peak_freq: float,
    ndof: int,
    *,
    notch_zeta: float = DEFAULT_NOTCH_ZETA,
    notch_depth: float = DEFAULT_NOTCH_DEPTH,
    lowpass_offset: float | None = DEFAULT_LOWPASS_OFFSET,
    lowpass_order: int = DEFAULT_LOWPASS_ORDER,
) -> FloatArray:
    """Zero-phase wave filtering of a pose series (n, 3); heading unwrapped, result wrapped.

    Components beyond ndof are 0. The input is not modified. ``lowpass_offset=None``: the notch
    alone; ``lowpass_order``: 1 or 2 (`filters.design_wave_filter`).
    """
    check_ndof(ndof)
    series = np.asarray(pose, dtype=np.float64)
    if series.ndim != 2 or series.shape[1] != 3:
        raise ValueError(f'pose must have shape (n, 3), got {series.shape}')
    sos = design_wave_filter(
        wave_peak_freq,
        sample_time,
        notch_zeta=notch_zeta,
        notch_depth=notch_depth,
        lowpass_offset=lowpass_offset,
        lowpass_order=lowpass_order,
    )
    channels = series[:, :ndof].copy()
    if ndof == 3:
        channels[:, _YAW] = np.unwrap(channels[:, _YAW])
    out = np.zeros_like(series)
    out[:, :ndof] = zero_phase(channels, sos)
    if ndof == 3:
        out[:, _YAW] = wrap_angle(out[:, _YAW])
    return out


class ZeroPhaseSmoother:
    """An `LfEstimator` facade over `smooth_poses` given the full series in advance.

    `update(t, ...)` returns the smoothed pose at the recorded sample nearest to t; the pose and
    force arguments are ignored (the smoother already saw the whole series). For evaluation only.
    """

    def __init__(
        self,
        t: ArrayLike,
        pose: ArrayLike,
        wave_peak_freq: float,
        ndof: int,
        **filter_options: Any,
    ) -> None:
        """Smooth pose (n, 3) sampled at times t (n,) [s] with the notch at ω0 [rad/s]."""
        times = np.asarray(t, dtype=np.float64)
        if times.ndim != 1 or times.size < 2 or np.any(np.diff(times) <= 0.0):
            raise ValueError('t must be a strictly increasing 1-D array with >= 2 samples')
        self.ndof = check_ndof(ndof)
        self.sample_time = float(np.median(np.diff(times)))
        self._t = times.copy()
        self._wave_peak_freq = float(wave_peak_freq)
        self._smoothed = smooth_poses(
            pose, self.sample_time, wave_peak_freq, ndof, **filter_options
        )

    @property
    def smoothed(self) -> FloatArray:
        """The whole smoothed series (n, 3) (a copy)."""
        return self._smoothed.copy()

    def update(self, t: float, pose: FloatArray, force: FloatArray) -> FloatArray:
        """Smoothed pose (3,) at the recorded sample nearest to t [s]."""
        index = int(np.clip(np.searchsorted(self._t, t), 1, self._t.size - 1))
        if abs(self._t[index - 1] - t) <= abs(self._t[index] - t):
            index -= 1
        return np.array(self._smoothed[index], dtype=np.float64)

    def reset(self) -> None:
        """Nothing to forget: the smoothed series is fixed."""

    def status(self) -> EstimatorStatus:
        """Always 'ok'."""
        return EstimatorStatus(
            state='ok',
            wave_peak_freq=self._wave_peak_freq,
            message=f'zero-phase smoother at {self._wave_peak_freq:.3f} rad/s (non-causal)',
        )
