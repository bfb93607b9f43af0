"""Heading continuity across ±π: wrapping, batch and streaming unwrapping.

Filters, spectra and networks need a continuous heading, the outside world wants (−π, π]
(docs/ARCHITECTURE.md: algorithms unwrap internally, outputs are wrapped). A pose is
``[north m, east m, yaw rad]``; only the yaw column (index 2) is touched, and only when
``ndof == 3`` (for 1-DOF the pose holds surge only). NaN samples (sensor dropouts) are left in
place and do not break the continuity of the samples around them.
"""
from __future__ import annotations

import math
from typing import overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

YAW_INDEX = 2  # yaw column of a pose [north, east, yaw]
TWO_PI = 2.0 * math.pi  # rad

_FloatArray = NDArray[np.float64]


@overload
def wrap_angle(angle: float) -> float: ...


@overload
def wrap_angle(angle: NDArray[np.floating]) -> _FloatArray: ...


def wrap_angle(angle: float | NDArray[np.floating]) -> float | _FloatArray:
    """Wrap angle(s) [rad] to (−π, π]; π and −π both map to π. Vectorized, NaN stays NaN."""
    if isinstance(angle, (float, int)):  # one number: the same arithmetic without numpy's
        wrapped_one = math.pi - (math.pi - angle) % TWO_PI  # overhead (per-sample paths)
        return wrapped_one + TWO_PI if wrapped_one <= -math.pi else wrapped_one
    values = np.asarray(angle, dtype=np.float64)
    wrapped = math.pi - np.mod(math.pi - values, TWO_PI)
    # np.mod may round a tiny negative argument up to exactly 2π, which would give −π.
    wrapped = np.where(wrapped <= -math.pi, wrapped + TWO_PI, wrapped)
    if np.ndim(angle) == 0:
        return float(wrapped)
    return np.asarray(wrapped, dtype=np.float64)


def unwrap_heading(series: ArrayLike) -> _FloatArray:
    """Unwrap a heading series [rad] along axis 0 so no step between valid samples exceeds π.

    The first valid sample keeps its value; NaN samples stay NaN and are skipped. Returns a new
    array (the input is not modified).
    """
    values = np.array(series, dtype=np.float64)  # copy
    if values.ndim == 1:
        return _unwrap_column(values)
    for column in range(values.shape[1]):
        values[:, column] = _unwrap_column(values[:, column])
    return values


def unwrap_step(previous: float | None, wrapped: float) -> float:
    """One streaming unwrap step: the angle equal to ``wrapped`` modulo 2π nearest ``previous``.

    With no previous value (or a NaN one) the wrapped value is returned as it is.
    """
    if math.isnan(wrapped) or previous is None or math.isnan(previous):
        return float(wrapped)
    return previous + wrap_angle(wrapped - previous)


class ContinuousHeading:
    """Streaming unwrapper: feed wrapped headings sample by sample, get a continuous heading."""

    def __init__(self) -> None:
        """Start without history; the first valid heading is taken as it is."""
        self._last: float | None = None

    @property
    def value(self) -> float | None:
        """The last continuous heading [rad], None before the first valid sample."""
        return self._last

    def update(self, wrapped: float) -> float:
        """Continuous heading [rad] for the new heading sample; NaN returns NaN, keeps state."""
        unwrapped = unwrap_step(self._last, float(wrapped))
        if not math.isnan(unwrapped):
            self._last = unwrapped
        return unwrapped

    def update_pose(self, pose: ArrayLike, ndof: int) -> _FloatArray:
        """Copy of ``pose`` with its yaw made continuous (only for ``ndof == 3``)."""
        out = np.array(pose, dtype=np.float64)
        if _has_yaw(out, ndof):
            out[..., YAW_INDEX] = self.update(float(out[..., YAW_INDEX]))
        return out

    def reset(self) -> None:
        """Forget the history (e.g. after a long dropout)."""
        self._last = None


def unwrap_pose_series(poses: ArrayLike, ndof: int) -> _FloatArray:
    """Copy of a pose series (n, ≥3) with the yaw column unwrapped when ``ndof == 3``."""
    out = np.array(poses, dtype=np.float64)
    if _has_yaw(out, ndof):
        out[:, YAW_INDEX] = _unwrap_column(out[:, YAW_INDEX])
    return out


def wrap_pose(poses: ArrayLike, ndof: int) -> _FloatArray:
    """Copy of a pose (3,) or pose series (n, 3) with yaw wrapped to (−π, π] when ``ndof == 3``."""
    out = np.array(poses, dtype=np.float64)
    if _has_yaw(out, ndof):
        if out.ndim == 1:  # one pose: the scalar wrap (the same arithmetic, less overhead)
            out[YAW_INDEX] = wrap_angle(float(out[YAW_INDEX]))
        else:
            out[..., YAW_INDEX] = wrap_angle(out[..., YAW_INDEX])
    return out


def _has_yaw(poses: _FloatArray, ndof: int) -> bool:
    """Whether the yaw column must be handled; ValueError on a bad ndof or a short pose."""
    if ndof not in (1, 3):
        raise ValueError(f'ndof must be 1 or 3, got {ndof!r}')
    if ndof == 1:
        return False
    if poses.ndim == 0 or poses.shape[-1] <= YAW_INDEX:
        raise ValueError(f'a 3-DOF pose needs [north, east, yaw] in its last axis, got shape '
                         f'{poses.shape}: pass the full pose')
    return True


def _unwrap_column(column: _FloatArray) -> _FloatArray:
    """Unwrap one 1-D series, skipping NaN samples (returns a new array)."""
    out = np.array(column, dtype=np.float64)
    valid = ~np.isnan(out)
    out[valid] = np.unwrap(out[valid])
    return out
