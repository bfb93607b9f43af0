"""`play`: publish a bag's messages on their ROS topics in (scaled) real time, with /clock.

    play BAG [--rate R] [--loop] [--topics T [T ...]] [--clock] [--clock-rate HZ]
             [--delay S] [--wait-for-subscribers S] [--wait-for-all-acked S]
             [--ros-args ...]

For stacks without rosbag2. BAG is an `.mcap` file or a rosbag2 directory. Messages go out as
the recorded CDR bytes (rclpy publishes serialized data directly), in log-time order, the
message with log time t at wall time w_first + (t - t_first) / R, w_first being when the
first message went out. Each publisher offers the recorded reliability and durability (first
recorded profile, rosbag2's rule) with keep_last 10, or reliable / volatile / keep_last 10 when
the bag has no QoS metadata.

With `--clock`, `/clock` (rosgraph_msgs/Clock, reliable, keep_last 10, so it matches both
reliable and best-effort subscribers) carries the bag time: just before each message whose log
time is later than the last published clock, and at `--clock-rate` Hz while waiting. A `/clock`
topic recorded in the bag is then not replayed. After a `--loop` restart the clock jumps back.

At the end of the bag `play` waits (up to `--wait-for-all-acked` seconds, default 5) until every
reliable subscriber has acknowledged every message, as rosbag2's option of that name does. A
sample lost on the way (a full receive buffer on a loaded machine) is repaired only after the
writer's next heartbeat, and DDS writers send one every few seconds (Fast DDS: 3 s); a writer
destroyed before that takes the repair with it, and the subscriber never sees the bag's last
messages. Best-effort subscribers (the predictor's sensor QoS) send no acknowledgements and cost
no wait. A topic still unacknowledged at the timeout is named in a warning.

Exits 0 at the end of the bag, 1 on an unreadable bag or an unknown message type, and 0 on
Ctrl-C / SIGTERM.
"""
# rclpy's API is partly untyped (QoSProfile, loggers).
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass
import sys
import time
from typing import Any

import rclpy
from rclpy.context import Context
from rclpy.duration import Duration
from rclpy.logging import get_logger
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.utilities import get_default_context, remove_ros_args, try_shutdown
from rosgraph_msgs.msg import Clock

from lf_predictor_ros.bag.mcap_reader import BagError, BagReader
from lf_predictor_ros.bag.ros_codec import message_class, qos_from_yaml

CLOCK_TOPIC = '/clock'
CLOCK_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
_MAX_SLEEP = 0.05  # [s] longest sleep between checks for shutdown
# [s] the end's wait for acknowledgements: above Fast DDS's 3 s heartbeat period, after which a
# reliable reader's acknowledgement (or its request to repeat a lost sample) comes.
DEFAULT_ACK_TIMEOUT = 5.0
# Not the node's name: rosout would try (and fail) to publish records made after a signal.
LOGGER_NAME = 'lf_predictor_ros.play'


@dataclass(frozen=True)
class PlayOptions:
    """Command-line options of `play`."""

    bag: str
    rate: float
    loop: bool
    topics: list[str] | None
    clock: bool
    clock_rate: float
    delay: float
    wait_for_subscribers: float
    wait_for_all_acked: float = DEFAULT_ACK_TIMEOUT


def parse_args(args: Sequence[str] | None) -> PlayOptions:
    """Parse the non-ROS arguments (`--help` exits 0 here, before rclpy starts)."""
    parser = argparse.ArgumentParser(
        prog='play',
        description='Publish the messages of an MCAP bag on ROS topics in scaled real time.')
    parser.add_argument('bag', help='.mcap file or rosbag2 directory')
    parser.add_argument('--rate', type=float, default=1.0,
                        help='playback speed factor (default 1.0 = real time)')
    parser.add_argument('--loop', action='store_true', help='start over at the end')
    parser.add_argument('--topics', nargs='+', metavar='TOPIC',
                        help='only these topics (default: all)')
    parser.add_argument('--clock', action='store_true',
                        help='publish the bag time on /clock (for use_sim_time)')
    parser.add_argument('--clock-rate', type=float, default=40.0, metavar='HZ',
                        help='/clock rate while waiting between messages (default 40)')
    parser.add_argument('--delay', type=float, default=0.0, metavar='S',
                        help='wait S seconds before the first message (default 0)')
    parser.add_argument('--wait-for-subscribers', type=float, default=0.0, metavar='S',
                        help='wait up to S seconds until every topic has a subscriber')
    parser.add_argument('--wait-for-all-acked', type=float, default=DEFAULT_ACK_TIMEOUT,
                        metavar='S',
                        help='at the end, wait up to S seconds until every reliable subscriber '
                             f'acknowledged every message (default {DEFAULT_ACK_TIMEOUT:g}; '
                             '0: do not wait)')
    argv = remove_ros_args(list(args) if args is not None else sys.argv)
    ns = parser.parse_args(argv[1:])
    if not ns.rate > 0.0:
        parser.error(f'--rate must be > 0, got {ns.rate}')
    if not ns.clock_rate > 0.0:
        parser.error(f'--clock-rate must be > 0 Hz, got {ns.clock_rate}')
    if not (ns.delay >= 0.0 and ns.wait_for_subscribers >= 0.0
            and ns.wait_for_all_acked >= 0.0):
        parser.error('--delay, --wait-for-subscribers and --wait-for-all-acked must be >= 0 s')
    return PlayOptions(ns.bag, ns.rate, ns.loop, ns.topics, ns.clock, ns.clock_rate, ns.delay,
                       ns.wait_for_subscribers, ns.wait_for_all_acked)


def clock_message(time_ns: int) -> Clock:
    """rosgraph_msgs/Clock for a time in nanoseconds."""
    message = Clock()
    message.clock.sec = time_ns // 1_000_000_000
    message.clock.nanosec = time_ns % 1_000_000_000
    return message


class Player:
    """Publishes one bag through a node; `play_once()` plays it from start to end."""

    def __init__(self, node: Node, reader: BagReader, options: PlayOptions) -> None:
        self._node = node
        self._reader = reader
        self._options = options
        infos = reader.topic_infos()
        selected = options.topics if options.topics is not None else list(infos)
        if options.clock:
            selected = [t for t in selected if t != CLOCK_TOPIC]
        self.topics = selected
        self._publishers: dict[str, Publisher] = {
            topic: node.create_publisher(message_class(infos[topic].type_name), topic,
                                         qos_from_yaml(infos[topic].offered_qos_profiles))
            for topic in selected
        }
        self._clock_publisher = (node.create_publisher(Clock, CLOCK_TOPIC, CLOCK_QOS)
                                 if options.clock else None)
        self._last_clock_ns = -1
        self.published = 0

    def _all_publishers(self) -> dict[str, Publisher]:
        """Every publisher by topic: the bag's topics, and /clock with ``--clock``."""
        publishers = dict(self._publishers)
        if self._clock_publisher is not None:
            publishers[CLOCK_TOPIC] = self._clock_publisher
        return publishers

    def wait_for_subscribers(self, context: Context) -> None:
        """Wait until every publisher (and /clock) has a subscriber, or the timeout passes."""
        deadline = time.monotonic() + self._options.wait_for_subscribers
        publishers = list(self._all_publishers().values())
        while context.ok() and time.monotonic() < deadline and any(
                p.get_subscription_count() == 0 for p in publishers):
            time.sleep(0.01)

    def wait_for_all_acked(self) -> list[str]:
        """Wait until reliable subscribers acknowledged everything; the topics that did not.

        One deadline for all publishers (`wait_for_all_acked` seconds from now).
        """
        deadline = time.monotonic() + self._options.wait_for_all_acked
        unacknowledged = []
        for topic, publisher in self._all_publishers().items():
            left = max(0.0, deadline - time.monotonic())
            if not publisher.wait_for_all_acked(Duration(seconds=left)):
                unacknowledged.append(topic)
        return unacknowledged

    def play_once(self, context: Context) -> bool:
        """Play the bag once; False if shutdown interrupted it.

        The schedule starts when the first message has gone out: a stall before that (reading
        the first chunk, a DDS writer's first send, a loaded machine) delays the whole bag
        instead of sending its first seconds in one burst. A stall later is caught up at once.
        """
        rate = self._options.rate
        self._last_clock_ns = -1
        anchor: tuple[float, int] | None = None  # (wall time, log time) of the first message
        for message in self._reader.messages(self.topics):
            if anchor is not None:
                due = anchor[0] + (message.log_time_ns - anchor[1]) / 1e9 / rate
                if not self._wait_until(due, anchor[0], anchor[1], context):
                    return False
            elif not context.ok():
                return False
            self._publish_clock(message.log_time_ns)
            self._publishers[message.topic].publish(message.data)
            self.published += 1
            if anchor is None:
                anchor = (time.monotonic(), message.log_time_ns)
        return context.ok()

    def _wait_until(self, due: float, wall_start: float, start_ns: int,
                    context: Context) -> bool:
        """Sleep until wall time `due`, publishing /clock at clock_rate meanwhile.

        `wall_start` is the wall time at which the bag time was `start_ns`.
        """
        period = 1.0 / self._options.clock_rate
        while True:
            if not context.ok():
                return False
            now = time.monotonic()
            if now >= due:
                return True
            if self._clock_publisher is not None and self._last_clock_ns >= 0:
                bag_now = start_ns + int((now - wall_start) * self._options.rate * 1e9)
                self._publish_clock(bag_now)
            time.sleep(min(due - now, period, _MAX_SLEEP))

    def _publish_clock(self, time_ns: int) -> None:
        if self._clock_publisher is None or time_ns <= self._last_clock_ns:
            return
        self._clock_publisher.publish(clock_message(time_ns))
        self._last_clock_ns = time_ns


def _sleep(seconds: float, context: Context) -> None:
    deadline = time.monotonic() + seconds
    while context.ok() and time.monotonic() < deadline:
        time.sleep(min(_MAX_SLEEP, max(0.0, deadline - time.monotonic())))


def run(options: PlayOptions, args: Sequence[str] | None = None) -> int:
    """Open the bag, start rclpy, play; returns the exit code."""
    logger = get_logger(LOGGER_NAME)
    try:
        reader = BagReader(options.bag)
        unknown = set(options.topics or []) - set(reader.topics())
        if unknown:
            raise BagError(f'topics {sorted(unknown)} are not in the bag; it has '
                           f'{sorted(reader.topics())}')
    except BagError as err:
        logger.error(str(err))
        return 1
    # The default context: rclpy's SIGINT/SIGTERM handler shuts it down.
    rclpy.init(args=None if args is None else list(args))
    context = get_default_context()
    node: Any = None
    player: Player | None = None
    try:
        node = Node('play', context=context)
        player = Player(node, reader, options)
        player.wait_for_subscribers(context)
        _sleep(options.delay, context)
        while player.play_once(context) and options.loop:
            pass
        if context.ok() and options.wait_for_all_acked > 0.0:
            late = player.wait_for_all_acked()
            if late:
                logger.warning(
                    f'subscribers on {late} did not acknowledge every message within '
                    f'{options.wait_for_all_acked:g} s; they may have missed the last ones '
                    '(a longer --wait-for-all-acked gives them more time)')
        return 0
    except KeyboardInterrupt:  # SIGINT: rclpy chains to Python's handler
        return 0
    except ValueError as err:  # unknown message type, corrupt chunk (BagError)
        logger.error(str(err))
        return 1
    finally:
        if player is not None:
            logger.info(f'published {player.published} messages from {reader.path}')
        reader.close()
        if node is not None:
            node.destroy_node()
        try_shutdown(context=context)


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of the `play` executable."""
    return run(parse_args(args), args)


if __name__ == '__main__':
    sys.exit(main())
