"""Predictor node over DDS: lf_odom, dead reckoning through pose dropouts, garbage thrust.

The supply vessel (3 DOF) in closed loop, decimated to 1 Hz poses and 2 Hz thrust; default
predictor windows, so no training happens within the 520 s fed here: the output is the
deterministic cascade fallback and the odometry runs on its priors (the vessel memory and the
covariance calibration are tested in test/core).
"""
# rclpy's Node, executor and lifecycle methods are untyped in Jazzy.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable
import math
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from nav_msgs.msg import Odometry
import numpy as np
import pytest
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
import torch

from lf_predictor_ros.core.odometry import UNESTIMATED_VARIANCE
from lf_predictor_ros.nodes.conversions import (
    msg_to_pose,
    odometry_from_msg,
    pose_to_msg,
    stamp_to_ns,
    wrench_to_msg,
)
from lf_predictor_ros.nodes.predictor_node import PredictorNode
from sim_ros.simulation import SimRecord, load_scenario, simulate

NS_PER_S = 1_000_000_000
DURATION = 520.0  # [s]
TIMEOUT = 60.0  # [s] dead_reckoning_timeout of these tests
DROPOUTS = ((150.0, 180.0), (300.0, 420.0))  # [s) pose dropouts: 30 s and 120 s

torch.set_num_threads(1)


@pytest.fixture(scope='module')
def record() -> SimRecord:
    """Supply vessel, closed loop, seed 3, 10 Hz (decimated when fed)."""
    return simulate(load_scenario('supply_closed_loop'), seed=3, duration=DURATION)


class Probe:
    """Publishes pose + thrust and keeps lf_pose, lf_odom and /diagnostics."""

    def __init__(self, node: Node) -> None:
        qos = QoSProfile(depth=10_000, reliability=ReliabilityPolicy.RELIABLE)
        self.messages: dict[str, list[Any]] = defaultdict(list)
        self.pose_pub = node.create_publisher(PoseStamped, 'measured_pose', qos)
        self.thrust_pub = node.create_publisher(WrenchStamped, 'thrust', qos)
        self.subscriptions = [
            node.create_subscription(kind, topic, self._keeper(topic), qos)
            for topic, kind in (('lf_pose', PoseStamped), ('lf_odom', Odometry),
                                ('/diagnostics', DiagnosticArray))]

    def _keeper(self, topic: str) -> Any:
        return lambda msg: self.messages[topic].append(msg)

    def wait_matched(self, executor: SingleThreadedExecutor, node: Node) -> None:
        inputs = [sub for sub in node.subscriptions
                  if sub.topic_name in ('/measured_pose', '/thrust')]
        end = time.monotonic() + 10.0
        while (self.pose_pub.get_subscription_count() == 0
               or self.thrust_pub.get_subscription_count() == 0
               or any(sub.get_publisher_count() == 0 for sub in self.subscriptions + inputs)):
            assert time.monotonic() < end, 'discovery did not complete'
            executor.spin_once(timeout_sec=0.01)

    def report(self) -> tuple[int, str, dict[str, str]]:
        reports = [m.status[0] for m in self.messages['/diagnostics']
                   if m.status[0].name == 'predictor: lf predictor']
        assert reports, 'no diagnostics received'
        last = reports[-1]
        return last.level[0], last.message, {kv.key: kv.value for kv in last.values}


def _spin_until(executor: SingleThreadedExecutor, done: Callable[[], bool],
                timeout: float) -> None:
    end = time.monotonic() + timeout
    while not done() and time.monotonic() < end:
        executor.spin_once(timeout_sec=0.005)


def _in_dropout(t: float) -> bool:
    return any(start <= t < end for start, end in DROPOUTS)


def _make(ros_context: Context, executor: SingleThreadedExecutor) -> tuple[PredictorNode, Probe]:
    node = PredictorNode(context=ros_context, parameter_overrides=[
        Parameter('dead_reckoning_timeout', value=TIMEOUT),
        Parameter('diagnostics_period', value=0.1)])
    probe_node = Node('probe', context=ros_context)
    probe = Probe(probe_node)
    executor.add_node(node)
    executor.add_node(probe_node)
    probe.wait_matched(executor, node)
    return node, probe


def _stamp(msg: Any) -> float:
    return stamp_to_ns(msg.header.stamp) / NS_PER_S


@pytest.mark.dds
def test_lf_odom_and_dead_reckoning_through_30_and_120_s_dropouts(
        ros_context: Context, executor: SingleThreadedExecutor, record: SimRecord) -> None:
    node, probe = _make(ros_context, executor)
    lf, odom = probe.messages['lf_pose'], probe.messages['lf_odom']
    reports: dict[float, tuple[int, str, dict[str, str]]] = {}
    checkpoints = (170.0, 200.0, 350.0, 400.0, 500.0)
    for k in range(4, len(record.t), 5):  # t = 0.5, 1.0, …: 2 Hz thrust, 1 Hz poses
        t = float(record.t[k])
        probe.thrust_pub.publish(wrench_to_msg(record.thrust[k], t))
        whole = abs(t - round(t)) < 1e-6
        posed = whole and not _in_dropout(t)
        if posed:
            probe.pose_pub.publish(pose_to_msg(record.measured_pose[k], t))
        before = len(odom)
        coasting = any(start <= t < start + TIMEOUT + 2.0 for start, _ in DROPOUTS)
        wait = 0.5 if posed else 0.05 if coasting else 0.005
        _spin_until(executor, lambda n=before: len(odom) > n, wait)
        if whole and round(t) in checkpoints:
            _spin_until(executor, lambda: False, 0.3)  # diagnostics at 10 Hz of wall clock
            reports[round(t)] = probe.report()
    _spin_until(executor, lambda: False, 0.3)

    # (a) lf_odom: frames, finite, same stamp and pose as lf_pose
    assert len(odom) == len(lf) > 300
    assert {m.header.frame_id for m in odom} == {'map_ned'}
    assert {m.child_frame_id for m in odom} == {'base_link_fsd'}
    for pose_msg, odom_msg in zip(lf, odom, strict=True):
        assert pose_msg.header.stamp == odom_msg.header.stamp
        pose, pose_cov, twist, twist_cov = odometry_from_msg(odom_msg)
        np.testing.assert_allclose(pose, msg_to_pose(pose_msg), rtol=0.0, atol=1e-12)
        assert np.all(np.isfinite(pose_cov)) and np.all(np.isfinite(twist_cov))
        assert np.all(np.isfinite(twist)) and np.all(np.linalg.eigvalsh(pose_cov) > 0.0)
        full = np.array(odom_msg.pose.covariance).reshape(6, 6)
        assert list(np.diag(full)[2:5]) == [UNESTIMATED_VARIANCE] * 3
    stamps = np.array([_stamp(m) for m in odom])
    assert np.all(np.diff(stamps) > 0.0)  # never back in time
    # tracking: one estimate per pose sample, stamped t + 1 s
    tracked = stamps[stamps <= DROPOUTS[0][0]]
    np.testing.assert_allclose(tracked, np.arange(2.0, DROPOUTS[0][0] + 1.0), atol=1e-6)
    # the twist is the LF velocity of a DP vessel holding position. With twist_bandwidth 1.0
    # rad/s (chosen for the D term, docs/BENCHMARKS.md) it carries the wave leakage of the
    # cascade fallback (no training in this run): measured RMS 0.23 m/s, peak 0.64 m/s (the
    # bound here was a 0.5 m/s peak at the old, slow twist); the true LF speed is ≈ 0.02 m/s
    speeds = np.array([math.hypot(m.twist.twist.linear.x, m.twist.twist.linear.y)
                       for m in odom])
    assert np.sqrt(np.mean(speeds ** 2)) < 0.3 and speeds.max() < 1.0

    def pose_var(m: Odometry) -> float:
        return float(np.array(m.pose.covariance).reshape(6, 6)[0, 0])

    last_fix = [DROPOUTS[0][0], DROPOUTS[1][0]]  # the last pose of each: stamp start − 1 + h
    for (start, end), fix in zip(DROPOUTS, last_fix, strict=True):
        inside = [m for m in odom if fix + 1.5 <= _stamp(m) < end]
        # dead reckoned: at most once per sample time (thrust at 2 Hz), growing pose covariance
        gaps = np.diff([_stamp(m) for m in inside])
        assert gaps.min() >= 1.0 - 1e-6
        variances = [pose_var(m) for m in inside]
        assert all(b >= a for a, b in zip(variances, variances[1:], strict=False))
        assert variances[-1] > 2.0 * variances[0]
        published_until = max(_stamp(m) for m in inside)
        if end - start < TIMEOUT:
            assert published_until >= end - 1.0  # the whole 30 s dropout bridged
        else:
            # stops after the timeout (a coast at most one sample after it is refused)
            assert fix - 1.0 + TIMEOUT - 1.0 <= published_until <= fix + TIMEOUT
            assert not [m for m in odom if fix + TIMEOUT < _stamp(m) < end]
        # resumes after reacquisition without a jump larger than the dead-reckoned drift
        last_dr = inside[-1]
        after = [m for m in odom if _stamp(m) >= end]
        assert after, 'no estimate after the poses came back'
        jump = np.hypot(*(odometry_from_msg(after[0])[0][:2] - odometry_from_msg(last_dr)[0][:2]))
        drift_std = math.sqrt(pose_var(last_dr) + float(
            np.array(last_dr.pose.covariance).reshape(6, 6)[1, 1]))
        true_step = np.hypot(*(np.interp(_stamp(after[0]), record.t, record.truth_lf_pose[:, 0])
                               - np.interp(_stamp(last_dr), record.t, record.truth_lf_pose[:, 0]),
                               np.interp(_stamp(after[0]), record.t, record.truth_lf_pose[:, 1])
                               - np.interp(_stamp(last_dr), record.t, record.truth_lf_pose[:, 1])))
        assert jump <= 3.0 * drift_std + true_step, (jump, drift_std, true_step)

    # diagnostics: dead reckoning (WARN, elapsed time and reckoner) → lost (ERROR) → tracking
    level, message, values = reports[170.0]
    assert level == 1 and message.startswith('dead_reckoning for ')
    assert 'constant_velocity reckoner' in message
    assert values['odom_mode'] == 'dead_reckoning'
    assert float(values['dead_reckoning_time']) == pytest.approx(170.0 - 150.0, abs=1.5)
    assert reports[200.0][2]['odom_mode'] == 'tracking'
    assert reports[350.0][2]['odom_mode'] == 'dead_reckoning'
    level, message, values = reports[400.0]
    assert level == 2 and values['odom_mode'] == 'lost'
    assert message.startswith(f'lost: no accepted position reference for > {TIMEOUT:g} s: '
                              'not publishing')
    level, message, values = reports[500.0]
    assert values['odom_mode'] == 'tracking' and level == 0
    assert values['odom_dead_reckoning_episodes'] == '2' and values['odom_lost'] == '1'
    assert values['odom_reacquired'] == '2' and values['callback_errors'] == '0'
    assert values['reckoner'] == 'constant_velocity' and values['odom_calibrated'] == 'false'
    # each dropout counted once by the reference checks; the aligner never bridges one (it
    # starts a new segment at the first pose after it, so its own gap counter stays 0)
    assert int(values['invalid']) == 0 and values['ref_dropout'] == '2'
    assert int(values['gaps']) == 0


@pytest.mark.dds
def test_garbage_thrust_while_dead_reckoning_never_crashes(
        ros_context: Context, executor: SingleThreadedExecutor, record: SimRecord) -> None:
    node, probe = _make(ros_context, executor)
    odom = probe.messages['lf_odom']
    garbage = [math.nan, math.inf, -math.inf, 1e308]
    for k in range(0, 1600, 10):  # 1 Hz, poses stop at 100 s, thrust goes on to 160 s
        t = float(record.t[k])
        msg = wrench_to_msg(record.thrust[k], t)
        if t >= 100.0 and k % 30 == 0:  # every 3 s one garbage component
            value = garbage[(k // 30) % len(garbage)]
            if k % 90 == 0:
                msg.wrench.force.x = value
            elif k % 90 == 30:
                msg.wrench.force.y = value
            else:
                msg.wrench.torque.z = value
        probe.thrust_pub.publish(msg)
        if t < 100.0:
            probe.pose_pub.publish(pose_to_msg(record.measured_pose[k], t))
        before = len(odom)
        _spin_until(executor, lambda n=before: len(odom) > n, 0.3)
    _spin_until(executor, lambda: False, 0.3)
    level, message, values = probe.report()
    assert values['odom_mode'] == 'dead_reckoning', message
    assert int(values['invalid']) >= 1  # the non-finite forces were refused
    dead_reckoned = [m for m in odom if _stamp(m) > 102.0]
    # one coast per second of thrust except the seconds whose only thrust was refused
    assert 35 <= len(dead_reckoned) <= 58
    assert values['callback_errors'] == '0'
    for msg in dead_reckoned:
        pose, pose_cov, twist, twist_cov = odometry_from_msg(msg)  # raises on non-finite
        assert np.all(np.isfinite(pose))
    assert node.predictor is not None  # still configured and running
