"""nodes/runner.py: flushing at a node's own end; freezing the heap once the node is built."""
from __future__ import annotations

import gc
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


def test_freeze_startup_heap_takes_every_live_object_out_of_the_collections() -> None:
    """What lives at the call is frozen (a full collection skips it); what comes later is not."""
    before = [1.0]
    try:
        runner.freeze_startup_heap()
        assert gc.get_freeze_count() > 1000  # pytest, rclpy, numpy: thousands of objects
        assert not any(obj is before for obj in gc.get_objects())
        after = [2.0]
        assert any(obj is after for obj in gc.get_objects())  # collected as before
    finally:
        gc.unfreeze()
    assert gc.get_freeze_count() == 0
    assert any(obj is before for obj in gc.get_objects())


def test_spin_node_freezes_the_heap_after_building_the_node_and_before_spinning(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The node's own objects are frozen too; a rejected configuration freezes nothing.

    The math libraries are put on one thread there too (`core.math_threads`).
    """
    calls: list[str] = []
    monkeypatch.setattr(runner, 'freeze_startup_heap', lambda: calls.append('freeze'))
    monkeypatch.setattr(runner, 'use_one_math_thread', lambda: calls.append('threads'))
    monkeypatch.setattr(runner, 'spin_until_shutdown', lambda node, until: calls.append('spin'))

    def make() -> Any:
        calls.append('make')
        return object()

    assert runner.spin_node(make, config_errors=(ValueError,), logger_name='freeze_test') == 0
    assert calls == ['make', 'threads', 'freeze', 'spin']

    def invalid() -> Any:
        raise ValueError('bad parameter')

    calls.clear()
    rclpy.init()
    try:
        assert runner.spin_node(invalid, config_errors=(ValueError,),
                                logger_name='freeze_test') == 1
    finally:
        rclpy.try_shutdown()
    assert calls == []
