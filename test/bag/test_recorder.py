"""recorder node over DDS: SIGINT / SIGTERM finish the file, SIGKILL loses at most a chunk."""
# rclpy and mcap are partly untyped.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
import signal
import subprocess
import sys
import time
from typing import Any

from geometry_msgs.msg import PoseStamped
import pytest
from rclpy.node import Node
from rosbags.highlevel import AnyReader
from std_msgs.msg import Float64

from lf_predictor_ros.bag.mcap_reader import BagReader, recover
from lf_predictor_ros.bag.ros_codec import deserialize

pytestmark = pytest.mark.filterwarnings('ignore::DeprecationWarning:lark.*')

REPO = Path(__file__).resolve().parents[2]
N_MESSAGES = 45  # chunks close every 10 poses (1024 B): 5 wait for the 1 s flush timer
WaitSubscribed = Callable[[Any, subprocess.Popen[str]], None]  # conftest fixture
EXIT_TIMEOUT = 10.0  # [s]


def _start_recorder(output: Path, env: dict[str, str], *extra: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, '-m', 'lf_predictor_ros.bag.recorder_node', '--ros-args',
         '-p', f'output:={output}', '-p', 'chunk_size:=1024', *extra],
        cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@pytest.fixture
def processes() -> Iterator[list[subprocess.Popen[str]]]:
    """Child processes to kill whatever happens."""
    started: list[subprocess.Popen[str]] = []
    yield started
    for process in started:
        if process.poll() is None:
            process.kill()
        process.communicate(timeout=EXIT_TIMEOUT)


def _publish_poses(context: Any, recorder: subprocess.Popen[str],
                   wait_until_subscribed: WaitSubscribed) -> list[float]:
    """Wait for the recorder's subscription, publish N poses; returns the x values sent."""
    node = Node('pose_source', context=context)
    try:
        publisher = node.create_publisher(PoseStamped, '/measured_pose', 10)
        wait_until_subscribed(publisher, recorder)
        sent = []
        for i in range(N_MESSAGES):
            message = PoseStamped()
            message.header.frame_id = 'map_ned'
            message.pose.position.x = 0.25 * i
            publisher.publish(message)
            sent.append(message.pose.position.x)
            time.sleep(0.005)
        time.sleep(0.5)  # delivery
        return sent
    finally:
        node.destroy_node()


def _xs_by_rosbags(path: Path) -> list[float]:
    with AnyReader([path]) as reader:
        assert [c.topic for c in reader.connections] == ['/measured_pose']
        messages: list[Any] = [reader.deserialize(raw, c.msgtype)
                               for c, _, raw in reader.messages()]
        return [m.pose.position.x for m in messages]


@pytest.mark.dds
@pytest.mark.parametrize('stop_signal', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_signal_finishes_the_file(tmp_path: Path, ros_context: Any, dds_env: dict[str, str],
                                  processes: list[subprocess.Popen[str]],
                                  stop_signal: signal.Signals,
                                  wait_until_subscribed: WaitSubscribed) -> None:
    output = tmp_path / 'rec.mcap'
    recorder = _start_recorder(output, dds_env)
    processes.append(recorder)
    sent = _publish_poses(ros_context, recorder, wait_until_subscribed)
    recorder.send_signal(stop_signal)
    _, stderr = recorder.communicate(timeout=EXIT_TIMEOUT)
    assert recorder.returncode == 0, stderr
    assert 'Traceback' not in stderr
    assert _xs_by_rosbags(output) == sent
    with BagReader(output, allow_incomplete=False) as reader:
        info = reader.topic_infos()['/measured_pose']
        assert info.type_name == 'geometry_msgs/msg/PoseStamped'
        assert 'reliability: reliable' in info.offered_qos_profiles  # the publisher's offer
        assert info.type_hash.startswith('RIHS01_')
        times = [m.log_time_ns for m in reader.messages()]
    assert times == sorted(times) and times[-1] - times[0] < 10 * 10**9


@pytest.mark.dds
def test_sigkill_keeps_everything_flushed(tmp_path: Path, ros_context: Any,
                                          dds_env: dict[str, str],
                                          processes: list[subprocess.Popen[str]],
                                          wait_until_subscribed: WaitSubscribed) -> None:
    output = tmp_path / 'killed.mcap'
    recorder = _start_recorder(output, dds_env)
    processes.append(recorder)
    sent = _publish_poses(ros_context, recorder, wait_until_subscribed)
    time.sleep(1.2)  # > 1 s: the recorder's steady timer has flushed the open chunk
    recorder.send_signal(signal.SIGKILL)
    recorder.communicate(timeout=EXIT_TIMEOUT)
    with BagReader(output) as reader:
        assert not reader.complete
        xs = [deserialize(m.data, m.type_name).pose.position.x for m in reader.messages()]
    assert xs == sent
    fixed = tmp_path / 'fixed.mcap'
    assert recover(output, fixed) == len(sent)
    assert _xs_by_rosbags(fixed) == sent


@pytest.mark.dds
def test_unwritable_output_exits_nonzero_without_traceback(
        tmp_path: Path, dds_env: dict[str, str],
        processes: list[subprocess.Popen[str]]) -> None:
    blocker = tmp_path / 'file'
    blocker.write_text('x')
    recorder = _start_recorder(blocker / 'rec.mcap', dds_env)
    processes.append(recorder)
    _, stderr = recorder.communicate(timeout=EXIT_TIMEOUT)
    assert recorder.returncode == 1
    assert 'cannot write bag' in stderr and 'Traceback' not in stderr


@pytest.mark.dds
def test_topic_without_type_is_recorded_after_discovery(
        tmp_path: Path, ros_context: Any, dds_env: dict[str, str],
        processes: list[subprocess.Popen[str]], wait_until_subscribed: WaitSubscribed) -> None:
    output = tmp_path / 'discovered.mcap'
    recorder = _start_recorder(output, dds_env, '-p', "topics:=['/extra']")
    processes.append(recorder)
    node = Node('extra_source', context=ros_context)
    try:
        publisher = node.create_publisher(Float64, '/extra', 10)
        wait_until_subscribed(publisher, recorder)
        for i in range(5):
            publisher.publish(Float64(data=float(i)))
            time.sleep(0.005)
        time.sleep(0.5)
    finally:
        node.destroy_node()
    recorder.send_signal(signal.SIGINT)
    recorder.communicate(timeout=EXIT_TIMEOUT)
    with BagReader(output, allow_incomplete=False) as reader:
        assert reader.topics() == {'/extra': 'std_msgs/msg/Float64'}
        values = [deserialize(m.data, m.type_name).data for m in reader.messages()]
    assert values == [0.0, 1.0, 2.0, 3.0, 4.0]


def test_help_exits_zero() -> None:
    result = subprocess.run(
        [sys.executable, '-m', 'lf_predictor_ros.bag.recorder_node', '--help'],
        cwd=REPO, capture_output=True, text=True, timeout=EXIT_TIMEOUT)
    assert result.returncode == 0
    assert 'usage: recorder' in result.stdout and 'chunk_size' in result.stdout


def test_record_qos_reliability_is_checked() -> None:
    from rclpy.qos import ReliabilityPolicy

    from lf_predictor_ros.bag.recorder_node import record_qos

    assert record_qos().reliability == ReliabilityPolicy.BEST_EFFORT
    assert record_qos('reliable').reliability == ReliabilityPolicy.RELIABLE
    assert record_qos('reliable').depth == 1000
    with pytest.raises(ValueError, match="reliability must be one of.*got 'sometimes'"):
        record_qos('sometimes')


@pytest.mark.dds
def test_a_burst_is_kept_and_a_reliable_recorder_ignores_best_effort_publishers(
        tmp_path: Path, ros_context: Any, dds_env: dict[str, str],
        processes: list[subprocess.Popen[str]], wait_until_subscribed: WaitSubscribed) -> None:
    """300 poses published at once all arrive, in order (with a depth of 100, 113 did).

    With reliability:=reliable a best-effort publisher on the topic does not match (what the
    default best_effort is for).
    """
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    output = tmp_path / 'reliable.mcap'
    recorder = _start_recorder(output, dds_env, '-p', 'reliability:=reliable')
    processes.append(recorder)
    node = Node('burst_source', context=ros_context)
    burst = 300
    try:
        publisher = node.create_publisher(PoseStamped, '/measured_pose', QoSProfile(
            depth=burst, reliability=ReliabilityPolicy.RELIABLE))
        wait_until_subscribed(publisher, recorder)
        best_effort = node.create_publisher(PoseStamped, '/measured_pose', QoSProfile(
            depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
        time.sleep(1.0)  # discovery of the new publisher
        assert best_effort.get_subscription_count() == 0
        for i in range(burst):
            message = PoseStamped()
            message.pose.position.x = float(i)
            publisher.publish(message)
        time.sleep(1.0)  # delivery and repairs
    finally:
        node.destroy_node()
    recorder.send_signal(signal.SIGINT)
    _, stderr = recorder.communicate(timeout=EXIT_TIMEOUT)
    assert recorder.returncode == 0, stderr
    with BagReader(output, allow_incomplete=False) as reader:
        xs = [deserialize(m.data, m.type_name).pose.position.x for m in reader.messages()]
    assert xs == [float(i) for i in range(burst)]


@pytest.mark.dds
def test_an_unknown_reliability_exits_1_with_the_choices(
        tmp_path: Path, dds_env: dict[str, str],
        processes: list[subprocess.Popen[str]]) -> None:
    recorder = _start_recorder(tmp_path / 'rec.mcap', dds_env, '-p', 'reliability:=sometimes')
    processes.append(recorder)
    _, stderr = recorder.communicate(timeout=EXIT_TIMEOUT)
    assert recorder.returncode == 1
    assert "reliability must be one of ['best_effort', 'reliable']" in stderr
    assert 'Traceback' not in stderr
