"""play over DDS: messages arrive in order, in scaled real time, with /clock."""
# rclpy and mcap are partly untyped.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

from pathlib import Path
import subprocess
import sys
import time
from typing import Any

from geometry_msgs.msg import PoseStamped
import numpy as np
import pytest
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64

from lf_predictor_ros.bag.mcap_reader import BagReader
from lf_predictor_ros.bag.mcap_writer import BagWriter
from lf_predictor_ros.bag.play import CLOCK_TOPIC, DEFAULT_ACK_TIMEOUT, Player, parse_args
from lf_predictor_ros.bag.ros_codec import serialize

pytestmark = pytest.mark.filterwarnings('ignore::DeprecationWarning:lark.*')

REPO = Path(__file__).resolve().parents[2]
START_NS = 2_000_000_000  # [ns] bag start time
SAMPLE_NS = 50_000_000  # [ns] 20 Hz poses
N_POSES = 10
RATE = 2.0  # playback speed factor
TIMEOUT = 20.0  # [s] start-up + discovery + playback on a loaded machine


def _write_bag(path: Path) -> None:
    """Poses at 20 Hz, a frequency estimate every 4th sample, and a recorded /clock."""
    with BagWriter(path) as writer:
        pose_channel = writer.add_topic('/measured_pose', 'geometry_msgs/msg/PoseStamped')
        freq_channel = writer.add_topic('/wave_peak_frequency', 'std_msgs/msg/Float64')
        clock_channel = writer.add_topic('/clock', 'rosgraph_msgs/msg/Clock')
        for i in range(N_POSES):
            t_ns = START_NS + i * SAMPLE_NS
            pose = PoseStamped()
            pose.pose.position.x = float(i)
            writer.write(pose_channel, t_ns, serialize(pose))
            writer.write(clock_channel, t_ns, serialize(Clock()))  # zeros: must not be played
            if i % 4 == 0:
                writer.write(freq_channel, t_ns + 1, serialize(Float64(data=0.1 * i)))


@pytest.mark.dds
def test_play_publishes_in_order_with_clock(tmp_path: Path, ros_context: Any,
                                            dds_env: dict[str, str]) -> None:
    bag = tmp_path / 'play.mcap'
    _write_bag(bag)
    node = Node('play_listener', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    poses: list[tuple[float, int]] = []
    frequencies: list[float] = []
    clocks: list[int] = []
    qos = QoSProfile(depth=100)

    def on_pose(message: Any, info: dict[str, int]) -> None:
        poses.append((message.pose.position.x, info['source_timestamp']))

    def on_frequency(message: Any) -> None:
        frequencies.append(message.data)

    def on_clock(message: Any) -> None:
        clocks.append(message.clock.sec * 10**9 + message.clock.nanosec)

    node.create_subscription(PoseStamped, '/measured_pose', on_pose, qos)  # type: ignore[arg-type]
    node.create_subscription(Float64, '/wave_peak_frequency', on_frequency, qos)
    node.create_subscription(Clock, '/clock', on_clock, qos)
    play = subprocess.Popen(
        [sys.executable, '-m', 'lf_predictor_ros.bag.play', str(bag), '--clock',
         '--rate', str(RATE), '--wait-for-subscribers', '10'],
        cwd=REPO, env=dds_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + TIMEOUT
        while play.poll() is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.02)
        end = time.monotonic() + 0.5  # let the last messages arrive
        while time.monotonic() < end and len(poses) < N_POSES:
            executor.spin_once(timeout_sec=0.02)
    finally:
        if play.poll() is None:
            play.kill()
        _, stderr = play.communicate(timeout=5.0)
        executor.shutdown()
        node.destroy_node()
    assert play.returncode == 0, stderr
    # Every reliable subscriber (ours) acknowledged everything before play's writers went.
    assert 'did not acknowledge' not in stderr
    assert [x for x, _ in poses] == [float(i) for i in range(N_POSES)]
    assert frequencies == pytest.approx([0.0, 0.4, 0.8])
    # Scaled real time: the last pose leaves (N - 1) * 50 ms / 2 = 225 ms after the first.
    spread = (poses[-1][1] - poses[0][1]) / 1e9
    assert 0.2 <= spread <= 0.6
    # /clock carries bag time, never the recorded zeros, ending at the last message's time.
    assert clocks and clocks == sorted(clocks)
    assert clocks[0] >= START_NS
    assert clocks[-1] == START_NS + (N_POSES - 1) * SAMPLE_NS


class _Publisher:
    """A publisher whose acknowledgements come (or not) within any timeout."""

    def __init__(self, acked: bool) -> None:
        self.acked = acked
        self.timeouts: list[float] = []

    def wait_for_all_acked(self, timeout: Duration) -> bool:
        self.timeouts.append(timeout.nanoseconds / 1e9)
        return self.acked


class _Node:
    """Hands out _Publisher objects: acknowledged except on `late_topics`."""

    def __init__(self, late_topics: set[str]) -> None:
        self.late_topics = late_topics
        self.publishers: dict[str, _Publisher] = {}

    def create_publisher(self, _type: Any, topic: str, _qos: Any) -> _Publisher:
        self.publishers[topic] = _Publisher(topic not in self.late_topics)
        return self.publishers[topic]


def test_wait_for_all_acked_names_the_topics_left_unacknowledged(tmp_path: Path) -> None:
    bag = tmp_path / 'play.mcap'
    _write_bag(bag)
    options = parse_args(['play', str(bag), '--clock', '--wait-for-all-acked', '3'])
    assert options.wait_for_all_acked == 3.0
    node = _Node({'/wave_peak_frequency'})
    with BagReader(bag) as reader:
        player = Player(node, reader, options)  # type: ignore[arg-type]
    assert player.wait_for_all_acked() == ['/wave_peak_frequency']
    # Every publisher (bag topics and /clock) was asked, within one 3 s deadline.
    assert set(node.publishers) == {'/measured_pose', '/wave_peak_frequency', CLOCK_TOPIC}
    timeouts = [t for p in node.publishers.values() for t in p.timeouts]
    assert len(timeouts) == 3 and all(0.0 <= t <= 3.0 for t in timeouts)
    assert parse_args(['play', str(bag)]).wait_for_all_acked == DEFAULT_ACK_TIMEOUT


class _StallingPublisher:
    """Logs when each message goes out; the first publish of all stalls `stall` seconds."""

    def __init__(self, topic: str, log: list[tuple[str, float]], stall: float) -> None:
        self.topic, self.log, self.stall = topic, log, stall

    def publish(self, _data: Any) -> None:
        if not self.log:
            time.sleep(self.stall)  # a DDS writer's first send on a loaded machine
        self.log.append((self.topic, time.monotonic()))


class _StallingNode:
    def __init__(self, stall: float) -> None:
        self.log: list[tuple[str, float]] = []
        self.stall = stall

    def create_publisher(self, _type: Any, topic: str, _qos: Any) -> _StallingPublisher:
        return _StallingPublisher(topic, self.log, self.stall)


class _Context:
    def ok(self) -> bool:
        return True


def test_a_stall_before_the_first_message_delays_the_bag_instead_of_bursting(
        tmp_path: Path) -> None:
    bag = tmp_path / 'play.mcap'
    _write_bag(bag)
    stall = 0.4  # [s] longer than the whole bag at RATE (225 ms)
    node = _StallingNode(stall)
    with BagReader(bag) as reader:
        options = parse_args(['play', str(bag), '--rate', str(RATE)])
        player = Player(node, reader, options)  # type: ignore[arg-type]
        assert player.play_once(_Context())  # type: ignore[arg-type]
    poses = [t for topic, t in node.log if topic == '/measured_pose']
    assert len(poses) == N_POSES and player.published == 2 * N_POSES + 3  # /clock played
    # Paced from the first message out: pose k leaves k * 50 ms / RATE after pose 0.
    gaps = np.diff(poses)
    expected = SAMPLE_NS / 1e9 / RATE
    assert gaps.min() >= 0.8 * expected
    assert poses[-1] - poses[0] == pytest.approx((N_POSES - 1) * expected, abs=0.05)


def test_negative_ack_timeout_is_a_usage_error() -> None:
    with pytest.raises(SystemExit) as exit_info:
        parse_args(['play', 'x.mcap', '--wait-for-all-acked', '-1'])
    assert exit_info.value.code == 2


def test_play_help_and_missing_bag() -> None:
    result = subprocess.run([sys.executable, '-m', 'lf_predictor_ros.bag.play', '--help'],
                            cwd=REPO, capture_output=True, text=True, timeout=TIMEOUT)
    assert result.returncode == 0 and '--rate' in result.stdout and '--clock' in result.stdout
    result = subprocess.run([sys.executable, '-m', 'lf_predictor_ros.bag.play', 'missing.mcap'],
                            cwd=REPO, capture_output=True, text=True, timeout=TIMEOUT)
    assert result.returncode == 1 and 'does not exist' in result.stderr
    assert 'Traceback' not in result.stderr
