"""Causal notch + low-pass cascade wave filter as an LF estimator (anchors §4).

The classical DP wave filter (Fossen 2011, §11.3.2; MSS ``notchFilter.m``): the measured pose
runs through the notch at ω0 and a low-pass, sample by sample. It is causal, so it lags the LF
motion by seconds at the controller bandwidth: this is the baseline the learned predictor has to
beat. Heading is unwrapped before filtering so a crossing of ±π is not seen as a 2π step.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lf_predictor_ros.core.estimator import EstimatorStatus, check_ndof
from lf_predictor_ros.core.filters import (
    DEFAULT_LOWPASS_OFFSET,
    DEFAULT_LOWPASS_ORDER,
    DEFAULT_NOTCH_DEPTH,
    DEFAULT_NOTCH_ZETA,
    CausalFilter,
    RetunePlan,
    design_wave_filter,
    plan_retune,
)
from lf_predictor_ros.core.heading import wrap_angle

FloatArray = NDArray[np.float64]
_YAW = 2  # index of heading in a pose


@dataclass(frozen=True)
class CascadePlan:
    """A cascade's coefficients at one ω0, designed ahead of its retuning (`plan_cascade`).

    For a job in another thread or process that finds a new ω0: the design (scipy's pole and
    zero placement, about 0.5 ms) and the coefficients' part of the retuning are done there, not
    on the predict path (issue 13, cost). What it was designed for travels with it, so a plan
    for another filter is refused (`CascadeFilter.set_wave_peak_freq`).
    """

    wave_peak_freq: float  # [rad/s]
    sample_time: float  # [s]
    design: tuple[tuple[str, Any], ...]  # design_wave_filter's keyword arguments, sorted
    retune: RetunePlan


def plan_cascade(wave_peak_freq: float, sample_time: float, *,
                 notch_zeta: float = DEFAULT_NOTCH_ZETA,
                 notch_depth: float = DEFAULT_NOTCH_DEPTH,
                 lowpass_offset: float | None = DEFAULT_LOWPASS_OFFSET,
                 lowpass_order: int = DEFAULT_LOWPASS_ORDER) -> CascadePlan:
    """`CascadePlan` of ``CascadeFilter(…, sample_time, …)`` with these design arguments at ω0."""
    freq, step = float(wave_peak_freq), float(sample_time)
    design = _design_arguments(notch_zeta, notch_depth, lowpass_offset, lowpass_order)
    sos = design_wave_filter(freq, step, **design)
    return CascadePlan(freq, step, tuple(sorted(design.items())), plan_retune(sos))


def _design_arguments(notch_zeta: float, notch_depth: float, lowpass_offset: float | None,
                      lowpass_order: int) -> dict[str, Any]:
    """`design_wave_filter`'s keyword arguments of a cascade (`CascadeFilter`, `plan_cascade`)."""
    return {'notch_zeta': notch_zeta, 'notch_depth': notch_depth,
            'lowpass_offset': lowpass_offset, 'lowpass_order': lowpass_order}


class CascadeFilter:
    """Notch + low-pass wave filter (filters.design_wave_filter) run causally per DOF.

    Implements `LfEstimator`; the force input is ignored. Components beyond `ndof` are 0.
    """

    def __init__(
        self,
        ndof: int,
        sample_time: float,
        wave_peak_freq: float,
        *,
        notch_zeta: float = DEFAULT_NOTCH_ZETA,
        notch_depth: float = DEFAULT_NOTCH_DEPTH,
        lowpass_offset: float | None = DEFAULT_LOWPASS_OFFSET,
        lowpass_order: int = DEFAULT_LOWPASS_ORDER,
    ) -> None:
        """Design the filter for ω0 = wave_peak_freq [rad/s] at sample_time [s].

        ``lowpass_offset=None`` runs the notch alone; ``lowpass_order`` 1 or 2 (default).
        """
        self.ndof = check_ndof(ndof)
        self.sample_time = float(sample_time)
        self._design = _design_arguments(notch_zeta, notch_depth, lowpass_offset, lowpass_order)
        self._wave_peak_freq = float(wave_peak_freq)
        sos = design_wave_filter(self._wave_peak_freq, self.sample_time, **self._design)
        self._filter = CausalFilter(sos, self.ndof)
        self._last_yaw: float | None = None
        self._unwrapped_yaw = 0.0

    @property
    def wave_peak_freq(self) -> float:
        """Current notch frequency ω0 [rad/s]."""
        return self._wave_peak_freq

    def set_wave_peak_freq(self, wave_peak_freq: float, plan: CascadePlan | None = None) -> None:
        """Retune the notch to a new ω0 [rad/s], keeping the output continuous.

        ``plan``: this filter's design at that ω0 made beforehand (`plan_cascade`), the same
        numbers with less work here. ValueError if it was made for another ω0 or filter.
        """
        freq = float(wave_peak_freq)
        if plan is None:
            self._filter.retune(design_wave_filter(freq, self.sample_time, **self._design))
        else:
            wanted = (freq, self.sample_time, tuple(sorted(self._design.items())))
            if (plan.wave_peak_freq, plan.sample_time, plan.design) != wanted:
                raise ValueError(f'a cascade plan for ω0 {plan.wave_peak_freq} rad/s, h '
                                 f'{plan.sample_time} s, {dict(plan.design)} cannot retune this '
                                 f'filter to ω0 {freq} rad/s (h {self.sample_time} s, '
                                 f'{self._design}): plan it with plan_cascade for this filter')
            self._filter.retune(plan.retune)
        self._wave_peak_freq = freq

    def _continuous_yaw(self, yaw: float) -> float:
        """Heading unwrapped against the previous sample (steps below π per sample)."""
        if self._last_yaw is None:
            self._unwrapped_yaw = yaw
        else:
            self._unwrapped_yaw += wrap_angle(float(yaw - self._last_yaw))
        self._last_yaw = yaw
        return self._unwrapped_yaw

    def update(self, t: float, pose: FloatArray, force: FloatArray) -> FloatArray:
        """Filter one measured pose (3,) at time t [s]; return the LF pose estimate (3,)."""
        measured = np.asarray(pose, dtype=np.float64)
        values = measured.tolist()
        if measured.shape != (3,) or not all(map(math.isfinite, values)):
            raise ValueError(f'pose must be 3 finite numbers [north, east, yaw], got {pose}')
        return np.array(self._estimate(self._filter.filter_values(self._channels(values))),
                        dtype=np.float64)

    def update_series(self, poses: FloatArray) -> FloatArray:
        """`update` of every row of ``poses`` (n, 3) in order: the same numbers, as (n, 3).

        A non-finite row raises as `update` does (the rows before it are filtered first).
        """
        measured = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        if not np.all(np.isfinite(measured)):
            return np.array([self.update(0.0, pose, np.zeros(3)) for pose in measured],
                            dtype=np.float64).reshape(-1, 3)
        channels = [self._channels(row) for row in measured.tolist()]
        out = [self._estimate(values) for values in self._filter.filter_rows(channels)]
        return np.array(out, dtype=np.float64).reshape(-1, 3)

    def _channels(self, pose: list[float]) -> list[float]:
        """The filter's input from a measured pose: its DOFs, the heading made continuous."""
        values = pose[: self.ndof]
        if self.ndof == 3:
            values[_YAW] = self._continuous_yaw(pose[_YAW])
        return values

    def _estimate(self, filtered: list[float]) -> list[float]:
        """The LF pose [north, east, yaw] from the filter's output (wrapped; 0: not estimated)."""
        values = filtered + [0.0] * (3 - self.ndof)
        if self.ndof == 3:
            values[_YAW] = wrap_angle(float(values[_YAW]))
        return values

    def reset(self) -> None:
        """Forget the filter state and heading history."""
        self._filter.reset()
        self._last_yaw = None
        self._unwrapped_yaw = 0.0

    def status(self) -> EstimatorStatus:
        """Always 'ok' with the notch frequency in use."""
        return EstimatorStatus(
            state='ok',
            wave_peak_freq=self._wave_peak_freq,
            message=f'notch + low-pass cascade at {self._wave_peak_freq:.3f} rad/s',
        )
