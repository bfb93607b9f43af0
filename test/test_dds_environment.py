"""Issue 2: two processes exchange a PoseStamped over DDS on loopback in the isolated domain.

Proves the environment every node relies on: rclpy + Fast DDS from the PyPI wheels, discovery
restricted to localhost, a per-process ROS_DOMAIN_ID (test/conftest.py).
"""
from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

PUBLISHER = r"""
import sys, time
import rclpy
from geometry_msgs.msg import PoseStamped
rclpy.init()
node = rclpy.create_node('dds_probe_publisher')
pub = node.create_publisher(PoseStamped, 'probe_pose', 10)
deadline = time.monotonic() + 20.0
i = 0
while time.monotonic() < deadline:
    msg = PoseStamped()
    msg.header.frame_id = 'map_ned'
    msg.header.stamp.sec = 1000 + i
    msg.pose.position.x = 12.5
    msg.pose.position.y = -3.25
    msg.pose.orientation.z = 0.5
    msg.pose.orientation.w = 0.75 ** 0.5
    pub.publish(msg)
    i += 1
    rclpy.spin_once(node, timeout_sec=0.05)
node.destroy_node()
rclpy.try_shutdown()
"""


@pytest.mark.dds
def test_pose_crosses_process_boundary(ros_context: object, dds_env: dict[str, str]) -> None:
    from geometry_msgs.msg import PoseStamped
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    assert dds_env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    assert dds_env['ROS_DOMAIN_ID'] == os.environ['ROS_DOMAIN_ID'] != '0'
    node = rclpy.create_node('dds_probe_subscriber', context=ros_context)
    received: list[PoseStamped] = []
    node.create_subscription(PoseStamped, 'probe_pose', received.append, 10)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    proc = subprocess.Popen([sys.executable, '-c', PUBLISHER], env=dds_env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 20.0
        while len(received) < 3 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
    finally:
        proc.kill()
        proc.wait(timeout=10)
        executor.shutdown()
        node.destroy_node()
    assert len(received) >= 3, 'no PoseStamped arrived from the other process within 20 s'
    msg = received[-1]
    assert msg.header.frame_id == 'map_ned'
    assert msg.header.stamp.sec >= 1000
    assert (msg.pose.position.x, msg.pose.position.y) == (12.5, -3.25)
    assert msg.pose.orientation.z == pytest.approx(0.5, abs=1e-12)
    stamps = [m.header.stamp.sec for m in received]
    assert stamps == sorted(stamps), 'reliable keep_last delivery reordered messages'


@pytest.mark.dds
def test_other_domain_is_not_heard(ros_context: object, dds_env: dict[str, str]) -> None:
    """The isolation is real: a publisher in another domain id reaches nobody here."""
    from geometry_msgs.msg import PoseStamped
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    other = dict(dds_env)
    # the next domain: under xdist another worker's (conftest), where no test uses probe_pose
    other['ROS_DOMAIN_ID'] = str(1 + (int(dds_env['ROS_DOMAIN_ID']) % 100))
    assert other['ROS_DOMAIN_ID'] != dds_env['ROS_DOMAIN_ID']
    node = rclpy.create_node('dds_probe_isolated', context=ros_context)
    received: list[PoseStamped] = []
    node.create_subscription(PoseStamped, 'probe_pose', received.append, 10)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    proc = subprocess.Popen([sys.executable, '-c', PUBLISHER], env=other,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 4.0
        while time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
    finally:
        proc.kill()
        proc.wait(timeout=10)
        executor.shutdown()
        node.destroy_node()
    assert received == []


def test_domain_ids_stay_in_range_and_xdist_workers_never_share_one() -> None:
    from conftest import _isolated_domain_id

    assert _isolated_domain_id(4321) == 22 and _isolated_domain_id(4399) == 100
    assert _isolated_domain_id(4400) == 1  # never 0, the default domain
    # PIDs 4321 and 4421 collide modulo 100; workers of one run (controller PID 4399) do not
    workers = [_isolated_domain_id(pid, f'gw{i}', 4399) for i, pid in enumerate((4321, 4421))]
    assert workers == [100, 1]
    assert len({_isolated_domain_id(0, f'gw{i}', 977) for i in range(100)}) == 100
    assert _isolated_domain_id(4321, 'master', 4399) == 22  # not an xdist worker name: the PID
