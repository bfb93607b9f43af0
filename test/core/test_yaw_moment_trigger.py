"""The heading gain from the yaw moment (``core.yaw_moment_trigger``; issue 13).

Against values worked out by hand: no gain in the warm-up (a parameter) or at a steady moment, the
gain 1 from the first sample of a turn's moment, held ``hold`` s after the last sample above the
ratio and then faded linearly over FADE_TIME; the level's floor; bad input.
"""
from __future__ import annotations

import math

import pytest

from lf_predictor_ros.core.yaw_moment_trigger import (
    FADE_TIME,
    LEVEL_FLOOR,
    LEVEL_TIME,
    MOMENT_TIME,
    YawMomentTrigger,
)

STATION = 1.0e6  # [N·m] the station-keeping yaw moment
TURN = 1.0e7  # [N·m] the moment of a turn: 10× the station-keeping level


def _warm(trigger: YawMomentTrigger, moment: float = STATION) -> list[float]:
    """Feed LEVEL_TIME of a steady moment; the gains."""
    return [trigger.update(moment) for _ in range(int(LEVEL_TIME / trigger.sample_time))]


def test_the_constants_are_the_probes() -> None:
    """The constants the adoption test ran with (yaw_moment_gate_probe.py, commit fd2c469)."""
    assert (MOMENT_TIME, LEVEL_TIME, FADE_TIME, LEVEL_FLOOR) == (2.0, 600.0, 10.0, 1.0)


def test_no_gain_in_the_warm_up_nor_at_a_steady_moment() -> None:
    trigger = YawMomentTrigger(1.0, 5.0, 30.0)
    assert trigger.update(TURN) == 0.0 and not trigger.warm  # (never triggered: 0, not NaN)
    trigger.reset()
    # turn moments in the warm-up: the level is not yet a measure, no gain
    gains = [trigger.update(TURN if k % 100 == 50 else STATION) for k in range(599)]
    assert gains == [0.0] * 599 and not trigger.warm
    assert [trigger.update(STATION) for _ in range(2000)] == [0.0] * 2000 and trigger.warm


def test_a_turn_opens_the_gain_at_once_holds_it_and_fades_it_linearly() -> None:
    """A 10-sample moment of 10× the level, h = 1 s, ρ 5, hold 30 s.

    LP over 2 s at h = 1 s weighs each sample 0.5: the first turn sample gives m = 5.5e6 against
    5 × (1e6 + 9e6/600) = 5.075e6 (open); the first sample after it m ≈ 5.5e6 against 5 × 1.149e6
    (shut), so the hold counts from the turn's last sample.
    """
    trigger = YawMomentTrigger(1.0, 5.0, 30.0)
    _warm(trigger)
    assert trigger.warm
    turn = [trigger.update(TURN) for _ in range(10)]
    assert turn == [1.0] * 10
    after = [trigger.update(STATION) for _ in range(60)]  # after[j - 1]: j s after the turn
    assert after[:30] == [1.0] * 30  # held: τ ≤ 30 s
    assert after[30:40] == pytest.approx([1.0 - j / FADE_TIME for j in range(1, 11)], abs=1e-12)
    assert after[39:] == [0.0] * 21


def test_the_warm_up_is_a_parameter_and_the_level_a_running_mean_in_it() -> None:
    """``warmup`` 120 s at h = 1 s: the 120th sample is the first that can open the gain.

    A turn moment as the 120th sample: level (119·1e6 + 1e7) / 120 = 1.075e6 (the running mean),
    m = 0.5·1e6 + 0.5·1e7 = 5.5e6 > 5 × 1.075e6 (open); as the 119th: not yet warm (0).
    """
    early = YawMomentTrigger(1.0, 5.0, 30.0, warmup=120.0)
    assert [early.update(STATION) for _ in range(118)] == [0.0] * 118
    assert early.update(TURN) == 0.0 and not early.warm
    trigger = YawMomentTrigger(1.0, 5.0, 30.0, warmup=120.0)
    assert [trigger.update(STATION) for _ in range(119)] == [0.0] * 119 and not trigger.warm
    assert trigger.update(TURN) == 1.0 and trigger.warm
    assert trigger._level == pytest.approx((119 * STATION + TURN) / 120, rel=1e-12)
    default = YawMomentTrigger(1.0, 5.0, 30.0)  # the warm-up is LEVEL_TIME unless given
    assert default.warmup == LEVEL_TIME
    assert [default.update(STATION) for _ in range(119)] + [default.update(TURN)] == [0.0] * 120
    # warm-up 0: warm from the first sample, which is its own level (no gain); the 100th
    # sample, a turn: level 1e6 + 9e6/100 = 1.09e6, 5 × 1.09e6 < m = 5.5e6 (open)
    at_once = YawMomentTrigger(1.0, 5.0, 30.0, warmup=0.0)
    assert at_once.update(TURN) == 0.0 and at_once.warm
    at_once.reset()
    assert [at_once.update(STATION) for _ in range(99)] + [at_once.update(TURN)] == \
        [0.0] * 99 + [1.0]


def test_hold_and_ratio_are_the_parameters() -> None:
    short = YawMomentTrigger(1.0, 5.0, 5.0)
    _warm(short)
    short.update(TURN)
    assert [short.update(STATION) for _ in range(8)] == pytest.approx(
        [1.0] * 5 + [0.9, 0.8, 0.7], abs=1e-12)
    strict = YawMomentTrigger(1.0, 20.0, 30.0)  # ρ 20: a tenfold moment is no turn
    _warm(strict)
    assert [strict.update(TURN) for _ in range(10)] == [0.0] * 10


def test_the_level_floor_keeps_a_vessel_without_moment_from_triggering_on_noise() -> None:
    trigger = YawMomentTrigger(1.0, 5.0, 0.0)
    _warm(trigger, 0.0)
    assert trigger.update(4.0 * LEVEL_FLOOR) == 0.0  # LP 2.0 N·m < 5 × the 1 N·m floor
    assert trigger.update(30.0 * LEVEL_FLOOR) == 1.0  # LP 16 N·m > 5 N·m


def test_a_non_finite_moment_is_skipped_and_reset_forgets() -> None:
    trigger = YawMomentTrigger(1.0, 5.0, 2.0)
    _warm(trigger)
    assert trigger.update(TURN) == 1.0
    assert [trigger.update(math.nan), trigger.update(math.inf)] == [1.0, 1.0]  # the hold goes on
    assert [trigger.update(-STATION), trigger.update(STATION)] == pytest.approx([0.9, 0.8])
    assert trigger.update(TURN) == 1.0  # the level and the moment stayed finite
    trigger.reset()
    assert not trigger.warm and trigger.update(TURN) == 0.0


@pytest.mark.parametrize(('args', 'message'), [
    ((0.0, 5.0, 30.0), 'sample_time must be finite and > 0'),
    ((1.0, 0.0, 30.0), 'ratio must be finite and > 0'),
    ((1.0, math.nan, 30.0), 'ratio must be finite and > 0'),
    ((1.0, 5.0, -1.0), 'hold must be finite and ≥ 0'),
    ((1.0, 5.0, math.inf), 'hold must be finite and ≥ 0'),
    ((1.0, 5.0, 30.0, -1.0), 'warmup must be finite and ≥ 0'),
    ((1.0, 5.0, 30.0, math.nan), 'warmup must be finite and ≥ 0'),
])
def test_bad_settings_are_refused(args: tuple[float, ...], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        YawMomentTrigger(*args)
