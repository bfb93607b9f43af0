"""The latency benchmark's CPU account and collection timer (benchmark/latency.py)."""
from __future__ import annotations

import gc
import os
from pathlib import Path
import signal
import subprocess
import sys
import time
from typing import Any

import numpy as np
import pytest

from lf_predictor_ros.benchmark.latency import (
    CollectionTimer,
    _descendants_cpu_seconds,
    slow_counts,
)

BURN = 0.6  # [s] CPU time the grandchild spends



def test_slow_counts_split_the_steps_from_the_other_callbacks() -> None:
    steps = [0.0009, 0.0011, 0.0030]  # [s] one under the 1 ms bound, two over
    callbacks = [0.0001, 0.0010, 0.0015, 0.0002, *steps]  # 1 ms itself is not over
    assert slow_counts(callbacks, steps) == (2, 1)
    assert slow_counts(callbacks, steps, limit=0.0005) == (3, 2)
    assert slow_counts([], []) == (0, 0)


@pytest.mark.skipif(not Path('/proc/self/stat').exists(), reason='reads Linux /proc')
def test_the_cpu_of_a_live_grandchild_is_counted() -> None:
    # a child that starts a grandchild burning BURN s of CPU, then both sleep (alive)
    code = ('import subprocess, sys; subprocess.run([sys.executable, "-c", "import time\\n'
            f'end = time.process_time() + {BURN}\\nwhile time.process_time() < end: pass\\n'
            'print(1, flush=True)\\ntime.sleep(30)"])')
    before = _descendants_cpu_seconds()
    child = subprocess.Popen([sys.executable, '-c', code], stdout=subprocess.PIPE,
                             start_new_session=True)  # its own group: both killed at the end
    try:
        assert child.stdout is not None
        assert child.stdout.readline().strip() == b'1'  # the grandchild has burnt its share
        time.sleep(0.1)
        spent = _descendants_cpu_seconds() - before
        # the burn, plus the two interpreters' start-up (≈ 0.05 s each here), less one tick
        assert BURN - 0.02 <= spent <= BURN + 1.0
    finally:
        os.killpg(child.pid, signal.SIGKILL)
        child.wait()


def test_the_collection_timer_counts_full_collections_while_it_records() -> None:
    timer = CollectionTimer()
    gc.collect()  # before start: not counted
    timer.start()
    try:
        gc.collect()  # a full collection (generation 2)
        gc.collect(0)
    finally:
        timer.stop()
    gc.collect()  # after stop: not counted
    assert timer not in gc.callbacks
    assert timer.generations.count(2) == 1 and 0 in timer.generations
    assert len(timer.seconds) == len(timer.generations) >= 2
    summary = timer.summary()
    assert summary['gc_full'] == 1.0
    assert summary['gc_max_ms'] == pytest.approx(max(timer.seconds) * 1e3)
    assert CollectionTimer().summary() == {'gc_full': 0.0, 'gc_max_ms': 0.0}


def test_the_pid_feed_answers_each_estimate_once_with_the_pid_command(ros_context: Any) -> None:
    """`DpControllerFeed`: dp_controller's command for each new estimate, its stamp, once."""
    from geometry_msgs.msg import PoseStamped
    from rclpy.node import Node

    from lf_predictor_ros.benchmark.latency import DpControllerFeed
    from lf_predictor_ros.nodes.conversions import msg_to_force, pose_to_msg, stamp_to_sec
    from lf_predictor_ros.nodes.qos import publisher_qos
    from sim_ros.control.pid import PidState, pid_step

    feed = DpControllerFeed(ros_context)
    config = feed.controller.config
    gains, tau_max = config.gains(), np.array(config.tau_max)
    node = Node('test_lf_pose', context=ros_context)
    publisher = node.create_publisher(PoseStamped, 'lf_pose', publisher_qos())
    poses = [np.array([1.0, -2.0, 0.1]), np.array([1.2, -2.1, 0.12])]
    setpoint = np.array(config.setpoint)
    first, state = pid_step(PidState(), gains, poses[0], setpoint, config.nominal_dt, tau_max)
    second, _ = pid_step(state, gains, poses[1], setpoint, 2.0, tau_max)  # dt: the stamps'
    try:
        end = time.monotonic() + 20.0
        while publisher.get_subscription_count() == 0:
            assert time.monotonic() < end, 'the controller never matched lf_pose'
            time.sleep(0.01)
        publisher.publish(pose_to_msg(poses[0], 10.0))
        answers = feed.answer(timeout=20.0)
        assert len(answers) == 1 and stamp_to_sec(answers[0].header.stamp) == 10.0
        np.testing.assert_allclose(msg_to_force(answers[0]), first, rtol=1e-12)
        publisher.publish(pose_to_msg(poses[0], 10.0))  # the same estimate again
        assert feed.answer(timeout=0.5) == []
        publisher.publish(pose_to_msg(poses[1], 12.0))
        answers = feed.answer(timeout=20.0)
        assert len(answers) == 1 and stamp_to_sec(answers[0].header.stamp) == 12.0
        np.testing.assert_allclose(msg_to_force(answers[0]), second, rtol=1e-12)
        assert feed.commands == 2
        assert np.all(np.abs(second[:2]) > 1e3)  # the offset from the setpoint: a real force
    finally:
        feed.close()
        node.destroy_node()
