"""bag.series: topics of a bag as numpy arrays, and /diagnostics as records."""
# rclpy message constructors are untyped.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from std_msgs.msg import Float64, String

from lf_predictor_ros.bag.mcap_reader import BagError, BagReader
from lf_predictor_ros.bag.mcap_writer import BagWriter
from lf_predictor_ros.bag.ros_codec import serialize
from lf_predictor_ros.bag.series import Series, read_diagnostics, read_series
from lf_predictor_ros.nodes.conversions import ns_to_stamp, pose_to_msg, wrench_to_msg
from lf_predictor_ros.nodes.diagnostics import make_diagnostic_array

POSE = 'geometry_msgs/msg/PoseStamped'
WRENCH = 'geometry_msgs/msg/WrenchStamped'
FLOAT = 'std_msgs/msg/Float64'
DIAG = 'diagnostic_msgs/msg/DiagnosticArray'
N = 40
STEP_NS = 100_000_007  # [ns] an odd period, so no stamp is a round decimal
START_NS = 1_700_000_000_123_456_789  # [ns] a wall-clock-like start (2023)
LATENCY_NS = 3_000_000  # [ns] log time - header stamp


def _seconds(ns: list[int], offset: int = 0) -> np.ndarray:
    """Nanoseconds to the nearest float second (int / int is correctly rounded)."""
    return np.array([(t + offset) / 1_000_000_000 for t in ns])


def _data() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(11)
    poses = np.column_stack([rng.normal(0, 50, N), rng.normal(0, 50, N),
                             np.linspace(-math.pi + 1e-3, math.pi, N)])  # yaw over all of (-π, π]
    forces = rng.normal(0, 1e4, (N, 3))
    freqs = rng.uniform(0.3, 1.3, N)
    return poses, forces, freqs


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A bag with pose, wrench, Float64, diagnostics and a String topic, in small chunks."""
    path = tmp_path_factory.mktemp('series') / 'series.mcap'
    poses, forces, freqs = _data()
    with BagWriter(path, chunk_size=2048) as writer:
        pose_ch = writer.add_topic('/measured_pose', POSE)
        wrench_ch = writer.add_topic('/thrust', WRENCH)
        float_ch = writer.add_topic('/wave_peak_frequency', FLOAT)
        diag_ch = writer.add_topic('/diagnostics', DIAG)
        text_ch = writer.add_topic('/note', 'std_msgs/msg/String')
        for k in range(N):
            stamp_ns = START_NS + k * STEP_NS
            log_ns = stamp_ns + LATENCY_NS
            writer.write(pose_ch, log_ns, serialize(pose_to_msg(poses[k], ns_to_stamp(stamp_ns))))
            writer.write(wrench_ch, log_ns + 1,
                         serialize(wrench_to_msg(forces[k], ns_to_stamp(stamp_ns))))
            writer.write(float_ch, log_ns + 2, serialize(Float64(data=float(freqs[k]))))
            if k % 10 == 0:
                array = make_diagnostic_array('predictor: lf', 'OK', 'fine',
                                              {'trainings': k // 10, 'state': 'trained'},
                                              stamp=ns_to_stamp(stamp_ns))
                array.status.append(make_diagnostic_array('other', 'WARN', 'x', {}).status[0])
                writer.write(diag_ch, log_ns, serialize(array))
        writer.write(text_ch, START_NS, serialize(String(data='hello')))
    return path


def test_round_trip_values_and_exact_stamps(bag: Path) -> None:
    poses, forces, freqs = _data()
    series = read_series(bag, ['/measured_pose', '/thrust', '/wave_peak_frequency'])
    assert set(series) == {'/measured_pose', '/thrust', '/wave_peak_frequency'}
    stamp_ns = [START_NS + STEP_NS * k for k in range(N)]
    expected_stamp = _seconds(stamp_ns)
    pose, wrench, freq = (series['/measured_pose'], series['/thrust'],
                          series['/wave_peak_frequency'])
    assert isinstance(pose, Series) and pose.topic == '/measured_pose' and len(pose) == N
    assert pose.values.shape == (N, 3) and wrench.values.shape == (N, 3)
    assert freq.values.shape == (N, 1)
    np.testing.assert_allclose(pose.values[:, :2], poses[:, :2], rtol=0, atol=1e-12)
    yaw_error = np.angle(np.exp(1j * (pose.values[:, 2] - poses[:, 2])))
    np.testing.assert_allclose(yaw_error, 0.0, atol=1e-12)
    assert np.all(pose.values[:, 2] > -math.pi) and np.all(pose.values[:, 2] <= math.pi)
    np.testing.assert_allclose(wrench.values, forces, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(freq.values[:, 0], freqs)
    # Header stamps are exact to the nanosecond; log times carry the written latency.
    np.testing.assert_array_equal(pose.stamp, expected_stamp)
    np.testing.assert_array_equal(wrench.stamp, expected_stamp)
    np.testing.assert_array_equal(pose.log_time, _seconds(stamp_ns, LATENCY_NS))
    np.testing.assert_array_equal(wrench.log_time, _seconds(stamp_ns, LATENCY_NS + 1))
    # Float64 has no header: its stamp is its log time.
    np.testing.assert_array_equal(freq.stamp, freq.log_time)
    np.testing.assert_array_equal(freq.log_time, _seconds(stamp_ns, LATENCY_NS + 2))


def test_reads_from_an_open_reader_and_leaves_it_open(bag: Path) -> None:
    with BagReader(bag) as reader:
        first = read_series(reader, ['/thrust'])['/thrust']
        again = read_series(reader, ['/thrust'])['/thrust']  # still usable
    np.testing.assert_array_equal(first.values, again.values)
    assert len(first) == N


def test_missing_topic_names_it_and_lists_the_bags_topics(bag: Path) -> None:
    with pytest.raises(BagError) as info:
        read_series(bag, ['/measured_pose', '/lf_pose'])
    text = str(info.value)
    assert "'/lf_pose'" in text and '/measured_pose' in text and '/thrust' in text


def test_unsupported_type_is_refused_with_its_name(bag: Path) -> None:
    with pytest.raises(BagError, match=r"'/note'.*std_msgs/msg/String"):
        read_series(bag, ['/note'])


def test_empty_topic_list_gives_empty_dict(bag: Path) -> None:
    assert read_series(bag, []) == {}


def test_read_diagnostics_flattens_every_status(bag: Path) -> None:
    records = read_diagnostics(bag)
    assert len(records) == 2 * 4  # 4 arrays of 2 statuses each
    ours = [r for r in records if r[1] == 'predictor: lf']
    assert [r[2]['trainings'] for r in ours] == ['0', '1', '2', '3']
    assert all(r[2]['state'] == 'trained' for r in ours)
    expected = _seconds([START_NS + k * STEP_NS for k in (0, 10, 20, 30)])
    assert [r[0] for r in ours] == expected.tolist()
    # The second status shares its array's header stamp; its values are empty.
    others = [r for r in records if r[1] == 'other']
    assert [r[0] for r in others] == [r[0] for r in ours] and all(r[2] == {} for r in others)


def test_read_diagnostics_missing_topic_and_wrong_type(bag: Path) -> None:
    with pytest.raises(BagError, match="'/nope'"):
        read_diagnostics(bag, '/nope')
    with pytest.raises(BagError, match='DiagnosticArray'):
        read_diagnostics(bag, '/measured_pose')


def test_unset_diagnostics_stamp_falls_back_to_log_time(tmp_path: Path) -> None:
    path = tmp_path / 'd.mcap'
    with BagWriter(path) as writer:
        channel = writer.add_topic('/diagnostics', DIAG)
        writer.write(channel, 7_500_000_000,
                     serialize(make_diagnostic_array('n', 'OK', 'm', {'a': 1.5})))
    assert read_diagnostics(path) == [(7.5, 'n', {'a': '1.5'})]
