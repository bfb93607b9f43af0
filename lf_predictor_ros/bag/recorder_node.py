"""`recorder`: record ROS topics to an MCAP bag with rosbag2's conventions.

    recorder [--ros-args -p output:=run.mcap -p topics:="['/measured_pose', '/thrust']"]

ROS parameters (`--ros-args -p NAME:=VALUE`):
- `output` (string): bag path; default `runs/record-<YYYYmmdd-HHMMSS>.mcap` under the working
  directory. An existing file is never overwritten.
- `topics` (string array): topics to record; default every topic of the interface contract.
  An entry is `name` or `name:pkg/msg/Type`; names of the contract and names given with a type
  are subscribed at once, other names when discovery shows their type.
- `chunk_size` (int, bytes): chunk size, default 262144 (256 KiB).
- `compression` (string): `zstd` (default), `lz4` or `none`.
- `reliability` (string): `best_effort` (default) or `reliable`, the subscriptions' reliability.

Subscriptions are raw (the CDR bytes go straight to the file), volatile, keep_last 1000: the
depth absorbs about 1 s of stall at 1000 messages/s per topic (with 100, a demo run at 90x real
time lost 3-5 of every 10 samples for 13 s while the recorder was starved of CPU, and a burst of
300 poses kept 113). Best effort (the default) matches every publisher, reliable or best effort.
Reliable matches only reliable publishers (every publisher of this package and of the interface
contract is one) and also has messages lost in transport sent again: `demo` records with it.
A channel is created at a topic's first message; its `offered_qos_profiles` and
`topic_type_hash` are those of the publishers seen then.

Times: log time = receive time on the node clock, so it is simulated time when the node runs
with `use_sim_time:=true` (0 until the first /clock message arrives); publish time = the
publisher's source timestamp (system time), as rosbag2 does.

Shutdown: SIGINT and SIGTERM are handled by rclpy (the context is shut down and spin returns);
the bag is then closed in `finally`, so an interrupted recording is a finished file. A SIGKILL
loses at most the open chunk: at most `chunk_size` bytes or 1 s of data (a steady-clock timer
flushes the open chunk every second).

Disk full (or any other write error of the bag file): the recorder logs ONE error naming the
path, the bytes kept and "disk full", stops writing and keeps running (no exception leaves a
callback). The file is cut back to its last complete chunk, so it reads like one from a killed
recorder and `mcap_reader.recover` rewrites it finished. Every message received and not in the
file (the failed chunk's and all later ones) is counted in `dropped_messages`, which is published
from then on, once per second, as an ERROR status on `/diagnostics` (a healthy recorder publishes
nothing, so it never records itself). On shutdown the file is closed without a summary and the
process exits 1.
"""
# rclpy's API is partly untyped (QoSProfile, loggers, destroy_node).
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

import argparse
from collections.abc import Sequence
from datetime import datetime
import functools
import sys
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
import rclpy
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.logging import get_logger
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import remove_ros_args, try_shutdown

from lf_predictor_ros.bag.mcap_writer import (
    DEFAULT_CHUNK_SIZE,
    DEFAULT_MAX_CHUNK_DURATION,
    BagError,
    BagWriteError,
    BagWriter,
)
from lf_predictor_ros.bag.msgdefs import full_definition
from lf_predictor_ros.bag.ros_codec import message_class, publishers_qos_yaml
from lf_predictor_ros.nodes.diagnostics import DiagnosticValue, make_diagnostic_array
from lf_predictor_ros.nodes.qos import publisher_qos
from lf_predictor_ros.nodes.runner import spin_until_shutdown

# Topics of the interface contract (shared/reference/interfaces.md) and their types.
CONTRACT_TOPICS: dict[str, str] = {
    '/measured_pose': 'geometry_msgs/msg/PoseStamped',
    '/thrust': 'geometry_msgs/msg/WrenchStamped',
    '/thrust_command': 'geometry_msgs/msg/WrenchStamped',
    '/lf_pose': 'geometry_msgs/msg/PoseStamped',
    '/wave_peak_frequency': 'std_msgs/msg/Float64',
    '/truth/pose': 'geometry_msgs/msg/PoseStamped',
    '/truth/lf_pose': 'geometry_msgs/msg/PoseStamped',
    '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray',
    '/clock': 'rosgraph_msgs/msg/Clock',
}

RECORD_DEPTH = 1000  # [messages] keep_last depth of every subscription: absorbs stalls
RELIABILITY = {'best_effort': ReliabilityPolicy.BEST_EFFORT,
               'reliable': ReliabilityPolicy.RELIABLE}


def record_qos(reliability: str = 'best_effort') -> QoSProfile:
    """Subscription profile; best effort matches reliable and best-effort publishers."""
    if reliability not in RELIABILITY:
        raise ValueError(f'reliability must be one of {sorted(RELIABILITY)}, got '
                         f'{reliability!r}; best_effort records every publisher, reliable only '
                         'reliable ones, and has messages lost in transport sent again')
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=RECORD_DEPTH,
                      reliability=RELIABILITY[reliability],
                      durability=DurabilityPolicy.VOLATILE)
# Not the node's name: rosout would try (and fail) to publish records made after a signal.
LOGGER_NAME = 'lf_predictor_ros.recorder'
DISCOVERY_PERIOD = 0.5  # [s] how often to look for the types of topics given without one
STATUS_PERIOD = 1.0  # [s] /diagnostics period after a write failure (steady clock)


def default_output_path() -> str:
    """`runs/record-<local time>.mcap`."""
    return f'runs/record-{datetime.now().strftime("%Y%m%d-%H%M%S")}.mcap'


def parse_topic_entry(entry: str) -> tuple[str, str | None]:
    """`'name'` or `'name:pkg/msg/Type'` -> (name, type or None)."""
    name, _, type_name = entry.partition(':')
    if not name:
        raise ValueError(f'topic entry {entry!r} has no name; write /name or /name:pkg/msg/Type')
    return name, type_name or None


class RecorderNode(Node):
    """Subscribes raw to the topics and appends every message to a BagWriter."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('recorder', **kwargs)
        output = str(self.declare_parameter('output', '').value) or default_output_path()
        topics = list(self.declare_parameter('topics', list(CONTRACT_TOPICS)).value or [])
        chunk_size = int(self.declare_parameter('chunk_size', DEFAULT_CHUNK_SIZE).value)
        compression = str(self.declare_parameter('compression', 'zstd').value)
        self._qos = record_qos(str(self.declare_parameter('reliability', 'best_effort').value))
        self.writer = BagWriter(output, chunk_size=chunk_size, compression=compression)
        self._channels: dict[str, int] = {}
        self._waiting: set[str] = set()
        self.dropped_messages = 0  # received but not in the file (after a write failure)
        self._failure: str = ''  # the one error logged; '' while healthy
        self._diag_pub: Any = None  # created at a write failure (a healthy bag has no trace)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        for entry in topics:
            name, type_name = parse_topic_entry(str(entry))
            resolved = self.resolve_topic_name(name)
            type_name = type_name or CONTRACT_TOPICS.get(resolved)
            if type_name is None:
                self._waiting.add(resolved)
            else:
                self._subscribe(resolved, type_name)
        if self._waiting:
            self.create_timer(DISCOVERY_PERIOD, self._discover, clock=steady)
        self.create_timer(DEFAULT_MAX_CHUNK_DURATION, self._flush, clock=steady)
        self.create_timer(STATUS_PERIOD, self.publish_status, clock=steady)
        self.get_logger().info(f'recording {len(topics)} topics to {self.writer.path}')

    def _subscribe(self, topic: str, type_name: str) -> None:
        """Raw subscription; ValueError if the type's class or .msg file is not installed."""
        full_definition(type_name)  # fail here, not in the first callback
        callback = functools.partial(self._on_message, topic, type_name)
        self.create_subscription(message_class(type_name), topic, callback, self._qos,
                                 raw=True)

    def _discover(self) -> None:
        for topic, types in self.get_topic_names_and_types():
            if topic in self._waiting and types:
                self._waiting.discard(topic)
                try:
                    self._subscribe(topic, types[0])
                except ValueError as err:
                    self.get_logger().error(f'not recording {topic}: {err}')
                    continue
                self.get_logger().info(f'recording {topic} ({types[0]})')

    def _on_message(self, topic: str, type_name: str, data: bytes,
                    info: dict[str, int]) -> None:
        if self._failure:
            self.dropped_messages += 1
            return
        try:
            log_time_ns = self.get_clock().now().nanoseconds
            channel = self._channels.get(topic)
            if channel is None:
                qos_yaml, type_hash = publishers_qos_yaml(self, topic)
                channel = self.writer.add_topic(topic, type_name, qos_yaml, type_hash=type_hash)
                self._channels[topic] = channel
            publish_time_ns = int(info.get('source_timestamp', 0)) or log_time_ns
            self.writer.write(channel, log_time_ns, data, publish_time_ns)
        except BagWriteError as err:
            self._stop(err)
        except Exception as err:  # noqa: BLE001 - a callback must never kill the recorder
            self.dropped_messages += 1
            self.get_logger().error(f'message on {topic} not recorded: {err}',
                                    throttle_duration_sec=5.0)

    def _flush(self) -> None:
        """Steady timer: put the open chunk on disk (a write failure may show up here)."""
        try:
            self.writer.flush()
        except BagWriteError as err:
            self._stop(err)

    def _stop(self, err: BagWriteError) -> None:
        """After a write failure: log it once, count what is lost, report on /diagnostics."""
        if self._failure:
            return
        self._failure = str(err)
        self.dropped_messages += self.writer.lost_count
        # Not the node logger: this may run in destroy_node, after /rosout is gone.
        get_logger(LOGGER_NAME).error(f'{err}. The recorder keeps running and counts the '
                                      'messages it cannot record (dropped_messages on '
                                      '/diagnostics).')
        try:
            self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics',
                                                   publisher_qos())
        except Exception as error:  # noqa: BLE001 - e.g. the context is going down
            get_logger(LOGGER_NAME).warning(f'no /diagnostics publisher: {error}')
        self.publish_status()

    @property
    def failed(self) -> bool:
        """Whether a write failure stopped the recording."""
        return bool(self._failure)

    def publish_status(self) -> None:
        """After a write failure: one ERROR status on /diagnostics (healthy: nothing)."""
        if not self._failure or self._diag_pub is None:
            return
        writer = self.writer
        values: dict[str, DiagnosticValue] = {
            'path': str(writer.path), 'bytes_written': writer.bytes_written,
            'messages_in_file': writer.message_count - writer.lost_count,
            'dropped_messages': self.dropped_messages}
        try:
            self._diag_pub.publish(make_diagnostic_array(
                'recorder: bag', 'ERROR', self._failure, values,
                stamp=self.get_clock().now().to_msg()))
        except Exception as err:  # noqa: BLE001 - e.g. the context is going down
            get_logger(LOGGER_NAME).warning(f'recorder status not published: {err}')

    def destroy_node(self) -> None:
        """Finish the bag (or, after a write failure, close what is there), destroy the node."""
        # Not the node logger: after a signal the context is down and /rosout is gone.
        logger = get_logger(LOGGER_NAME)
        try:
            self.writer.close()
        except BagWriteError as err:  # the summary did not fit on the disk
            self._stop(err)
        except OSError as err:
            logger.error(f'closing {self.writer.path} failed: {err}')
        writer = self.writer
        if self._failure:
            logger.error(f'{writer.path} is incomplete ({writer.bytes_written} bytes, '
                         f'{writer.message_count - writer.lost_count} messages; '
                         f'{self.dropped_messages} dropped after the write failure): run '
                         'recover() on it for a finished copy')
        else:
            logger.info(f'wrote {writer.message_count} messages to {writer.path}')
        super().destroy_node()


def _parse_cli(args: Sequence[str] | None) -> None:
    """Handle --help (and reject unknown options) before rclpy starts."""
    parser = argparse.ArgumentParser(
        prog='recorder',
        description='Record ROS topics to an MCAP bag (rosbag2 conventions). Stop with Ctrl-C '
                    'or SIGTERM; the file is finished either way.',
        epilog='ROS parameters (--ros-args -p NAME:=VALUE): output (path, default '
               'runs/record-<time>.mcap), topics (string array, default the contract topics: '
               f'{", ".join(CONTRACT_TOPICS)}), chunk_size (bytes, default {DEFAULT_CHUNK_SIZE}),'
               ' compression (zstd | lz4 | none), reliability (best_effort | reliable).')
    argv = remove_ros_args(list(args) if args is not None else sys.argv)
    parser.parse_args(argv[1:])


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of the `recorder` executable; returns the exit code."""
    _parse_cli(args)
    rclpy.init(args=None if args is None else list(args))
    try:
        node = RecorderNode()
    except (BagError, ValueError) as err:
        get_logger(LOGGER_NAME).error(str(err))
        try_shutdown()
        return 1
    spin_until_shutdown(node)
    return 1 if node.failed else 0


if __name__ == '__main__':
    sys.exit(main())
