"""Stability rule of a DP loop: bounded and no limit cycle (benchmark.stability)."""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
import pytest

from lf_predictor_ros.benchmark.stability import (
    HEADING_FLOOR,
    assess,
    dominant_oscillation,
    excursion_bounds,
    is_limit_cycle,
    pose_offset,
    saturated_fraction,
)

FloatArray = NDArray[np.float64]
DT, N = 1.0, 3000  # s, samples: a 50-minute scored record at h = 1 s


def _gauss_markov(seed: int, time_constant: float = 100.0) -> FloatArray:
    """Unit-variance first-order Gauss–Markov process (a broadband LF DP error)."""
    rng = np.random.default_rng(seed)
    a = math.exp(-DT / time_constant)
    drive = rng.standard_normal(N) * math.sqrt(1.0 - a * a)
    x = np.empty(N)
    x[0] = rng.standard_normal()
    for k in range(1, N):
        x[k] = a * x[k - 1] + drive[k]
    return x


def test_a_sinusoid_in_noise_is_a_limit_cycle() -> None:
    """1 m at 0.05 rad/s + 0.2 m white noise: share = 0.5 / (0.5 + 0.04) = 0.926."""
    t = np.arange(N) * DT
    x = np.sin(0.05 * t + 0.3) + 0.2 * np.random.default_rng(1).standard_normal(N)
    osc = dominant_oscillation(x, DT, 0.3)
    assert osc.frequency == pytest.approx(0.05, abs=5e-4)
    assert osc.amplitude == pytest.approx(1.0, abs=0.02)
    assert osc.share == pytest.approx(0.5 / 0.54, abs=0.01)
    assert is_limit_cycle(osc, 0)


@pytest.mark.parametrize('seed', range(6))
def test_broadband_noise_is_not_a_limit_cycle(seed: int) -> None:
    """A Gauss–Markov error (T = 100 s): one sinusoid explains < 30 % (measured 7–22 %)."""
    osc = dominant_oscillation(_gauss_markov(seed), DT, 0.3)
    assert osc.share < 0.3
    assert not is_limit_cycle(osc, 0)


def test_small_or_out_of_band_oscillations_do_not_count() -> None:
    t = np.arange(N) * DT
    noise = 0.01 * np.random.default_rng(2).standard_normal(N)
    tiny = dominant_oscillation(0.05 * np.sin(0.05 * t) + noise, DT, 0.3)
    assert tiny.share > 0.9 and tiny.amplitude == pytest.approx(0.05, abs=0.002)
    assert not is_limit_cycle(tiny, 0)  # 5 cm: below the 0.1 m floor
    assert is_limit_cycle(tiny, 2)  # as a heading error 0.05 rad (2.9°) it would count
    wave = dominant_oscillation(np.sin(0.8 * t) + 0.3 * _gauss_markov(3), DT, 0.3)
    assert wave.frequency < 0.3 and wave.share < 0.3  # wave-frequency motion is not searched
    slow = dominant_oscillation(np.sin(2 * math.pi * 2.0 / (N * DT) * t), DT, 0.3)
    assert slow.share < 0.5  # two cycles per record: below the 3-cycle minimum, not searched


def test_bounds_come_from_the_ideal_loop_with_floors() -> None:
    assert excursion_bounds(0.3, 0.001) == (5.0, HEADING_FLOOR)
    assert excursion_bounds(0.865, 0.05) == pytest.approx((8.65, 0.5))


def test_assess_bounded_and_limit_cycle_verdicts() -> None:
    t = np.arange(N) * DT
    calm = np.column_stack([0.3 * _gauss_markov(4), 0.3 * _gauss_markov(5),
                            0.002 * _gauss_markov(6)])
    ok = assess(calm, DT, 3, (5.0, HEADING_FLOOR), 0.3, aborted=False)
    assert ok.stable and ok.bounded and not ok.limit_cycle
    assert ok.checked_band == pytest.approx((2 * math.pi * 3 / 3000.0, 0.3))
    drifting = calm.copy()
    drifting[-1, 1] = 6.0
    far = assess(drifting, DT, 3, (5.0, HEADING_FLOOR), 0.3, aborted=False)
    assert not far.stable and not far.bounded and 'excursion 6 m > bound 5 m' in far.reason
    cycling = calm.copy()
    cycling[:, 2] += 0.05 * np.sin(0.25 * t)  # 2.9° yaw oscillation at 0.25 rad/s
    cyc = assess(cycling, DT, 3, (5.0, HEADING_FLOOR), 0.3, aborted=False)
    assert cyc.bounded and cyc.limit_cycle and not cyc.stable
    assert cyc.oscillations[2].frequency == pytest.approx(0.25, abs=1e-3)
    assert 'limit cycle in DOF 2' in cyc.reason
    gone = assess(calm[:100], DT, 3, (5.0, HEADING_FLOOR), 0.3, aborted=True)
    assert not gone.bounded and gone.reason.startswith('diverged')


def test_an_oscillation_the_ideal_loop_has_too_is_forced_not_a_limit_cycle() -> None:
    """0.5 m at 0.007 rad/s (a multisine line) in both loops: forced; only in one: a cycle."""
    t = np.arange(N) * DT
    forcing = 0.5 * np.sin(0.007 * t)
    ideal = (forcing + 0.05 * _gauss_markov(7))[:, None]
    loop = (1.1 * forcing + 0.05 * _gauss_markov(8))[:, None]
    alone = assess(loop, DT, 1, (5.0, HEADING_FLOOR), 0.3, aborted=False)
    assert alone.limit_cycle  # without a reference the rule alone would flag it
    forced = assess(loop, DT, 1, (5.0, HEADING_FLOOR), 0.3, aborted=False, reference=ideal)
    assert forced.stable and not forced.limit_cycle
    calm_ideal = (0.05 * _gauss_markov(7))[:, None]
    own = assess(loop, DT, 1, (5.0, HEADING_FLOOR), 0.3, aborted=False, reference=calm_ideal)
    assert own.limit_cycle and not own.stable


def test_pose_offset_wraps_heading_and_saturation_share() -> None:
    pose = np.array([[1.0, 2.0, math.pi - 0.1], [0.0, 0.0, -math.pi + 0.1]])
    offset = pose_offset(pose, np.array([1.0, 0.0, -math.pi + 0.1]), 3)
    np.testing.assert_allclose(offset, [[0.0, 2.0, -0.2], [-1.0, 0.0, 0.0]], atol=1e-12)
    command = np.array([[1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.5, -3.0, 0.0], [0.0, 0.0, 0.0]])
    assert saturated_fraction(command, np.array([2.0, 3.0, 1.0]), 3) == 0.5
    assert saturated_fraction(command, np.array([2.0, 3.0, 1.0]), 1) == 0.25
    assert saturated_fraction(command, None, 3) == 0.0
