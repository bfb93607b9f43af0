"""BagWriter: round trip through our reader and rosbags, rosbag2 metadata, chunk bound, errors."""
from __future__ import annotations

from pathlib import Path
import shutil
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, WrenchStamped
from mcap.reader import make_reader
import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64
import yaml

from lf_predictor_ros.bag.mcap_reader import BagReader
from lf_predictor_ros.bag.mcap_writer import (
    BagError,
    BagWriter,
    qos_profile_dict,
    qos_profiles_yaml,
)
from lf_predictor_ros.bag.msgdefs import full_definition
from lf_predictor_ros.bag.ros_codec import deserialize, serialize
from lf_predictor_ros.nodes.conversions import odometry_to_msg

pytestmark = pytest.mark.filterwarnings('ignore::DeprecationWarning:lark.*')

TOPICS = {
    '/measured_pose': 'geometry_msgs/msg/PoseStamped',
    '/thrust': 'geometry_msgs/msg/WrenchStamped',
    '/wave_peak_frequency': 'std_msgs/msg/Float64',
    '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray',
    '/clock': 'rosgraph_msgs/msg/Clock',
    '/lf_odom': 'nav_msgs/msg/Odometry',
}
SAMPLE_NS = 100_000_000  # [ns] 10 Hz


def _messages(seed: int, n: int) -> list[tuple[str, int, Any]]:
    """(topic, log time ns, message) with random field values, several per sample time."""
    rng = np.random.default_rng(seed)
    out: list[tuple[str, int, Any]] = []
    for i in range(n):
        t_ns = 1_700_000_000_000_000_000 + i * SAMPLE_NS
        pose = PoseStamped()
        pose.header.stamp.sec, pose.header.stamp.nanosec = divmod(t_ns, 10**9)
        pose.header.frame_id = 'map_ned'
        pose.pose.position.x, pose.pose.position.y = rng.normal(0.0, 5.0, 2)
        pose.pose.orientation.z, pose.pose.orientation.w = np.sin(0.1 * i), np.cos(0.1 * i)
        wrench = WrenchStamped()
        wrench.header.frame_id = 'base_link_fsd'
        wrench.wrench.force.x, wrench.wrench.force.y, wrench.wrench.torque.z = rng.normal(
            0.0, 1e5, 3)
        odom = odometry_to_msg(
            pose.header.stamp, [pose.pose.position.x, pose.pose.position.y, 0.1 * i],
            np.diag(rng.uniform(0.01, 1.0, 3)), rng.normal(0.0, 0.5, 3),
            np.diag(rng.uniform(1e-4, 1e-2, 3)))
        out += [('/measured_pose', t_ns, pose), ('/thrust', t_ns + 1, wrench),
                ('/clock', t_ns, Clock(clock=pose.header.stamp)), ('/lf_odom', t_ns + 4, odom)]
        if i % 3 == 0:
            frequency = Float64(data=float(rng.uniform(0.3, 1.2)))
            out.append(('/wave_peak_frequency', t_ns + 2, frequency))
        if i % 5 == 0:
            status = DiagnosticStatus(level=DiagnosticStatus.OK, name='predictor',
                                      message=f'trained {i}',
                                      values=[KeyValue(key='loss', value=f'{rng.random():.6f}')])
            out.append(('/diagnostics', t_ns + 3, DiagnosticArray(status=[status, status])))
    return out


def _write(path: Path, messages: list[tuple[str, int, Any]], **options: Any) -> None:
    with BagWriter(path, **options) as writer:
        channels = {topic: writer.add_topic(topic, type_name)
                    for topic, type_name in TOPICS.items()}
        for topic, t_ns, message in messages:
            writer.write(channels[topic], t_ns, serialize(message))


@pytest.mark.parametrize('compression', ['zstd', 'lz4', 'none'])
def test_round_trip_through_our_reader(tmp_path: Path, compression: str) -> None:
    written = _messages(seed=1, n=40)
    path = tmp_path / 'run.mcap'
    _write(path, written, chunk_size=2048, compression=compression)
    with BagReader(path) as reader:
        assert reader.complete and reader.problem is None
        assert reader.topics() == TOPICS
        read = list(reader.messages())
        infos = reader.topic_infos()
    assert len(read) == len(written) == reader.message_count
    expected = sorted(written, key=lambda m: m[1])  # log-time order (stable for ties)
    for (topic, t_ns, message), got in zip(expected, read, strict=True):
        assert (got.topic, got.type_name, got.log_time_ns) == (topic, TOPICS[topic], t_ns)
        assert deserialize(got.data, got.type_name) == message
    for topic, info in infos.items():
        assert info.message_count == sum(1 for m in written if m[0] == topic)
        assert (info.message_encoding, info.schema_encoding) == ('cdr', 'ros2msg')
        assert info.definition == full_definition(info.type_name)


def test_rosbags_reads_our_file_field_by_field(tmp_path: Path) -> None:
    written = _messages(seed=2, n=30)
    path = tmp_path / 'run.mcap'
    _write(path, written, chunk_size=4096)
    by_topic: dict[str, list[Any]] = {topic: [] for topic in TOPICS}
    with AnyReader([path]) as reader:
        assert {c.topic: c.msgtype for c in reader.connections} == TOPICS
        counts = {c.topic: c.msgcount for c in reader.connections}
        for connection, t_ns, raw in reader.messages():
            by_topic[connection.topic].append((t_ns, reader.deserialize(raw, connection.msgtype)))
        ext: Any = reader.connections[0].ext
        qos = ext.offered_qos_profiles
    assert qos[0].depth == 10 and qos[0].reliability.name == 'RELIABLE'
    for topic in TOPICS:
        mine = [(t, m) for top, t, m in written if top == topic]
        assert counts[topic] == len(mine) == len(by_topic[topic])
        for (t_ns, ours), (t_theirs, theirs) in zip(mine, by_topic[topic], strict=True):
            assert t_theirs == t_ns
            if topic == '/measured_pose':
                assert theirs.header.frame_id == ours.header.frame_id
                assert theirs.header.stamp.sec == ours.header.stamp.sec
                assert theirs.pose.position.x == ours.pose.position.x
                assert theirs.pose.position.y == ours.pose.position.y
                assert theirs.pose.orientation.z == ours.pose.orientation.z
                assert theirs.pose.orientation.w == ours.pose.orientation.w
            elif topic == '/thrust':
                assert theirs.wrench.force.x == ours.wrench.force.x
                assert theirs.wrench.force.y == ours.wrench.force.y
                assert theirs.wrench.torque.z == ours.wrench.torque.z
            elif topic == '/wave_peak_frequency':
                assert theirs.data == ours.data
            elif topic == '/lf_odom':
                assert (theirs.header.frame_id, theirs.child_frame_id) == (
                    ours.header.frame_id, ours.child_frame_id)
                assert theirs.pose.pose.position.x == ours.pose.pose.position.x
                assert theirs.pose.pose.orientation.z == ours.pose.pose.orientation.z
                assert list(theirs.pose.covariance) == list(ours.pose.covariance)
                assert theirs.twist.twist.angular.z == ours.twist.twist.angular.z
                assert list(theirs.twist.covariance) == list(ours.twist.covariance)
            elif topic == '/clock':
                assert (theirs.clock.sec, theirs.clock.nanosec) == (ours.clock.sec,
                                                                    ours.clock.nanosec)
            else:
                assert [s.message for s in theirs.status] == [s.message for s in ours.status]
                assert theirs.status[1].values[0].value == ours.status[1].values[0].value


def test_file_carries_rosbag2_metadata_summary_and_schemas(tmp_path: Path) -> None:
    written = _messages(seed=3, n=20)
    path = tmp_path / 'run.mcap'
    _write(path, written)
    with path.open('rb') as stream:
        reader = make_reader(stream)
        header = reader.get_header()
        summary = reader.get_summary()
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    assert header.profile == 'ros2'
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == len(written)
    assert summary.statistics.message_start_time == min(m[1] for m in written)
    assert summary.statistics.message_end_time == max(m[1] for m in written)
    schemas = {s.name: s for s in summary.schemas.values()}
    assert set(schemas) == set(TOPICS.values())
    pose_schema = schemas['geometry_msgs/msg/PoseStamped']
    assert pose_schema.encoding == 'ros2msg'
    assert pose_schema.data.decode() == full_definition('geometry_msgs/msg/PoseStamped')
    assert 'MSG: std_msgs/Header' in pose_schema.data.decode()
    odom_schema = schemas['nav_msgs/msg/Odometry'].data.decode()
    assert odom_schema == full_definition('nav_msgs/msg/Odometry')
    for dependency in ('geometry_msgs/PoseWithCovariance', 'geometry_msgs/TwistWithCovariance',
                       'geometry_msgs/Quaternion', 'std_msgs/Header'):
        assert f'MSG: {dependency}' in odom_schema
    for channel in summary.channels.values():
        assert channel.message_encoding == 'cdr'
        assert yaml.safe_load(channel.metadata['offered_qos_profiles'])[0]['depth'] == 10
    bag_info = yaml.safe_load(metadata['rosbag2']['serialized_metadata'])
    assert bag_info['version'] == 9 and bag_info['storage_identifier'] == 'mcap'
    assert bag_info['message_count'] == len(written)
    assert bag_info['starting_time']['nanoseconds_since_epoch'] == written[0][1]
    assert bag_info['duration']['nanoseconds'] == max(m[1] for m in written) - written[0][1]
    counts = {t['topic_metadata']['name']: t['message_count']
              for t in bag_info['topics_with_message_count']}
    assert counts == {topic: sum(1 for m in written if m[0] == topic) for topic in TOPICS}


def test_custom_data_round_trips_through_the_rosbag2_metadata(tmp_path: Path) -> None:
    path = tmp_path / 'custom.mcap'
    custom = {'lf_predictor_ros.recording_loop': 'estimator', 'vessel': 'supply 76 m: ä'}
    with BagWriter(path, custom_data=custom) as writer:
        writer.write(writer.add_topic('/x', 'std_msgs/msg/Float64'), 5, serialize(Float64()))
    with path.open('rb') as stream:
        metadata = {m.name: m.metadata for m in make_reader(stream).iter_metadata()}
    assert yaml.safe_load(metadata['rosbag2']['serialized_metadata'])['custom_data'] == custom
    with BagReader(path) as reader:
        assert reader.custom_data() == custom
    plain = tmp_path / 'plain.mcap'
    _write(plain, _messages(seed=4, n=3))
    with BagReader(plain) as reader:
        assert reader.custom_data() == {}
    for bad in ({'': 'x'}, {'seed': 5}):
        with pytest.raises(BagError, match='custom_data must map non-empty strings'):
            BagWriter(tmp_path / 'bad.mcap', custom_data=bad)  # type: ignore[dict-item]
    assert not (tmp_path / 'bad.mcap').exists()


def test_sigkill_loses_at_most_the_open_chunk(tmp_path: Path) -> None:
    """A copy of the file taken while the writer is open is what a SIGKILL leaves behind."""
    path = tmp_path / 'live.mcap'
    writer = BagWriter(path, chunk_size=1 << 20, max_chunk_duration=1.0)
    channel = writer.add_topic('/wave_peak_frequency', 'std_msgs/msg/Float64')
    for i in range(25):  # 0.1 s apart: a chunk closes when its span reaches 1.0 s (11 messages)
        writer.write(channel, i * SAMPLE_NS, serialize(Float64(data=float(i))))
    killed = tmp_path / 'killed.mcap'
    shutil.copyfile(path, killed)
    writer.close()
    with BagReader(killed) as reader:
        assert not reader.complete
        values = [deserialize(m.data, m.type_name).data for m in reader.messages()]
    assert values == [float(i) for i in range(22)]  # 2 closed chunks of 11; 3 in the open one
    with pytest.raises(BagError, match='recover'):
        BagReader(killed, allow_incomplete=False)


def test_chunk_size_bounds_chunks(tmp_path: Path) -> None:
    path = tmp_path / 'small_chunks.mcap'
    payload = bytes(1000)  # opaque bytes: the writer does not parse them
    with BagWriter(path, chunk_size=4000, compression='none') as writer:
        channel = writer.add_topic('/wave_peak_frequency', 'std_msgs/msg/Float64')
        for i in range(20):
            writer.write(channel, i, payload)
    with path.open('rb') as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and summary.statistics is not None
    # 4 messages of 1031 bytes reach 4000 bytes: 20 messages make 5 chunks.
    assert summary.statistics.chunk_count == 5
    assert all(index.uncompressed_size < 4000 + 1031 + 2048 for index in summary.chunk_indexes)


def test_close_is_idempotent_and_deferred_inside_a_write(tmp_path: Path) -> None:
    path = tmp_path / 'run.mcap'
    writer = BagWriter(path)
    channel = writer.add_topic('/wave_peak_frequency', 'std_msgs/msg/Float64')
    with writer._guard('write'):  # what a signal handler interrupting write() sees
        writer.close()
        assert not writer.closed
    assert writer.closed
    writer.close()
    with pytest.raises(BagError, match='is closed'):
        writer.write(channel, 0, serialize(Float64()))
    with BagReader(path) as reader:
        assert reader.complete and reader.topics() == {
            '/wave_peak_frequency': 'std_msgs/msg/Float64'}


def test_bad_paths_and_arguments_raise_clear_errors(tmp_path: Path) -> None:
    blocker = tmp_path / 'a_file'
    blocker.write_text('x')
    with pytest.raises(BagError, match='cannot write bag'):
        BagWriter(blocker / 'run.mcap')
    existing = tmp_path / 'exists.mcap'
    existing.write_bytes(b'')
    with pytest.raises(BagError, match='exists already'):
        BagWriter(existing)
    with pytest.raises(BagError, match='compression must be one of'):
        BagWriter(tmp_path / 'x.mcap', compression='gzip')
    with pytest.raises(BagError, match='chunk_size'):
        BagWriter(tmp_path / 'y.mcap', chunk_size=0)
    with BagWriter(tmp_path / 'nested' / 'dir' / 'z.mcap') as writer:  # parents are created
        writer.add_topic('/thrust', 'geometry_msgs/msg/WrenchStamped')
        with pytest.raises(BagError, match='one type per topic'):
            writer.add_topic('/thrust', 'std_msgs/msg/Float64')
        with pytest.raises(BagError, match='unknown channel id 7'):
            writer.write(7, 0, b'')


def test_qos_yaml_is_what_rosbags_parses() -> None:
    from rosbags.rosbag2.metadata import parse_qos

    text = qos_profiles_yaml([qos_profile_dict(reliability='best_effort',
                                               durability='transient_local', depth=5,
                                               deadline_ns=1_500_000_000)])
    (qos,) = parse_qos(text)
    assert (qos.reliability.name, qos.durability.name, qos.history.name, qos.depth) == (
        'BEST_EFFORT', 'TRANSIENT_LOCAL', 'KEEP_LAST', 5)
    assert (qos.deadline.sec, qos.deadline.nsec) == (1, 500_000_000)
    assert (qos.lifespan.sec, qos.lifespan.nsec) == (9223372036, 854775807)
