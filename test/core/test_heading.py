"""Heading continuity across ±π: wrap, batch unwrap, streaming unwrap, pose helpers."""
from __future__ import annotations

import math

from hypothesis import given
from hypothesis import strategies as st
import numpy as np
from numpy.typing import NDArray
import pytest

from lf_predictor_ros.core.heading import (
    ContinuousHeading,
    unwrap_heading,
    unwrap_pose_series,
    unwrap_step,
    wrap_angle,
    wrap_pose,
)


def crossing_heading(n: int = 6000, sample_time: float = 0.5) -> NDArray[np.float64]:
    """True heading oscillating around π (crosses ±π often) while drifting over 3 turns."""
    t = np.arange(n) * sample_time
    rng = np.random.default_rng(3)
    heading = (math.pi + 0.4 * np.sin(0.7 * t) + 6.0 * math.pi * t / t[-1]
               + 0.01 * rng.standard_normal(n))
    return np.asarray(heading, dtype=np.float64)


def test_wrap_angle_values() -> None:
    assert wrap_angle(math.pi) == math.pi
    assert wrap_angle(-math.pi) == math.pi
    assert wrap_angle(3.0 * math.pi) == pytest.approx(math.pi)
    assert wrap_angle(0.0) == 0.0
    assert wrap_angle(7.0) == pytest.approx(7.0 - 2.0 * math.pi)
    assert wrap_angle(-4.0) == pytest.approx(2.0 * math.pi - 4.0)
    assert isinstance(wrap_angle(1.0), float)
    arr = wrap_angle(np.array([-math.pi, 0.5, 2.0 * math.pi + 0.25, np.nan]))
    np.testing.assert_allclose(arr[:3], [math.pi, 0.5, 0.25], atol=1e-12)
    assert math.isnan(arr[3])
    # the largest double below −π must not land on −π through rounding
    just_below = np.nextafter(-math.pi, -4.0)
    assert wrap_angle(just_below) == pytest.approx(math.pi)
    assert -math.pi < wrap_angle(-1e-17) <= math.pi


@given(st.floats(min_value=-1e4, max_value=1e4, allow_nan=False))
def test_wrap_angle_range_and_equivalence(angle: float) -> None:
    wrapped = wrap_angle(angle)
    assert -math.pi < wrapped <= math.pi
    turns = (angle - wrapped) / (2.0 * math.pi)
    assert abs(turns - round(turns)) < 1e-9


def test_unwrap_crossing_series_is_continuous_and_rewraps() -> None:
    truth = crossing_heading()
    wrapped = wrap_angle(truth)
    assert np.count_nonzero(np.abs(np.diff(wrapped)) > math.pi) >= 20  # really crosses ±π
    unwrapped = unwrap_heading(wrapped)
    assert np.max(np.abs(np.diff(unwrapped))) < 0.5  # largest true step ≈ 0.14 + noise
    offset = truth - unwrapped  # a constant multiple of 2π
    np.testing.assert_allclose(offset, offset[0], atol=1e-9)
    assert offset[0] / (2.0 * math.pi) == pytest.approx(round(offset[0] / (2.0 * math.pi)))
    np.testing.assert_allclose(wrap_angle(unwrapped), wrapped, atol=1e-12)


def test_streaming_matches_batch_and_skips_dropouts() -> None:
    wrapped = wrap_angle(crossing_heading(2000))
    wrapped[[50, 51, 52, 700]] = np.nan
    batch = unwrap_heading(wrapped)
    heading = ContinuousHeading()
    assert heading.value is None
    stream = np.array([heading.update(a) for a in wrapped])
    np.testing.assert_allclose(stream, batch, atol=1e-12, equal_nan=True)
    valid = batch[~np.isnan(batch)]
    assert np.max(np.abs(np.diff(valid))) < 0.5
    heading.reset()
    assert heading.update(3.0) == 3.0


def test_unwrap_step() -> None:
    assert unwrap_step(None, 3.0) == 3.0
    assert unwrap_step(3.1, -3.1) == pytest.approx(2.0 * math.pi - 3.1)
    assert unwrap_step(4.0 * math.pi + 3.1, -3.1) == pytest.approx(6.0 * math.pi - 3.1)
    assert math.isnan(unwrap_step(1.0, math.nan))


def test_pose_helpers_touch_only_yaw_and_only_for_3_dof() -> None:
    wrapped = wrap_angle(crossing_heading(500))
    poses = np.column_stack([np.linspace(0, 10, 500), np.linspace(-5, 5, 500), wrapped])
    original = poses.copy()
    three = unwrap_pose_series(poses, 3)
    np.testing.assert_array_equal(poses, original)  # input untouched
    np.testing.assert_array_equal(three[:, :2], poses[:, :2])
    np.testing.assert_allclose(three[:, 2], unwrap_heading(wrapped))
    np.testing.assert_array_equal(unwrap_pose_series(poses, 1), poses)
    np.testing.assert_allclose(wrap_pose(three, 3), poses, atol=1e-12)
    single = wrap_pose(np.array([1.0, 2.0, 3.0 * math.pi]), 3)
    np.testing.assert_allclose(single, [1.0, 2.0, math.pi])
    np.testing.assert_array_equal(wrap_pose(np.array([1.0, 2.0, 7.0]), 1), [1.0, 2.0, 7.0])
    heading = ContinuousHeading()
    heading.update_pose(np.array([0.0, 0.0, 3.1]), 3)
    pose = np.array([1.0, 1.0, -3.1])
    assert heading.update_pose(pose, 3)[2] == pytest.approx(2.0 * math.pi - 3.1)
    assert pose[2] == -3.1
    with pytest.raises(ValueError, match='ndof must be 1 or 3'):
        unwrap_pose_series(poses, 2)
    with pytest.raises(ValueError, match='north, east, yaw'):
        unwrap_pose_series(poses[:, :2], 3)
