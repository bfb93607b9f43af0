"""InputAligner: resampling onto the grid and the documented behaviour for bad input."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lf_predictor_ros.core.alignment import (
    AlignerSettings,
    InputAligner,
    block_mean_poses,
    mean_pose,
)


def _feed(aligner: InputAligner, times: np.ndarray, poses: np.ndarray) -> list:
    out = []
    for t, p in zip(times, poses, strict=True):
        out.extend(aligner.add_pose(float(t), p))
    return out


def test_resamples_10hz_ramp_to_2hz_grid_exactly() -> None:
    aligner = InputAligner(AlignerSettings(sample_time=0.5, average_poses=False))
    t = np.arange(0.03, 20.0, 0.1)
    poses = np.stack([2.0 * t, -t, 0.01 * t], axis=1)  # a ramp interpolates exactly
    out = _feed(aligner, t, poses)
    grid = np.array([s.t for s in out])
    np.testing.assert_allclose(grid, np.arange(0.5, 20.0, 0.5), atol=1e-12)
    got = np.array([s.pose for s in out])
    np.testing.assert_allclose(got, np.stack([2 * grid, -grid, 0.01 * grid], axis=1), atol=1e-9)
    assert out[0].segment_start and not any(s.segment_start for s in out[1:])


def test_average_is_the_interval_mean_of_a_faster_sensor() -> None:
    aligner = InputAligner(AlignerSettings(sample_time=0.5))
    t = np.arange(0.03, 20.0, 0.1)
    poses = np.stack([2.0 * t, -t, 0.01 * t], axis=1)
    out = _feed(aligner, t, poses)
    grid = np.array([s.t for s in out])
    np.testing.assert_allclose(grid, np.arange(0.5, 20.0, 0.5), atol=1e-12)
    # the five poses in (t_k − 0.5, t_k] are stamped t_k − 0.47 … t_k − 0.07: mean t_k − 0.27
    mean_t = grid - 0.27
    got = np.array([s.pose for s in out])
    np.testing.assert_allclose(got, np.stack([2 * mean_t, -mean_t, 0.01 * mean_t], axis=1),
                               atol=1e-9)


def test_average_divides_white_noise_by_root_of_block_size() -> None:
    rng = np.random.default_rng(3)
    t = np.arange(0.1, 2000.0 + 1e-9, 0.1)  # 10 poses per 1 s grid interval
    noise = np.zeros((t.size, 3))
    noise[:, 0] = rng.normal(0.0, 1.0, t.size)
    out = _feed(InputAligner(AlignerSettings(sample_time=1.0)), t, noise)
    std = np.std([s.pose[0] for s in out])
    assert std == pytest.approx(1.0 / math.sqrt(10.0), rel=0.05)
    picked = _feed(InputAligner(AlignerSettings(sample_time=1.0, average_poses=False)), t, noise)
    assert np.std([s.pose[0] for s in picked]) == pytest.approx(1.0, rel=0.05)


def test_block_mean_poses_equals_the_aligner_on_a_regular_grid() -> None:
    rng = np.random.default_rng(4)
    t = np.arange(1, 201) * 0.1  # 0.1 … 20.0 s; grid points every 10th sample
    poses = np.cumsum(rng.normal(0.0, 0.1, (t.size, 3)), axis=0)
    poses[:, 2] = np.remainder(poses[:, 2] + 3.0 + math.pi, 2 * math.pi) - math.pi  # near ±π
    out = _feed(InputAligner(AlignerSettings(sample_time=1.0)), t, poses)
    blocks = block_mean_poses(poses, 10)
    np.testing.assert_allclose(np.array([s.pose for s in out]), blocks, atol=1e-12)


def test_mean_pose_averages_heading_across_pi() -> None:
    pose = mean_pose(np.array([[0.0, 2.0, math.pi - 0.1], [2.0, 4.0, -math.pi + 0.3]]))
    np.testing.assert_allclose(pose, [1.0, 3.0, -math.pi + 0.1], atol=1e-12)
    with pytest.raises(ValueError, match='shape'):
        mean_pose(np.zeros((0, 3)))


def test_heading_interpolates_along_shortest_arc_across_pi() -> None:
    aligner = InputAligner(AlignerSettings(sample_time=0.5))
    aligner.add_pose(0.0, [0.0, 0.0, math.pi - 0.1])
    (sample,) = aligner.add_pose(1.0, [0.0, 0.0, -math.pi + 0.1])[-1:]
    assert sample.t == pytest.approx(1.0)
    mid = InputAligner(AlignerSettings(sample_time=0.5))
    mid.add_pose(0.25, [0.0, 0.0, math.pi - 0.1])
    (half,) = mid.add_pose(0.75, [0.0, 0.0, -math.pi + 0.1])
    assert abs(abs(half.pose[2]) - math.pi) < 1e-9  # through ±π, not through 0


def test_thrust_zero_order_hold_and_staleness() -> None:
    aligner = InputAligner(AlignerSettings(sample_time=1.0, thrust_timeout=2.5))
    aligner.add_force(0.2, [100.0, 0.0, 0.0])
    aligner.add_force(1.7, [200.0, 0.0, 0.0])
    aligner.add_force(3.05, [300.0, 0.0, 0.0])  # arrives before the pose for t=3, stamped after
    out = _feed(aligner, np.arange(0.0, 6.01, 0.5), np.zeros((13, 3)))
    forces = {s.t: (s.force[0], s.force_stale) for s in out}
    assert forces[0.0] == (0.0, True)  # nothing received yet
    assert forces[1.0] == (100.0, False)
    assert forces[2.0] == (200.0, False)
    assert forces[3.0] == (200.0, False)  # 3.05 is in the future of t = 3
    assert forces[4.0] == (300.0, False)
    assert forces[6.0] == (0.0, True)  # 2.95 s old > 2.5 s timeout
    assert aligner.counters.stale_force_samples == 2


@pytest.mark.parametrize('bad', [[np.nan, 0, 0], [0, np.inf, 0], [0, 0], [1e9, 0, 0], 'x'])
def test_invalid_pose_dropped_and_counted(bad: object) -> None:
    aligner = InputAligner(AlignerSettings(sample_time=0.5))
    aligner.add_pose(0.0, [0.0, 0.0, 0.0])
    assert aligner.add_pose(0.5, bad) == []
    assert aligner.counters.invalid == 1
    out = aligner.add_pose(1.0, [1.0, 0.0, 0.0])
    assert [s.t for s in out] == [0.5, 1.0]  # recovers, interpolating over the dropped one
    assert all(np.all(np.isfinite(s.pose)) for s in out)


def test_out_of_order_and_duplicates_dropped() -> None:
    aligner = InputAligner(AlignerSettings(sample_time=0.5))
    aligner.add_pose(1.0, [0.0, 0.0, 0.0])
    assert aligner.add_pose(1.0, [5.0, 0.0, 0.0]) == []
    assert aligner.add_pose(0.8, [5.0, 0.0, 0.0]) == []
    assert aligner.counters.out_of_order == 2
    assert aligner.counters.resets == 0


def test_backward_jump_restarts_segment() -> None:
    aligner = InputAligner(AlignerSettings(sample_time=0.5, backward_jump=5.0))
    _feed(aligner, np.arange(100.0, 110.0, 0.1), np.zeros((100, 3)))
    out = aligner.add_pose(0.0, [0.0, 0.0, 0.0])
    assert aligner.counters.resets == 1
    assert len(out) == 1 and out[0].t == 0.0 and out[0].segment_start


def test_gap_is_never_interpolated_across() -> None:
    aligner = InputAligner(AlignerSettings(sample_time=0.5, max_gap=3.0))
    _feed(aligner, np.arange(0.0, 2.01, 0.5), np.zeros((5, 3)))
    out = aligner.add_pose(60.0, [10.0, 0.0, 0.0])
    assert aligner.counters.gaps == 1
    assert [s.t for s in out] == [60.0] and out[0].segment_start
    np.testing.assert_allclose(out[0].pose, [10.0, 0.0, 0.0])


def test_gnss_outlier_dropped() -> None:
    aligner = InputAligner(AlignerSettings(sample_time=0.5, max_speed=10.0))
    aligner.add_pose(0.0, [0.0, 0.0, 0.0])
    assert aligner.add_pose(0.1, [500.0, 0.0, 0.0]) == []
    assert aligner.counters.outliers == 1
    out = aligner.add_pose(0.5, [0.5, 0.0, 0.0])
    assert out[-1].pose[0] == pytest.approx(0.5)


@pytest.mark.parametrize('kwargs', [{'sample_time': 0.0}, {'sample_time': 1.0, 'max_gap': 0.5},
                                    {'max_speed': -1.0}])
def test_invalid_settings_rejected(kwargs: dict[str, float]) -> None:
    with pytest.raises(ValueError, match='must be'):
        AlignerSettings(**kwargs)
