"""sim_bag: fair recording loop by default, the leaking one only when asked, provenance kept."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lf_predictor_ros.bag import sim_bag
from lf_predictor_ros.bag.mcap_reader import BagReader
from lf_predictor_ros.bag.provenance import RECORDING_ESTIMATOR_KEY, RECORDING_LOOP_KEY
from lf_predictor_ros.bag.ros_codec import stamped_fields
from lf_predictor_ros.benchmark.recordings import grid_rows
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


def test_thrust_command_is_written_once_per_controller_instant(tmp_path: Path) -> None:
    path = tmp_path / 'sim.mcap'
    assert sim_bag.main(['supply_closed_loop', '--duration', '20', '--seed', str(SEED),
                         '--thrust-command', '-o', str(path)]) == 0
    record, _ = sim_bag.simulate_recording(load_scenario('supply_closed_loop'), SEED, 20.0)
    with BagReader(path) as reader:
        rows = [(m.log_time_ns, stamped_fields(m.data, WRENCH))
                for m in reader.messages(['/thrust_command'])]
    stamps = [fields.sec + fields.nanosec * 1e-9 for _, fields in rows]
    assert stamps == pytest.approx(np.arange(1.0, 20.5, 1.0), abs=1e-9)  # h = 1 s, t = 1 … 20
    assert [log for log, _ in rows] == [round(t * 1e9) for t in np.arange(1.0, 20.5, 1.0)]
    k = np.round(np.array(stamps) / 0.1).astype(int) - 1  # the sample at each stamp
    np.testing.assert_array_equal(np.array(record.t)[k], stamps)
    commands = np.array([fields.values for _, fields in rows])[:, [0, 1, 5]]
    np.testing.assert_array_equal(commands, record.thrust_command[k])
    assert np.all(np.abs(commands[:, 0]) > 0.0)  # the PID's commands, not zeros


def test_command_rows_are_the_grid_instants() -> None:
    """The commands go at the predictor's grid instants, the samples `decimate` keeps."""
    rows = np.arange(30)  # sensor samples at 0.1 … 3.0 s
    np.testing.assert_array_equal(rows[grid_rows(10)], [9, 19, 29])  # h = 1 s
    np.testing.assert_array_equal(rows[grid_rows(5)], [4, 9, 14, 19, 24, 29])  # h = 0.5 s
    with pytest.raises(ValueError, match='stride must be >= 1'):
        grid_rows(0)


def test_thrust_command_without_a_controller_is_refused(tmp_path: Path) -> None:
    with pytest.raises(SystemExit) as exit_info:
        sim_bag.main(['threedof_open_loop', '--duration', '20', '--thrust-command',
                      '-o', str(tmp_path / 'x.mcap')])
    assert exit_info.value.code == 2
    assert not (tmp_path / 'x.mcap').exists()
