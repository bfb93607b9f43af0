"""sim_bag: fair recording loop by default, the leaking one only when asked, provenance kept."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lf_predictor_ros.bag import sim_bag
from lf_predictor_ros.bag.mcap_reader import BagReader
from lf_predictor_ros.bag.provenance import RECORDING_ESTIMATOR_KEY, RECORDING_LOOP_KEY
from lf_predictor_ros.bag.ros_codec import stamped_fields
from sim_ros.simulation import load_scenario, simulate

DURATION = 60.0  # [s] 600 sensor samples of the supply vessel
SEED = 5
WRENCH = 'geometry_msgs/msg/WrenchStamped'


def test_the_default_loop_runs_on_the_observer_once_per_h() -> None:
    scenario = load_scenario('supply_closed_loop')
    record, provenance = sim_bag.simulate_recording(scenario, SEED, DURATION)
    assert (provenance.loop, provenance.estimator, provenance.seed) == ('estimator', 'observer',
                                                                        SEED)
    assert len(record.t) == 600
    # The PID answers each estimate once per h = 1 s (10 sensor samples) and holds its command;
    # the truth loop's PID acts on every sample, so its thrust changes within a second.
    held = record.thrust_command[10:].reshape(-1, 10, 3)
    assert np.array_equal(held, np.repeat(held[:, :1], 10, axis=1))
    assert not np.array_equal(held[1:, 0], held[:-1, 0])  # a new command every second
    truth_loop = simulate(scenario, seed=SEED, duration=DURATION)
    assert not np.array_equal(truth_loop.thrust_command[11], truth_loop.thrust_command[10])


def test_the_truth_loop_is_the_scenario_file_s_loop_and_says_so() -> None:
    scenario = load_scenario('supply_closed_loop')
    record, provenance = sim_bag.simulate_recording(scenario, SEED, DURATION, 'truth')
    assert (provenance.loop, provenance.estimator) == ('truth_lf', None)
    expected = simulate(scenario, seed=SEED, duration=DURATION)
    assert np.array_equal(record.thrust, expected.thrust)
    assert np.array_equal(record.measured_pose, expected.measured_pose)


def test_a_scenario_without_controller_is_recorded_open_loop() -> None:
    _, provenance = sim_bag.simulate_recording(load_scenario('threedof_open_loop'), SEED, 20.0)
    assert (provenance.loop, provenance.estimator) == ('open', None)


def test_unknown_loop_estimator_is_refused() -> None:
    with pytest.raises(ValueError, match='unknown loop estimator .smoother_tuned.'):
        sim_bag.simulate_recording(load_scenario('supply_closed_loop'), SEED, DURATION,
                                   'smoother_tuned')


def test_command_line_writes_the_run_and_its_provenance(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str],
                                                        ) -> None:
    path = tmp_path / 'sim.mcap'
    assert sim_bag.main(['supply_closed_loop', '--duration', '20', '--seed', str(SEED),
                         '-o', str(path)]) == 0
    assert 'loop on observer' in capsys.readouterr().out
    record, _ = sim_bag.simulate_recording(load_scenario('supply_closed_loop'), SEED, 20.0)
    with BagReader(path) as reader:
        custom = reader.custom_data()
        thrust = [stamped_fields(m.data, WRENCH).values for m in reader.messages(['/thrust'])]
        assert set(reader.topics()) == {'/thrust', '/measured_pose', '/truth/lf_pose',
                                        '/truth/pose'}
    assert custom[RECORDING_LOOP_KEY] == 'estimator'
    assert custom[RECORDING_ESTIMATOR_KEY] == 'observer'
    assert np.array_equal(np.array(thrust)[:, [0, 1, 5]], record.thrust)
