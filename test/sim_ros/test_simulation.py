"""Scenario loading/validation and Simulator ground truth, reproducibility, sensors."""
from __future__ import annotations

from dataclasses import replace
import math
from pathlib import Path

import numpy as np
import pytest

from sim_ros.physics import schedule
from sim_ros.physics.kinematics import wrap_angles
from sim_ros.physics.sensors import SensorConfig
from sim_ros.physics.waves import WaveGenerator
from sim_ros.simulation import (
    Scenario,
    Simulator,
    WaveConfig,
    available_scenarios,
    load_scenario,
    scenario_from_dict,
    scenario_with_schedule_shift,
    simulate,
    with_schedule_shift,
)

SCENARIOS = ['onedof_reference', 'onedof_excited', 'onedof_no_excitation', 'onedof_feedback',
             'threedof_open_loop', 'supply_closed_loop', 'omega_schedule', 'omega_steps']


def test_all_scenarios_load_and_validate() -> None:
    """Every required scenario exists and loads by name and by path."""
    assert set(SCENARIOS) <= set(available_scenarios())
    for name in SCENARIOS:
        scn = load_scenario(name)
        assert scn.name == name
        assert scn.substeps * scn.internal_step == pytest.approx(scn.sample_time)
    path = Path(__file__).resolve().parents[2] / 'config' / 'scenarios' / 'supply_closed_loop.yaml'
    scn = load_scenario(str(path))
    assert scn.vessel == 'supply' and scn.sample_time == 0.1 and scn.controller.enabled
    assert scn.environment.current_direction == pytest.approx(math.radians(20.0), abs=1e-6)
    sched = load_scenario('omega_schedule').waves.peak_freq
    assert sched(0.0) == 1.25 and sched(4 * 3600.0) == 0.3
    steps = load_scenario('omega_steps').waves.peak_freq
    assert [steps(t) for t in (3599.0, 3600.0, 7199.0, 7200.0)] == [1.25, 0.3, 0.3, 1.25]


@pytest.mark.parametrize(('change', 'message'), [
    ({'vessel': 'barge'}, 'vessel must be one of'),
    ({'sample_time': 2.0}, '1–100 Hz'),
    ({'sample_time': 0.1, 'internal_step': 0.03}, 'integer multiple'),
    ({'waves': {'model': 'force', 'damping': 1.5}}, 'damping'),
    ({'colour': 'red'}, "unknown key\\(s\\) \\['colour'\\]"),
    ({'waves': {'peak_freq': {'table': [[0, 1.0], [10, 9.0]]}}}, 'rad/s'),
    ({'sensors': {'dropout_probability': 1.0}}, 'dropout_probability'),
])
def test_invalid_scenarios_raise_clear_errors(change: dict[str, object], message: str) -> None:
    """Broken rules raise ValueError naming the rule."""
    data: dict[str, object] = {'vessel': 'onedof', 'sample_time': 1.0}
    data.update(change)
    with pytest.raises(ValueError, match=message):
        scenario_from_dict(data)


def test_unknown_scenario_name() -> None:
    """A missing name lists what is available."""
    with pytest.raises(ValueError, match='available'):
        load_scenario('no_such_scenario')


@pytest.mark.parametrize('model', ['force', 'motion'])
def test_zero_sigma_lf_truth_equals_total(model: str) -> None:
    """σ = 0: truth_lf_pose == truth_pose exactly; σ > 0 they differ by the WF motion."""
    base = load_scenario('threedof_open_loop')
    calm = replace(base, waves=replace(base.waves, model=model, sigma=(0.0, 0.0, 0.0)))
    rec = simulate(calm, seed=3, duration=200.0)
    np.testing.assert_array_equal(rec.truth_pose, rec.truth_lf_pose)
    sigma = (85.0, 85.0, 2.2) if model == 'force' else (1.0, 1.0, 0.02)
    rough = replace(base, waves=replace(base.waves, model=model, sigma=sigma))
    rec = simulate(rough, seed=3, duration=200.0)
    assert np.abs(rec.truth_pose - rec.truth_lf_pose)[:, :2].std() > 0.1


def test_same_seed_identical_different_seed_differs() -> None:
    """One seed reproduces a run bit for bit; another seed changes every noise source."""
    scn = load_scenario('supply_closed_loop')
    a = simulate(scn, seed=5, duration=120.0)
    b = simulate(scn, seed=5, duration=120.0)
    c = simulate(scn, seed=6, duration=120.0)
    for field in ('measured_pose', 'truth_pose', 'truth_lf_pose', 'thrust', 'measured_valid'):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    noise_a = a.measured_pose - a.truth_pose
    noise_c = c.measured_pose - c.truth_pose
    ok = (a.measured_valid == 1) & (c.measured_valid == 1)
    assert np.corrcoef(noise_a[ok, 0], noise_c[ok, 0])[0, 1] < 0.1
    wave_a = a.truth_pose - a.truth_lf_pose
    wave_c = c.truth_pose - c.truth_lf_pose
    assert np.abs(wave_a - wave_c).max() > 0.1
    assert Simulator(scn, seed=5).seed == 5 and Simulator(scn).seed == scn.seed


def test_motion_superposition_wf_is_the_wave_process() -> None:
    """Supply vessel (motion superposition): truth − LF truth is the wave process itself.

    It equals the wave generator's output for the simulator's wave child seed exactly (σ per
    DOF, across block refills); its variance λω0σ² is checked in test_waves (0.50 m, 0.0131 rad
    here).
    """
    scn = load_scenario('supply_closed_loop')
    rec = simulate(scn, seed=9, duration=250.0)
    wave = rec.truth_pose - rec.truth_lf_pose
    wave[:, 2] = wrap_angles(wave[:, 2])
    rng = np.random.default_rng(np.random.SeedSequence(9).spawn(8)[0])
    gen = WaveGenerator('motion', 0.1, np.array(scn.waves.sigma), scn.waves.peak_freq, 0.1, rng)
    expected, _ = gen.next_block(wave.shape[0])
    np.testing.assert_allclose(wave, expected, atol=1e-9)
    assert math.sqrt(0.1 * 0.8) * 1.77 == pytest.approx(0.50, abs=0.005)


def test_force_superposition_wf_motion_stays_at_wave_frequency() -> None:
    """1-DOF force superposition (σ = 85): WF std ≈ 0.50 m and no LF drift in the WF part.

    0.50 m is the design value (undamped response b K_ω/(s² + 2λω0 s + ω0²)³ at ω0 = 0.8);
    over 2400 s the estimate of the std scatters by ≈ 8 % (1σ, seeds 10–15: −15 … +9 %), so
    we allow ±30 %. The WF mean stays below 0.15 m while the vessel moves tens of metres
    (a wrongly initialized or zero-order-held WF state leaves offsets of 0.3–2.4 m).
    """
    scn = load_scenario('onedof_reference')
    rec = simulate(scn, seed=2, duration=2400.0)
    wave = rec.truth_pose[:, 0] - rec.truth_lf_pose[:, 0]
    assert wave.std() == pytest.approx(0.50, rel=0.3)
    assert abs(wave.mean()) < 0.15
    assert rec.truth_lf_pose[:, 0].std() > 10.0


def test_sensors_noise_wrap_dropouts_outliers() -> None:
    """Noise std, heading in (−π, π], dropout rate, outlier jumps as configured."""
    base = load_scenario('threedof_open_loop')
    sensors = SensorConfig(position_std=0.2, heading_std=0.01, dropout_probability=0.1,
                           outlier_probability=0.02, outlier_position=5.0, outlier_heading=0.2)
    scn = replace(base, sensors=sensors, initial_pose=(0.0, 0.0, math.pi - 0.05),
                  internal_step=0.25)
    rec = simulate(scn, seed=4, duration=3000.0)
    valid = rec.measured_valid == 1.0
    n = valid.size
    assert abs((~valid).mean() - 0.1) < 3 * math.sqrt(0.1 * 0.9 / n)
    heading = rec.measured_pose[:, 2]
    assert np.all(heading <= math.pi) and np.all(heading > -math.pi)
    assert np.any(heading > 3.0) and np.any(heading < -3.0)  # crossed ±π
    err = rec.measured_pose - rec.truth_pose
    err[:, 2] = wrap_angles(err[:, 2])
    jumps = valid & (np.hypot(err[:, 0], err[:, 1]) > 3.0)
    assert abs(jumps.sum() / valid.sum() - 0.02) < 3 * math.sqrt(0.02 * 0.98 / valid.sum())
    clean = valid & ~jumps
    assert err[clean, 0].std() == pytest.approx(0.2, rel=0.05)
    assert err[clean, 2].std() == pytest.approx(0.01, rel=0.1)
    # a dropout repeats the last valid measurement
    first_drop = int(np.argmax(~valid[1:])) + 1
    np.testing.assert_array_equal(rec.measured_pose[first_drop], rec.measured_pose[first_drop - 1])


def test_wave_peak_freq_follows_schedule_and_true_model() -> None:
    """SimSample.wave_peak_freq follows ω0(t); true_model gives M, D."""
    scn = replace(load_scenario('omega_schedule'), duration=600.0)
    rec = simulate(scn, seed=0, duration=600.0)
    np.testing.assert_allclose(rec.wave_peak_freq, scn.waves.peak_freq.sample(rec.t))
    sim = Simulator(load_scenario('supply_closed_loop'))
    model = sim.true_model()
    assert model.mass[2, 2] == pytest.approx(4.4524e9, rel=1e-4)
    assert sim.ndof == 3 and sim.sample_time == 0.1 and sim.t == 0.0
    sim.step(np.zeros(3))
    assert sim.t == pytest.approx(0.1)
    onedof = Simulator(Scenario(vessel='onedof', sample_time=1.0, waves=WaveConfig()))
    assert onedof.ndof == 1
    assert onedof.true_model().mass[0, 0] == pytest.approx(1 / 0.00068)
    with pytest.raises(ValueError, match='tau_command'):
        sim.step(np.zeros(2))


def test_a_schedule_shift_moves_every_event_and_nothing_else() -> None:
    """rao_supply's events 30 s later: the setpoint at t + 30 is the old one at t, inputs kept."""
    controller = load_scenario('rao_supply').controller
    rows = controller.setpoint_schedule
    moved = with_schedule_shift(controller, 30.0)
    assert [row[0] for row in moved.setpoint_schedule] == [row[0] + 30.0 for row in rows]
    assert [row[1:] for row in moved.setpoint_schedule] == [row[1:] for row in rows]
    assert replace(moved, setpoint_schedule=rows) == controller  # nothing else changed
    assert controller.setpoint_schedule == rows  # the input is not modified
    times = np.arange(0.0, 3500.0, 7.0)
    assert np.array_equal(moved.setpoint_series(times + 30.0), controller.setpoint_series(times))
    assert with_schedule_shift(controller, 0.0) is controller
    still = load_scenario('supply_closed_loop').controller  # station keeping: no schedule
    assert with_schedule_shift(still, 30.0) is still
    for bad in (-1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match='schedule shift must be finite and >= 0'):
            with_schedule_shift(controller, bad)


def test_a_scenario_shift_moves_the_wave_peak_frequency_steps_too() -> None:
    """omega_steps' ω0 steps (3600 s, 7200 s) 45 s later; ω0(t + 45) = the old ω0(t) after 0."""
    scenario = load_scenario('omega_steps')
    moved = scenario_with_schedule_shift(scenario, 45.0)
    old, new = scenario.waves.peak_freq, moved.waves.peak_freq
    assert new.values == old.values
    assert new.times == tuple(t + 45.0 if t > 0.0 else t for t in old.times)
    times = np.arange(0.0, 10800.0, 5.0)
    assert np.array_equal(new.sample(times + 45.0), old.sample(times))
    assert new.sample(np.array([3600.0, 3644.9, 3645.0])).tolist() == [1.25, 1.25, 0.3]
    assert replace(moved, waves=scenario.waves) == scenario  # nothing else changed
    assert moved is not scenario  # ω0 steps to move
    # setpoint events move as with_schedule_shift moves them; a constant sea stays the object
    rao = load_scenario('rao_supply')
    moved_rao = scenario_with_schedule_shift(rao, 45.0)
    assert moved_rao.controller == with_schedule_shift(rao.controller, 45.0)
    assert moved_rao.waves is rao.waves and moved_rao is not rao  # setpoint events to move
    still = load_scenario('supply_closed_loop')  # no setpoint events, constant ω0
    assert scenario_with_schedule_shift(still, 45.0) is still  # nothing to move
    assert scenario_with_schedule_shift(scenario, 0.0) is scenario
    with pytest.raises(ValueError, match='delay must be finite and >= 0'):
        schedule.delayed(old, -1.0)
    assert schedule.delayed(schedule.constant(0.8), 45.0) == schedule.constant(0.8)
