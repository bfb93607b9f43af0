"""`waves.model: rao` scenarios and the controller setpoint schedule (sim_ros.simulation)."""
from __future__ import annotations

from dataclasses import replace
import math

import numpy as np
import pytest

from sim_ros.physics.kinematics import wrap_angles
from sim_ros.physics.rao import wave_motion
from sim_ros.simulation import (
    ControllerConfig,
    Scenario,
    Simulator,
    WaveConfig,
    load_scenario,
    scenario_from_dict,
    simulate,
    simulate_in_loop,
)

# scenario → (vessel, largest heading setpoint step [rad], largest WF yaw std [rad]: the short
# hulls yaw more per unit wave slope)
RAO_SCENARIOS = {'rao_supply': ('supply', math.pi / 2, 0.03),
                 'rao_swell': ('supply', math.pi / 2, 0.03),
                 'rao_tanker': ('tanker', math.pi / 3, 0.03),
                 'rao_workboat': ('workboat', math.pi / 2, 0.05),
                 'rao_crewboat': ('crewboat', math.pi / 2, 0.05)}


@pytest.mark.parametrize('name', RAO_SCENARIOS)
def test_rao_scenario_loads_and_runs(name: str) -> None:
    """Loads, reports ω_p, truth − LF is the RAO motion at the LF heading, deterministic."""
    scn = load_scenario(name)
    vessel, largest_turn, yaw_std = RAO_SCENARIOS[name]
    assert scn.waves.model == 'rao' and scn.vessel == vessel and scn.controller.enabled
    assert len(scn.controller.setpoint_schedule) >= 4
    yaw_steps = np.diff([0.0] + [row[3] for row in scn.controller.setpoint_schedule])
    assert np.max(np.abs(yaw_steps)) == pytest.approx(largest_turn, abs=1e-5)
    wp = 2.0 * math.pi / scn.waves.tp
    rec = simulate(scn, duration=60.0)
    np.testing.assert_allclose(rec.wave_peak_freq, wp)
    wave = rec.truth_pose - rec.truth_lf_pose
    wave[:, 2] = wrap_angles(wave[:, 2])
    assert 0.1 < float(np.std(wave[:, :2])) < 1.5
    assert 0.002 < float(np.std(wave[:, 2])) < yaw_std
    sea = Simulator(scn).wave_components()
    assert sea is not None
    expected = wave_motion(sea, scn.waves.rao, rec.t, rec.truth_lf_pose[:, 2])
    np.testing.assert_allclose(wave, expected, atol=1e-9)
    again = simulate(scn, duration=60.0)
    np.testing.assert_array_equal(rec.measured_pose, again.measured_pose)
    other = simulate(scn, seed=scn.seed + 1, duration=60.0)
    assert not np.allclose(other.truth_pose - other.truth_lf_pose, wave)


@pytest.mark.parametrize(('waves', 'message'), [
    ({'model': 'rao', 'hs': 2.0, 'sigma': [1, 1, 0.1]}, 'force/motion'),
    ({'model': 'rao', 'hs': 2.0, 'peak_freq': 0.6}, 'force/motion'),
    ({'model': 'motion', 'sigma': 1.0, 'hs': 2.0}, 'keys of waves.model rao'),
    ({'model': 'rao', 'hs': 2.0, 'gamma': 9.0}, 'γ'),
    ({'model': 'rao', 'hs': -1.0}, 'Hs'),
    ({'model': 'rao', 'hs': 2.0, 'tp': 60.0}, 'waves.tp'),
    ({'model': 'rao', 'hs': 2.0, 'components': [40, 4]}, 'long-crested'),
    ({'model': 'rao', 'hs': 2.0, 'spreading': 5, 'components': [40.5, 4]}, 'integers'),
    ({'model': 'rao', 'hs': 2.0, 'spreading': 5, 'components': [400, 40]}, 'product'),
    ({'model': 'rao', 'hs': 2.0, 'spreading': -2.0, 'components': [40, 4]}, 'spreading'),
    ({'model': 'rao', 'hs': 2.0, 'frequency_range': [1.5, 3.0]}, 'frequency_range'),
    ({'model': 'rao', 'hs': 2.0, 'rao': {'beam': 18.0}}, "unknown key\\(s\\) \\['beam'\\]"),
    ({'model': 'rao', 'hs': 2.0, 'rao': {'order': 2.5}}, 'rao.order'),
    ({'model': 'rao', 'hs': 2.0, 'rao': {'length': -3.0}}, 'rao.length'),
])
def test_rao_wave_config_errors(waves: dict[str, object], message: str) -> None:
    """Wrong rao keys and values raise ValueError saying what to change."""
    with pytest.raises(ValueError, match=message):
        scenario_from_dict({'vessel': 'supply', 'sample_time': 0.1, 'waves': waves})


def test_rao_defaults_and_calm_sea() -> None:
    """Hs = 0 is a calm sea (no wave motion); peak_freq is derived from Tp."""
    scn = scenario_from_dict({'vessel': 'supply', 'sample_time': 0.5, 'waves': {
        'model': 'rao', 'hs': 0.0, 'tp': 8.0}})
    assert scn.waves.peak_freq(0.0) == pytest.approx(2.0 * math.pi / 8.0)
    rec = simulate(scn, duration=10.0, controller=False)
    np.testing.assert_array_equal(rec.truth_pose, rec.truth_lf_pose)
    assert Simulator(scn).wave_components() is None


@pytest.mark.parametrize(('schedule', 'message'), [
    ([[10.0, 1.0, 2.0]], 'row'),
    ([[10.0, 1.0, 2.0, 0.0], [5.0, 0.0, 0.0, 0.0]], 'non-decreasing'),
    ([[-1.0, 1.0, 2.0, 0.0]], '>= 0'),
])
def test_setpoint_schedule_errors(schedule: list[list[float]], message: str) -> None:
    """Malformed schedules are ValueErrors."""
    with pytest.raises(ValueError, match=message):
        scenario_from_dict({'vessel': 'supply', 'sample_time': 0.1,
                            'controller': {'enabled': True, 'setpoint_schedule': schedule}})


def test_setpoint_at_is_piecewise_constant() -> None:
    """Before the first row: `setpoint`; from each row's time on: that row."""
    ctl = ControllerConfig(True, (1.0, 2.0, 0.1), ((100.0, 10.0, 0.0, 0.5),
                                                   (200.0, 10.0, 5.0, -1.0)))
    times = np.array([0.0, 99.9, 100.0, 150.0, 200.0, 1e4])
    expected = np.array([[1, 2, 0.1], [1, 2, 0.1], [10, 0, 0.5], [10, 0, 0.5], [10, 5, -1],
                         [10, 5, -1]], dtype=np.float64)
    np.testing.assert_array_equal(ctl.setpoint_series(times), expected)
    for t, row in zip(times, expected, strict=True):
        np.testing.assert_array_equal(ctl.setpoint_at(float(t)), row)


def _calm_supply(schedule: tuple[tuple[float, float, float, float], ...],
                 initial_yaw: float = 0.0, setpoint_yaw: float = 0.0) -> Scenario:
    return Scenario(vessel='supply', sample_time=0.5, internal_step=0.5, duration=400.0,
                    initial_pose=(0.0, 0.0, initial_yaw), waves=WaveConfig(),
                    controller=ControllerConfig(True, (0.0, 0.0, setpoint_yaw), schedule))


def test_schedule_moves_and_turns_the_vessel() -> None:
    """Both loops follow a 10 m move and a 90° turn; simulate and simulate_in_loop agree."""
    scn = _calm_supply(((20.0, 10.0, 0.0, 0.0), (60.0, 10.0, -5.0, math.pi / 2)))
    rec = simulate(scn, feedback='measured')
    final = rec.truth_lf_pose[-1]
    np.testing.assert_allclose(final[:2], [10.0, -5.0], atol=0.2)
    assert final[2] == pytest.approx(math.pi / 2, abs=0.01)
    assert np.all(np.abs(rec.truth_lf_pose[rec.t < 20.0]) < 1e-6)  # before the step: at rest
    loop = simulate_in_loop(scn, None, None, lambda t, pose, thrust: pose, 0.5,
                            pid_period=0.5, abort_excursion=50.0)
    assert loop.aborted_at is None
    np.testing.assert_array_equal(loop.record.truth_lf_pose[-1], rec.truth_lf_pose[-1])


def test_heading_setpoint_turns_the_short_way_across_180() -> None:
    """170° → −170° is a 20° turn through 180° (wrapped error), not 340° through 0°."""
    start = math.radians(170.0)
    scn = _calm_supply(((10.0, 0.0, 0.0, math.radians(-170.0)),), start, start)
    rec = simulate(scn)
    heading = np.unwrap(rec.truth_lf_pose[:, 2])
    assert heading[-1] == pytest.approx(math.radians(190.0), abs=0.01)
    assert np.all(heading > math.radians(165.0))


def test_scenario_with_schedule_replace_keeps_validation() -> None:
    """dataclasses.replace on a rao scenario re-derives ω_p from a new Tp."""
    scn = load_scenario('rao_supply')
    moved = replace(scn, waves=replace(scn.waves, tp=8.0))
    assert moved.waves.peak_freq(0.0) == pytest.approx(2.0 * math.pi / 8.0)
