"""BagReader: foreign bags, rosbag2 directories, damaged files, ordering, recover()."""
# rclpy and mcap are partly untyped.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

from pathlib import Path
import shutil
from typing import Any

from geometry_msgs.msg import PoseStamped
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as RosbagsWriter
from rosbags.typesys import Stores, get_typestore
from std_msgs.msg import Float64

from lf_predictor_ros.bag.mcap_reader import BagError, BagReader, recover
from lf_predictor_ros.bag.mcap_writer import BagWriter
from lf_predictor_ros.bag.msgdefs import full_definition
from lf_predictor_ros.bag.ros_codec import deserialize, serialize

pytestmark = pytest.mark.filterwarnings('ignore::DeprecationWarning:lark.*')

FLOAT = 'std_msgs/msg/Float64'
POSE = 'geometry_msgs/msg/PoseStamped'


def _float_bag(path: Path, times_ns: list[int], **options: object) -> Path:
    """A bag of Float64 messages whose data is the message index."""
    with BagWriter(path, **options) as writer:  # type: ignore[arg-type]
        channel = writer.add_topic('/wave_peak_frequency', FLOAT)
        for i, t_ns in enumerate(times_ns):
            writer.write(channel, t_ns, serialize(Float64(data=float(i))))
    return path


def _values(reader: BagReader) -> list[float]:
    return [deserialize(m.data, m.type_name).data for m in reader.messages()]


def _rosbags_bag(path: Path, storage: StoragePlugin) -> list[tuple[int, float]]:
    """A rosbag2 directory written by the rosbags library; returns (time, x) written."""
    store = get_typestore(Stores.ROS2_JAZZY)
    pose_type = store.types[POSE]
    header_type = store.types['std_msgs/msg/Header']
    time_type = store.types['builtin_interfaces/msg/Time']
    pose_inner = store.types['geometry_msgs/msg/Pose']
    point = store.types['geometry_msgs/msg/Point']
    quaternion = store.types['geometry_msgs/msg/Quaternion']
    written = []
    with RosbagsWriter(path, version=9, storage_plugin=storage) as writer:
        connection = writer.add_connection('/measured_pose', POSE, typestore=store)
        for i in range(15):
            t_ns = 5_000_000_000 + i * 100_000_000
            message = pose_type(
                header=header_type(stamp=time_type(sec=5, nanosec=i), frame_id='map_ned'),
                pose=pose_inner(position=point(x=0.5 * i, y=-1.0, z=0.0),
                                orientation=quaternion(x=0.0, y=0.0, z=0.0, w=1.0)))
            writer.write(connection, t_ns, store.serialize_cdr(message, POSE))
            written.append((t_ns, 0.5 * i))
    return written


def test_reads_rosbag2_directory_written_by_rosbags(tmp_path: Path) -> None:
    bag = tmp_path / 'rosbags_bag'
    written = _rosbags_bag(bag, StoragePlugin.MCAP)
    assert (bag / 'metadata.yaml').is_file()
    with BagReader(bag) as reader:
        assert reader.path.suffix == '.mcap' and reader.complete
        assert reader.topics() == {'/measured_pose': POSE}
        assert reader.topic_infos()['/measured_pose'].message_count == 15
        got = [(m.log_time_ns, deserialize(m.data, m.type_name)) for m in reader.messages()]
        assert 'rosbag2' in reader.metadata()
    assert [(t, msg.pose.position.x) for t, msg in got] == written
    assert all(msg.header.frame_id == 'map_ned' and msg.pose.orientation.w == 1.0
               for _, msg in got)
    with BagReader(reader.path) as direct:  # the .mcap file inside works too
        assert direct.message_count == 15


def test_sqlite_and_multi_file_directories_are_refused(tmp_path: Path) -> None:
    sqlite_bag = tmp_path / 'sqlite_bag'
    _rosbags_bag(sqlite_bag, StoragePlugin.SQLITE3)
    with pytest.raises(BagError, match="storage 'sqlite3'; only MCAP"):
        BagReader(sqlite_bag)
    empty_dir = tmp_path / 'not_a_bag'
    empty_dir.mkdir()
    with pytest.raises(BagError, match='without metadata.yaml'):
        BagReader(empty_dir)
    with pytest.raises(BagError, match='does not exist'):
        BagReader(tmp_path / 'missing.mcap')


def test_not_mcap_empty_and_foreign_profile_raise(tmp_path: Path) -> None:
    text_file = tmp_path / 'notes.mcap'
    text_file.write_text('this is not a bag\n' * 10)
    with pytest.raises(BagError, match='not an MCAP bag.*magic'):
        BagReader(text_file)
    empty = tmp_path / 'empty.mcap'
    empty.write_bytes(b'')
    with pytest.raises(BagError, match='is empty'):
        BagReader(empty)
    foreign = tmp_path / 'foreign.mcap'
    with foreign.open('wb') as stream:
        writer = Writer(stream, compression=CompressionType.NONE)
        writer.start(profile='', library='test')
        writer.finish()
    with pytest.raises(BagError, match="profile '', not a ROS 2 bag"):
        BagReader(foreign)


def test_truncated_files(tmp_path: Path) -> None:
    full = _float_bag(tmp_path / 'full.mcap', [i * 10_000_000 for i in range(300)],
                      chunk_size=600, compression='none')
    data = full.read_bytes()
    inside_header = tmp_path / 'header_cut.mcap'
    inside_header.write_bytes(data[:20])
    with pytest.raises(BagError, match='truncated inside its header'):
        BagReader(inside_header)
    half = tmp_path / 'half.mcap'
    half.write_bytes(data[:len(data) // 2])
    with pytest.raises(BagError, match='incomplete.*recover'):
        BagReader(half, allow_incomplete=False)
    with BagReader(half) as reader:
        assert not reader.complete and 'incomplete or damaged' in str(reader.problem)
        values = _values(reader)
    # Every complete chunk before the cut, in order, nothing invented.
    assert 0 < len(values) < 300
    assert values == [float(i) for i in range(len(values))]
    assert reader.message_count == len(values)


def test_corrupt_chunk_in_a_finished_file_raises(tmp_path: Path) -> None:
    path = _float_bag(tmp_path / 'ok.mcap', [i * 10_000_000 for i in range(200)],
                      chunk_size=1000, compression='zstd')
    with path.open('rb') as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    chunk = summary.chunk_indexes[2]
    data = bytearray(path.read_bytes())
    end = chunk.chunk_start_offset + chunk.chunk_length
    data[end - 24:end - 8] = b'\xff' * 16  # inside the chunk's compressed records
    damaged = tmp_path / 'damaged.mcap'
    damaged.write_bytes(bytes(data))
    with pytest.raises(BagError, match='corrupt'):
        with BagReader(damaged) as reader:
            list(reader.messages())
    # Without a summary (killed writer) the readable part ends at the damaged chunk.
    unfinished = tmp_path / 'damaged_unfinished.mcap'
    unfinished.write_bytes(bytes(data[:summary.chunk_indexes[-1].chunk_start_offset]))
    with BagReader(unfinished) as reader:
        assert not reader.complete and 'does not decode' in str(reader.problem)
        values = _values(reader)
    expected = [t for t in range(200)
                if t * 10_000_000 <= summary.chunk_indexes[1].message_end_time]
    assert values == [float(i) for i in expected]


def test_log_time_order_across_out_of_order_chunks(tmp_path: Path) -> None:
    # Chunk 1 holds t = 1.0..1.9 s, chunk 2 t = 0.0..0.9 s, chunk 3 interleaves with both.
    times = ([1_000_000_000 + i * 100_000_000 for i in range(10)]
             + [i * 100_000_000 for i in range(10)]
             + [50_000_000 + i * 200_000_000 for i in range(10)])
    path = _float_bag(tmp_path / 'jumps.mcap', times, chunk_size=10 * 39,
                      compression='none', max_chunk_duration=100.0)
    with BagReader(path) as reader:
        got = [m.log_time_ns for m in reader.messages()]
        assert reader.start_time_ns == 0 and reader.end_time_ns == 1_900_000_000
    assert got == sorted(times)
    with AnyReader([path]) as theirs:
        assert [t for _, t, _ in theirs.messages()] == sorted(times)


def test_unchunked_file_is_read(tmp_path: Path) -> None:
    path = tmp_path / 'fastwrite.mcap'
    with path.open('wb') as stream:
        writer = Writer(stream, use_chunking=False, compression=CompressionType.NONE)
        writer.start(profile='ros2', library='test')
        schema = writer.register_schema(POSE, 'ros2msg', full_definition(POSE).encode())
        channel = writer.register_channel('/measured_pose', 'cdr', schema)
        for i in range(12):
            pose = PoseStamped()
            pose.pose.position.x = float(i)
            writer.add_message(channel, (12 - i) * 1000, serialize(pose), 0)
        writer.finish()
    with BagReader(path) as reader:
        xs = [deserialize(m.data, m.type_name).pose.position.x for m in reader.messages()]
    assert xs == [float(i) for i in reversed(range(12))]  # reversed log times


def test_topic_filter(tmp_path: Path) -> None:
    path = tmp_path / 'two.mcap'
    with BagWriter(path) as writer:
        a = writer.add_topic('/a', FLOAT)
        b = writer.add_topic('/b', FLOAT)
        for i in range(10):
            writer.write(a if i % 2 else b, i, serialize(Float64(data=float(i))))
    with BagReader(path) as reader:
        assert [m.log_time_ns for m in reader.messages(['/a'])] == [1, 3, 5, 7, 9]
        with pytest.raises(BagError, match=r"\['/c'\] are not in bag"):
            list(reader.messages(['/c']))


def test_recover_keeps_the_custom_data_of_a_finished_bag(tmp_path: Path) -> None:
    source = tmp_path / 'source.mcap'
    custom = {'lf_predictor_ros.scenario': 'rao_supply'}
    with BagWriter(source, custom_data=custom) as writer:
        channel = writer.add_topic('/wave_peak_frequency', FLOAT)
        writer.write(channel, 10, serialize(Float64(data=0.6)))
    copy = tmp_path / 'copy.mcap'
    assert recover(source, copy) == 1
    with BagReader(copy) as reader:
        assert reader.custom_data() == custom
    relabelled = tmp_path / 'relabelled.mcap'
    assert recover(source, relabelled, custom_data={'a': 'b'}) == 1
    with BagReader(relabelled) as reader:
        assert reader.custom_data() == {'a': 'b'}


def test_recover_rewrites_a_killed_file_completely(tmp_path: Path) -> None:
    live = tmp_path / 'live.mcap'
    writer = BagWriter(live, chunk_size=300, compression='none')
    channel = writer.add_topic('/wave_peak_frequency', FLOAT)
    for i in range(50):
        writer.write(channel, 1000 + i, serialize(Float64(data=float(i))), publish_time_ns=7 + i)
    killed = tmp_path / 'killed.mcap'
    shutil.copyfile(live, killed)
    with BagReader(killed) as partial:
        kept = partial.message_count
    assert kept == 49  # 43-byte records close a 300-byte chunk every 7: the 50th is open
    fixed = tmp_path / 'fixed.mcap'
    assert recover(killed, fixed) == kept
    with BagReader(fixed, allow_incomplete=False) as reader:
        assert reader.complete
        info = reader.topic_infos()['/wave_peak_frequency']
        assert info.definition == full_definition(FLOAT)
        assert [p.publish_time for _, p in reader.records()] == [7 + i for i in range(kept)]
    with AnyReader([fixed]) as theirs:
        messages: list[Any] = [theirs.deserialize(raw, c.msgtype)
                               for c, _, raw in theirs.messages()]
    assert [m.data for m in messages] == [float(i) for i in range(kept)]
    writer.close()
