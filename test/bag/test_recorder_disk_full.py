"""Disk full while recording: one clear error, writing stops, node keeps running, file recoverable.

Three levels: the writer alone (a file object that runs out of room after N bytes), the real
recorder node in-process (its message callback and flush timer called directly), and the recorder
as a process over DDS with a real file-size limit (RLIMIT_FSIZE, SIGXFSZ ignored, so write()
fails with EFBIG exactly as on a full disk).
"""
# rclpy and mcap are partly untyped.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

from collections.abc import Callable, Iterator
import errno
import os
from pathlib import Path
import signal
import subprocess
import sys
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy

from lf_predictor_ros.bag.mcap_reader import BagReader, recover
from lf_predictor_ros.bag.mcap_writer import BagWriteError, BagWriter
from lf_predictor_ros.bag.recorder_node import RecorderNode
from lf_predictor_ros.bag.ros_codec import deserialize, serialize

pytestmark = pytest.mark.filterwarnings('ignore::DeprecationWarning:lark.*')

REPO = Path(__file__).resolve().parents[2]
POSE_TYPE = 'geometry_msgs/msg/PoseStamped'
CHUNK_SIZE = 1024  # [bytes] small chunks: a few poses each, so several finish before the limit
ROOM = 3500  # [bytes] free space after the header: about three 1 KiB chunks fit
N_POSES = 120
MATCH_TIMEOUT = 15.0  # [s] recorder start-up + discovery on a loaded machine
EXIT_TIMEOUT = 10.0  # [s]
NS_PER_S = 1_000_000_000  # [ns/s]


class _FullDisk:
    """A raw file whose disk fills after ``room`` more bytes: short write, then ``err``."""

    def __init__(self, raw: Any, room: int, err: int = errno.ENOSPC) -> None:
        self._raw = raw
        self._room = room
        self._errno = err

    def write(self, data: memoryview) -> int:
        if self._room <= 0:
            raise OSError(self._errno, os.strerror(self._errno))
        written: int = self._raw.write(data[:self._room])
        self._room -= written
        return written

    def truncate(self, size: int) -> int:
        result: int = self._raw.truncate(size)
        return result

    def close(self) -> None:
        self._raw.close()


def _fill_disk(writer: BagWriter, room: int, err: int = errno.ENOSPC) -> None:
    """Let only ``room`` more bytes reach ``writer``'s file (white box: its direct stream)."""
    stream = writer._stream
    stream._raw = _FullDisk(stream._raw, room, err)


def _pose(i: int) -> PoseStamped:
    message = PoseStamped()
    message.header.frame_id = 'map_ned'
    message.header.stamp.sec = i
    message.pose.position.x = 0.25 * i
    message.pose.orientation.w = 1.0
    return message


def _xs(path: Path) -> list[float]:
    with BagReader(path) as reader:
        return [deserialize(m.data, m.type_name).pose.position.x for m in reader.messages()]


def _write_until_full(writer: BagWriter, channel: int) -> tuple[int, BagWriteError]:
    """Write poses until the writer fails; (poses handed to write(), the error)."""
    for i in range(N_POSES):
        try:
            writer.write(channel, i * NS_PER_S, serialize(_pose(i)))
        except BagWriteError as err:
            return i + 1, err
    raise AssertionError(f'{N_POSES} poses fitted into {ROOM} bytes; the test lost its point')


@pytest.mark.parametrize(('err', 'disk_full'), [(errno.ENOSPC, True), (errno.EFBIG, True),
                                                (errno.EIO, False)],
                         ids=['ENOSPC', 'EFBIG', 'EIO'])
def test_writer_stops_at_a_chunk_boundary_and_the_rest_recovers(
        tmp_path: Path, err: int, disk_full: bool) -> None:
    path = tmp_path / 'full.mcap'
    writer = BagWriter(path, chunk_size=CHUNK_SIZE, compression='none')
    channel = writer.add_topic('/measured_pose', POSE_TYPE)
    header_bytes = writer.bytes_written
    _fill_disk(writer, ROOM, err)
    attempted, error = _write_until_full(writer, channel)

    assert error.errno == err and error.disk_full is disk_full
    assert ('disk full' in str(error)) is disk_full and str(path) in str(error)
    kept = writer.message_count - writer.lost_count
    assert writer.message_count == attempted and 0 < writer.lost_count < attempted
    # Cut back to the end of the last complete chunk: nothing partial stays in the file.
    assert path.stat().st_size == error.bytes_kept == writer.bytes_written
    # The disk took header + ROOM bytes; the partial chunk at the end was cut off again.
    assert header_bytes < error.bytes_kept < header_bytes + ROOM
    with BagReader(path) as reader:
        assert reader.problem == f'file ends at byte {error.bytes_kept} without a data end record'
    assert f'after {error.bytes_kept} bytes' in str(error) and f'{kept} messages' in str(error)
    # Stopped for good: write raises the same error, flush and close do not raise.
    with pytest.raises(BagWriteError):
        writer.write(channel, attempted * NS_PER_S, serialize(_pose(attempted)))
    writer.flush()
    writer.close()
    assert writer.closed and path.stat().st_size == error.bytes_kept

    expected = [0.25 * i for i in range(kept)]
    assert kept >= 2 and _xs(path) == expected
    fixed = tmp_path / 'fixed.mcap'
    assert recover(path, fixed) == kept
    with BagReader(fixed, allow_incomplete=False) as reader:
        assert reader.complete
    assert _xs(fixed) == expected


def test_summary_that_does_not_fit_leaves_the_chunks_readable(tmp_path: Path) -> None:
    path = tmp_path / 'summary.mcap'
    writer = BagWriter(path, chunk_size=1 << 20, compression='none')
    channel = writer.add_topic('/measured_pose', POSE_TYPE)
    for i in range(10):
        writer.write(channel, i * NS_PER_S, serialize(_pose(i)))
    writer.flush()
    on_disk = writer.bytes_written
    _fill_disk(writer, 100)  # the metadata record and summary need well over 100 bytes
    with pytest.raises(BagWriteError, match='disk full'):
        writer.close()
    assert writer.closed and writer.lost_count == 0
    assert path.stat().st_size == on_disk
    assert _xs(path) == [0.25 * i for i in range(10)]


@pytest.fixture
def executor(ros_context: Any) -> Iterator[SingleThreadedExecutor]:
    ex = SingleThreadedExecutor(context=ros_context)
    yield ex
    ex.shutdown()


def _recorder(context: Any, output: Path) -> RecorderNode:
    return RecorderNode(context=context, parameter_overrides=[
        Parameter('output', value=str(output)), Parameter('topics', value=['/measured_pose']),
        Parameter('chunk_size', value=CHUNK_SIZE), Parameter('compression', value='none')])


def _status_values(msg: DiagnosticArray) -> dict[str, str] | None:
    for status in msg.status:
        if status.name == 'recorder: bag':
            return {kv.key: kv.value for kv in status.values}
    return None


@pytest.mark.dds
def _collect_statuses(node: Node) -> list[dict[str, str]]:
    """Subscribe ``node`` to /diagnostics; the returned list fills with the recorder's statuses."""
    statuses: list[dict[str, str]] = []

    def on_diagnostics(msg: DiagnosticArray) -> None:
        values = _status_values(msg)
        if values is not None:
            statuses.append(values)

    node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics,
                             QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
    return statuses


def test_recorder_node_logs_once_keeps_running_and_counts_drops(
        tmp_path: Path, ros_context: Any, executor: SingleThreadedExecutor,
        capfd: pytest.CaptureFixture[str]) -> None:
    output = tmp_path / 'node.mcap'
    recorder = _recorder(ros_context, output)
    monitor = Node('monitor', context=ros_context)
    statuses = _collect_statuses(monitor)
    executor.add_node(recorder)
    executor.add_node(monitor)
    try:
        _fill_disk(recorder.writer, ROOM)
        for i in range(N_POSES):  # the message callback as the subscription calls it
            recorder._on_message('/measured_pose', POSE_TYPE, serialize(_pose(i)),
                                 {'source_timestamp': (i + 1) * NS_PER_S})
            if i % 25 == 24:
                recorder._flush()  # the steady flush timer, also after the failure
        assert recorder.failed
        kept = recorder.writer.message_count - recorder.writer.lost_count
        assert recorder.dropped_messages == N_POSES - kept
        deadline = time.monotonic() + MATCH_TIMEOUT
        # One status at the failure, then one per second (steady timer) with the count so far.
        while time.monotonic() < deadline and (
                len(statuses) < 2 or statuses[-1]['dropped_messages'] != str(N_POSES - kept)):
            executor.spin_once(timeout_sec=0.1)
        assert statuses, 'no ERROR status on /diagnostics after the write failure'
        assert statuses[-1]['dropped_messages'] == str(N_POSES - kept)
        assert statuses[-1]['messages_in_file'] == str(kept)
        assert statuses[-1]['bytes_written'] == str(output.stat().st_size)
        executor.remove_node(recorder)
    finally:
        recorder.destroy_node()  # closes what is there; must not raise
        monitor.destroy_node()
    stderr = capfd.readouterr().err
    assert stderr.count('disk full') == 1, stderr
    assert str(output) in stderr and 'run recover()' in stderr
    fixed = tmp_path / 'fixed.mcap'
    assert recover(output, fixed) == kept >= 2
    assert _xs(fixed) == [0.25 * i for i in range(kept)]


# A launcher that puts a real file-size limit on the recorder: SIGXFSZ ignored (so write()
# returns EFBIG instead of killing the process) and RLIMIT_FSIZE, both kept across exec.
_LIMITED = ('import os, resource, signal, sys\n'
            'signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n'
            'limit = int(sys.argv[1])\n'
            'resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))\n'
            'os.execv(sys.executable, [sys.executable, "-m", *sys.argv[2:]])\n')
FILE_SIZE_LIMIT = 4096  # [bytes] header + schema + a few chunks of poses


@pytest.mark.dds
def test_recorder_process_with_a_file_size_limit(
        tmp_path: Path, ros_context: Any, executor: SingleThreadedExecutor,
        dds_env: dict[str, str],
        wait_until_subscribed: Callable[[Any, subprocess.Popen[str]], None]) -> None:
    output = tmp_path / 'limited.mcap'
    env = {**dds_env, 'ROS_LOG_DIR': str(tmp_path / 'ros_log'), 'PYTHONDONTWRITEBYTECODE': '1'}
    recorder = subprocess.Popen(
        [sys.executable, '-c', _LIMITED, str(FILE_SIZE_LIMIT),
         'lf_predictor_ros.bag.recorder_node', '--ros-args', '-p', f'output:={output}',
         '-p', "topics:=['/measured_pose']", '-p', f'chunk_size:={CHUNK_SIZE}',
         '-p', 'compression:=none'],
        cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    node = Node('pose_source', context=ros_context)
    statuses = _collect_statuses(node)
    executor.add_node(node)
    try:
        publisher = node.create_publisher(PoseStamped, '/measured_pose', 10)
        wait_until_subscribed(publisher, recorder)
        for i in range(N_POSES):
            publisher.publish(_pose(i))
            time.sleep(0.005)
        deadline = time.monotonic() + MATCH_TIMEOUT
        while (not statuses or statuses[-1]['dropped_messages'] == '0' or int(
                statuses[-1]['dropped_messages']) + int(statuses[-1]['messages_in_file'])
               < N_POSES) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        assert recorder.poll() is None, 'the recorder died at the write failure'
        recorder.send_signal(signal.SIGINT)
        _, stderr = recorder.communicate(timeout=EXIT_TIMEOUT)
    finally:
        executor.remove_node(node)
        node.destroy_node()
        if recorder.poll() is None:
            recorder.kill()
            recorder.communicate(timeout=EXIT_TIMEOUT)
    assert recorder.returncode == 1, stderr  # a recording that lost data is a failure
    assert 'Traceback' not in stderr, stderr  # the whole log, to see what raised
    assert stderr.count('disk full') == 1, stderr
    assert 'File too large' in stderr and str(output) in stderr
    assert output.stat().st_size <= FILE_SIZE_LIMIT
    xs = _xs(output)
    kept = len(xs)
    assert kept >= 2 and xs == [0.25 * i for i in range(kept)]
    assert statuses, 'no ERROR status on /diagnostics'
    assert statuses[-1]['messages_in_file'] == str(kept)
    assert int(statuses[-1]['dropped_messages']) == N_POSES - kept  # every pose arrived
    fixed = tmp_path / 'fixed.mcap'
    assert recover(output, fixed) == kept
