"""nodes/runner.py: a node that ends by itself flushes its reliable publishers first."""
from __future__ import annotations

from typing import Any

import pytest
import rclpy
from rclpy.duration import Duration
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from std_msgs.msg import String

from lf_predictor_ros.nodes import runner


def test_a_node_that_ends_by_itself_waits_for_its_subscribers_then_shuts_down(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Until's future done: every publisher waits for its acks first, within FLUSH_TIMEOUT.

    Then the node is destroyed and the default context shut down.
    """
    asked: list[tuple[str, float]] = []
    real = Publisher.wait_for_all_acked

    def spy(self: Publisher, timeout: Duration) -> bool:
        asked.append((self.topic_name, timeout.nanoseconds * 1e-9))
        return real(self, timeout)

    monkeypatch.setattr(Publisher, 'wait_for_all_acked', spy)
    rclpy.init()
    try:
        node = rclpy.create_node('runner_flush_test')
        node.create_publisher(String, 'reliable_out', QoSProfile(
            depth=10, reliability=ReliabilityPolicy.RELIABLE))
        node.create_subscription(String, 'reliable_out', lambda msg: None, 10)
        done: Future = Future()
        done.set_result(True)

        def until(_: Any) -> Future:
            return done

        runner.spin_until_shutdown(node, until)
        assert '/reliable_out' in [topic for topic, _ in asked]
        assert all(0.0 <= timeout <= runner.FLUSH_TIMEOUT for _, timeout in asked)
        assert not rclpy.ok()  # the context was shut down
    finally:
        rclpy.try_shutdown()


def test_flush_reports_a_subscriber_that_never_acknowledges_within_the_timeout(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A publisher whose acks never come: flush gives up after the timeout and says so."""
    monkeypatch.setattr(Publisher, 'wait_for_all_acked',
                        lambda self, timeout: False)
    rclpy.init()
    try:
        node = rclpy.create_node('runner_flush_timeout_test')
        node.create_publisher(String, 'out', 10)
        assert runner.flush(node, 0.1) is False
        node.destroy_node()
    finally:
        rclpy.try_shutdown()
