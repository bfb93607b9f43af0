"""Settings of the LF odometry (core.odometry_params): every bad value is refused with its name."""
from __future__ import annotations

import math
import re
from typing import Any

import pytest

from lf_predictor_ros.core.odometry_params import NON_NEGATIVE, OdometryParams


@pytest.mark.parametrize('bad', [0.5, -1.0, math.nan, math.inf])
def test_dead_reckoning_force_margin_is_checked(bad: float) -> None:
    with pytest.raises(ValueError, match='dead_reckoning_force_margin'):
        OdometryParams(dead_reckoning_force_margin=bad)
    assert OdometryParams().dead_reckoning_force_margin == 0.0  # no clip (forty-ninth session)
    assert OdometryParams(dead_reckoning_force_margin=2.0).dead_reckoning_force_margin == 2.0


@pytest.mark.parametrize('bad', [(30.0, 30.0), (30.0, -1.0, 0.0), (30.0, math.nan, 0.0)])
def test_dead_reckoning_force_time_is_checked(bad: tuple[float, ...]) -> None:
    with pytest.raises(ValueError, match='dead_reckoning_force_time'):
        OdometryParams(dead_reckoning_force_time=bad)
    assert OdometryParams().dead_reckoning_force_time == (30.0, 30.0, 0.0)


@pytest.mark.parametrize('bad', [-0.1, math.nan, math.inf])
def test_dead_reckoning_excursion_std_is_checked(bad: float) -> None:
    with pytest.raises(ValueError, match='dead_reckoning_excursion_std'):
        OdometryParams(dead_reckoning_excursion_std=bad)


@pytest.mark.parametrize('bad', [-0.1, math.nan, math.inf])
def test_dead_reckoning_moving_gate_is_checked(bad: float) -> None:
    with pytest.raises(ValueError, match='dead_reckoning_moving_gate'):
        OdometryParams(dead_reckoning_moving_gate=bad)


@pytest.mark.parametrize('bad', [-0.1, 0.5, 1.0, math.nan, math.inf])
def test_controller_read_pair_ratio_is_checked(bad: float) -> None:
    with pytest.raises(ValueError, match='controller_read_pair_ratio'):
        OdometryParams(controller_read_pair_ratio=bad)


@pytest.mark.parametrize(('blocks', 'block_time'), [(-1, 300.0), (8, 0.0), (8.5, 300.0),
                                                   (True, 300.0)])
def test_controller_read_pool_blocks_is_checked(blocks: Any, block_time: float) -> None:
    with pytest.raises(ValueError, match='controller_read_pool_blocks'):
        OdometryParams(controller_read_pool_blocks=blocks, controller_read_block_time=block_time)
    assert OdometryParams(controller_read_pool_blocks=8).controller_read_pool_blocks == 8


@pytest.mark.parametrize('bad', [-0.1, math.nan, math.inf])
def test_dead_reckoning_moving_gate_slow_is_checked(bad: float) -> None:
    with pytest.raises(ValueError, match='dead_reckoning_moving_gate_slow'):
        OdometryParams(dead_reckoning_moving_gate_slow=bad)


@pytest.mark.parametrize('bad', [-0.1, math.nan, math.inf])
def test_dead_reckoning_twist_average_periods_is_checked(bad: float) -> None:
    with pytest.raises(ValueError, match='dead_reckoning_twist_average_periods must be'):
        OdometryParams(dead_reckoning_twist_average_periods=bad,
                       dead_reckoning_moving_gate_averaged=0.0)
    with pytest.raises(ValueError, match='dead_reckoning_twist_average_periods > 0'):
        OdometryParams(dead_reckoning_twist_average_periods=0.0,
                       dead_reckoning_moving_gate_averaged=0.0,
                       dead_reckoning_moving_twist_start='average')


@pytest.mark.parametrize('bad', [-0.1, math.nan, math.inf])
def test_dead_reckoning_excursion_band_is_checked(bad: float) -> None:
    with pytest.raises(ValueError, match='dead_reckoning_excursion_band'):
        OdometryParams(dead_reckoning_excursion_band=bad)


def test_the_averaged_gate_needs_the_averaging_span() -> None:
    with pytest.raises(ValueError, match='dead_reckoning_twist_average_periods > 0'):
        OdometryParams(dead_reckoning_twist_average_periods=0.0,
                       dead_reckoning_moving_gate_averaged=2.0)
    for bad in (-0.1, math.nan, math.inf):
        with pytest.raises(ValueError, match='dead_reckoning_moving_gate_averaged'):
            OdometryParams(dead_reckoning_twist_average_periods=1.0,
                           dead_reckoning_moving_gate_averaged=bad)


def test_the_clamp_is_checked_and_needs_the_span() -> None:
    for bad in (-0.1, math.nan, math.inf):
        with pytest.raises(ValueError, match='dead_reckoning_moving_twist_clamp must be'):
            OdometryParams(dead_reckoning_moving_twist_clamp=bad)
    with pytest.raises(ValueError, match='dead_reckoning_moving_twist_clamp > 0'):
        OdometryParams(dead_reckoning_twist_average_periods=0.0,
                       dead_reckoning_moving_gate_averaged=0.0,
                       dead_reckoning_moving_twist_clamp=2.0)
    averaged = OdometryParams(dead_reckoning_moving_twist_start='average',
                              dead_reckoning_moving_twist_clamp=2.0)  # nothing to clamp
    assert averaged.dead_reckoning_moving_twist_clamp == 2.0
    params = OdometryParams(dead_reckoning_moving_twist_clamp=2.0)
    assert params.dead_reckoning_moving_twist_clamp == 2.0


@pytest.mark.parametrize('name', ['controller_read_fitted_damping_dofs',
                                  'dead_reckoning_damping_memory',
                                  'controller_read_stiffness_frame',
                                  'dead_reckoning_moving_twist_start',
                                  'dead_reckoning_moving_twist_clamp_dofs'])
def test_a_choice_outside_its_choices_is_refused(name: str) -> None:
    with pytest.raises(ValueError, match=f"{name} must be one of .*, got 'heading'"):
        OdometryParams(**{name: 'heading'})


@pytest.mark.parametrize(('name', 'hint'), NON_NEGATIVE)
@pytest.mark.parametrize('bad', [-1.0, math.nan, math.inf, -math.inf])
def test_a_setting_that_must_be_non_negative_is_refused_with_its_unit(name: str, hint: str,
                                                                       bad: float) -> None:
    with pytest.raises(ValueError,
                       match=re.escape(f'{name} must be a finite number >= 0{hint}, got {bad}')):
        OdometryParams(**{name: bad})
    assert getattr(OdometryParams(**{name: 2.0}), name) == 2.0
