"""Tests of `core.manoeuvre`: block means and the manoeuvre test (numbers by construction)."""
from __future__ import annotations

import numpy as np
import pytest

from lf_predictor_ros.core.manoeuvre import (
    MANOEUVRE_BLOCK,
    MANOEUVRE_STEP,
    block_means,
    manoeuvring,
    turning,
)


def holding(n: int, seed: int = 0) -> np.ndarray:
    """Station keeping at h = 1 s: 0.5 m waves (period 8 s), 0.3 m slow LF motion, noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(float(n))
    y = np.column_stack([0.5 * np.sin(0.8 * t) + 0.3 * np.sin(0.01 * t),
                         0.5 * np.cos(0.8 * t) - 0.3 * np.cos(0.013 * t),
                         0.01 * np.sin(0.8 * t) + 0.005 * np.sin(0.01 * t)])
    return np.asarray(y + rng.normal(0.0, 0.05, y.shape), dtype=np.float64)


def test_block_means_are_the_means_of_the_newest_whole_blocks() -> None:
    y = np.arange(250.0)[:, None] * np.array([[1.0, -2.0]])
    means = block_means(y, 1.0)
    assert means.shape == (4, 2)  # 250 s: four whole 60 s blocks, the oldest 10 s left out
    np.testing.assert_allclose(means[:, 0], [39.5, 99.5, 159.5, 219.5])
    np.testing.assert_allclose(means[:, 1], -2.0 * means[:, 0])
    assert block_means(y[:59], 1.0).shape == (0, 2)
    assert block_means(y, 0.5).shape == (2, 2)  # 120 samples per block at h = 0.5 s
    with pytest.raises(ValueError, match='shape'):
        block_means(np.zeros(10), 1.0)


def test_station_keeping_is_not_a_manoeuvre() -> None:
    assert not manoeuvring(holding(1200), 1.0)
    assert not manoeuvring(holding(1200)[:, :1], 1.0)  # 1 DOF
    assert not manoeuvring(holding(100), 1.0)  # one block: no evidence


@pytest.mark.parametrize('dof', [0, 1, 2])
def test_a_move_or_a_turn_is_a_manoeuvre_and_a_smaller_step_is_not(dof: int) -> None:
    """A ramp of 1.5 × the limit per block in one DOF is seen; 0.5 × the limit is not."""
    n = 1200
    ramp = np.zeros((n, 3))
    block = int(MANOEUVRE_BLOCK)
    for factor, expected in ((1.5, True), (0.5, False)):
        rate = factor * MANOEUVRE_STEP[dof] / block  # per sample
        ramp[:, dof] = np.clip(np.arange(n) - 600.0, 0.0, 180.0) * rate  # a 3-block move
        assert manoeuvring(holding(n) + ramp, 1.0) is expected, (dof, factor)


def test_non_finite_block_means_are_no_evidence() -> None:
    assert not manoeuvring(np.full((600, 3), np.nan), 1.0)


def test_a_turn_is_turning_and_a_move_is_not() -> None:
    """Turning looks at the heading alone: a 1.5 × step per block turns, a 10 m move does not."""
    n = 600
    ramp = np.clip(np.arange(n) - 300.0, 0.0, 180.0)  # 3 blocks of ramp
    heading = holding(n)[:, 2]
    assert not turning(heading, 1.0)
    assert turning(heading + ramp * 1.5 * MANOEUVRE_STEP[2] / MANOEUVRE_BLOCK, 1.0)
    assert not turning(heading + ramp * 0.5 * MANOEUVRE_STEP[2] / MANOEUVRE_BLOCK, 1.0)
    moved = holding(n)
    moved[:, 0] += ramp * 10.0 / 180.0
    assert manoeuvring(moved, 1.0) and not turning(moved[:, 2], 1.0)
    assert not turning(heading[:100], 1.0)  # one block: no evidence
    with pytest.raises(ValueError, match='shape'):
        turning(holding(n), 1.0)
