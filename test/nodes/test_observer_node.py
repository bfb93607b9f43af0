"""Observer node: both baselines behind lf_pose, ω0 source, parameters, YAML, --help."""
# rclpy's Node, executor and lifecycle methods are untyped in Jazzy.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

from collections import defaultdict
import dataclasses
from pathlib import Path
import time
from typing import Any

from dds_helpers import poses_fed_to
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
import numpy as np
import pytest
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64
import yaml

from lf_predictor_ros.core.alignment import AlignedSample
from lf_predictor_ros.core.baselines.cascade import CascadeFilter
from lf_predictor_ros.core.baselines.observer import PassiveObserver
from lf_predictor_ros.core.reference_checks import ReferenceCheckSettings
from lf_predictor_ros.nodes import observer_node
from lf_predictor_ros.nodes.conversions import msg_to_pose, pose_to_msg, stamp_to_ns, wrench_to_msg
from lf_predictor_ros.nodes.observer_node import ObserverConfig, ObserverNode, make_estimator
from sim_ros.physics.vessels import SUPPLY_D, SUPPLY_M

REPO = Path(__file__).resolve().parents[2]
SAMPLE_TIME = 0.5  # [s]
WAVE_PEAK_FREQ = 0.8  # [rad/s]
LF_POSE = np.array([10.0, -5.0, 0.1])  # [m, m, rad] constant LF pose
WAVE_AMPLITUDE = np.array([0.5, 0.3, 0.02])  # [m, m, rad] wave-frequency motion at ω0
WAVE_PHASE = np.array([0.0, 1.0, 2.0])  # [rad]
N_SAMPLES = 240  # 120 s


def _poses() -> tuple[np.ndarray, np.ndarray]:
    """Stamps t = 0.5 … 120 s and poses: constant LF pose + a sinusoid at ω0 per DOF."""
    t = SAMPLE_TIME * np.arange(1, N_SAMPLES + 1)
    poses = LF_POSE + WAVE_AMPLITUDE * np.sin(WAVE_PEAK_FREQ * t[:, None] + WAVE_PHASE)
    return t, poses


def _make(ros_context: Context, **values: Any) -> ObserverNode:
    values = {'sample_time': SAMPLE_TIME, 'diagnostics_period': 0.2, **values}
    return ObserverNode(context=ros_context, parameter_overrides=[
        Parameter(name, value=value) for name, value in values.items()])


@pytest.mark.dds
@pytest.mark.parametrize('method', ['passive_observer', 'cascade'])
def test_lf_pose_out_for_pose_and_thrust_in(
        ros_context: Context, executor: SingleThreadedExecutor, method: str) -> None:
    node = _make(ros_context, method=method, wave_peak_freq=WAVE_PEAK_FREQ)
    probe = Node('probe', context=ros_context)
    qos = QoSProfile(depth=10_000, reliability=ReliabilityPolicy.RELIABLE)
    received: dict[str, list[Any]] = defaultdict(list)
    pose_pub = probe.create_publisher(PoseStamped, 'measured_pose', qos)
    thrust_pub = probe.create_publisher(WrenchStamped, 'thrust', qos)
    subs = [probe.create_subscription(PoseStamped, 'lf_pose', received['lf_pose'].append, qos),
            probe.create_subscription(DiagnosticArray, '/diagnostics',
                                      received['/diagnostics'].append, qos)]
    executor.add_node(node)
    executor.add_node(probe)
    inputs = [s for s in node.subscriptions if s.topic_name in ('/measured_pose', '/thrust')]
    end = time.monotonic() + 10.0
    while any(s.get_publisher_count() == 0 for s in subs + inputs):
        assert time.monotonic() < end, 'discovery did not complete'
        executor.spin_once(timeout_sec=0.01)

    t, poses = _poses()
    for k in range(N_SAMPLES):
        thrust_pub.publish(wrench_to_msg(np.zeros(3), float(t[k])))
        pose_pub.publish(pose_to_msg(poses[k], float(t[k])))
        end = time.monotonic() + 2.0
        while len(received['lf_pose']) <= k and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.01)
    end = time.monotonic() + 0.5
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.01)

    lf = received['lf_pose']
    # a baseline estimates the LF pose now: stamped with the sample time itself
    assert [stamp_to_ns(m.header.stamp) for m in lf] == [
        (k + 1) * 500_000_000 for k in range(N_SAMPLES)]
    assert {m.header.frame_id for m in lf} == {'map_ned'}
    estimate = np.array([msg_to_pose(m) for m in lf])
    # the node is a thin adapter: same numbers as the core estimator fed the same samples
    core = make_estimator(node.config, WAVE_PEAK_FREQ)
    expected = np.array([core.update(float(t[k]), poses[k], np.zeros(3))
                         for k in range(N_SAMPLES)])
    np.testing.assert_allclose(estimate, expected, rtol=0.0, atol=1e-9)
    # and it filters the waves: over the last 40 s the wave motion at ω0 is attenuated to
    # < 15 % (analytic steady-state gains at ω0: cascade 0.042, observer notch λ/ζn = 0.1 times
    # low-pass ωc/|jω0 + ωc| = 0.77, plus the slow bias transient)
    residual = np.abs(estimate[t > 80.0] - LF_POSE).max(axis=0)
    assert np.all(residual < 0.15 * WAVE_AMPLITUDE), residual
    reports = [m.status[0] for m in received['/diagnostics']
               if m.status[0].name == f'observer: {method}']
    assert reports
    values = {kv.key: kv.value for kv in reports[-1].values}
    assert reports[-1].level == b'\x00'
    assert values['method'] == method and int(values['samples']) == N_SAMPLES
    assert float(values['wave_peak_freq']) == pytest.approx(WAVE_PEAK_FREQ)
    assert values['wave_peak_source'] == 'parameter'
    assert int(values['dropped']) == 0 and int(values['stale_thrust']) == 0


def test_wave_peak_frequency_follows_the_topic_unless_fixed(ros_context: Context) -> None:
    node = _make(ros_context, method='cascade')
    fixed = _make(ros_context, method='passive_observer', wave_peak_freq=0.9)
    try:
        assert node.wave_peak_freq == pytest.approx(0.8)  # default_wave_peak_freq
        assert node.diagnostic_values()[2]['wave_peak_source'] == 'default'
        node.on_wave_peak_frequency(Float64(data=0.6))
        assert node.wave_peak_freq == 0.6
        assert isinstance(node.estimator, CascadeFilter)
        assert node.estimator.wave_peak_freq == 0.6  # the notch was retuned
        assert node.diagnostic_values()[2]['wave_peak_source'] == 'topic'
        node.on_wave_peak_frequency(Float64(data=float('nan')))  # ignored
        node.on_wave_peak_frequency(Float64(data=0.6005))  # below RETUNE_TOLERANCE: kept
        assert node.wave_peak_freq == 0.6
        fixed.on_wave_peak_frequency(Float64(data=0.6))
        assert fixed.wave_peak_freq == 0.9
        assert fixed.diagnostic_values()[2]['wave_peak_source'] == 'parameter'
    finally:
        node.destroy_node()
        fixed.destroy_node()


def test_one_dof_passes_measured_east_and_yaw_through(ros_context: Context) -> None:
    """With ndof 1 only north is estimated; east and yaw are the measurement, never 0."""
    node = _make(ros_context, ndof=1, method='cascade', wave_peak_freq=WAVE_PEAK_FREQ)
    published: list[PoseStamped] = []
    node._lf_pub.publish = published.append  # type: ignore[method-assign]  # noqa: SLF001
    try:
        pose = np.array([3.0, -7.5, 3.1])  # a vessel heading 178°
        for k in range(5):
            node._process(AlignedSample(0.5 * (k + 1), pose, np.zeros(3), False,  # noqa: SLF001
                                        k == 0))
        out = msg_to_pose(published[-1])
        assert out[1] == pytest.approx(-7.5) and out[2] == pytest.approx(3.1)
        assert abs(out[0] - 3.0) < 1.0  # north filtered (starting at the first measurement)
    finally:
        node.destroy_node()


def test_parameters_are_validated_at_start_and_at_run_time(ros_context: Context) -> None:
    with pytest.raises(ValueError, match='method must be one of'):
        _make(ros_context, method='kalman')
    node = _make(ros_context, ndof=1)
    try:
        assert isinstance(node.estimator, PassiveObserver) and node.estimator.ndof == 1
        result = node.set_parameters([Parameter('mass_matrix', value=[1.0] * 8)])[0]
        assert not result.successful and 'mass_matrix must be 9 finite numbers' in result.reason
        result = node.set_parameters([Parameter('mass_matrix', value=[-1.0] + [0.0] * 8)])[0]
        assert not result.successful and 'positive definite' in result.reason
        result = node.set_parameters([Parameter('max_gap', value=0.1)])[0]
        assert not result.successful and 'max_gap (0.1 s) must be >= sample_time' in result.reason
        assert node.set_parameters([Parameter('method', value='cascade')])[0].successful
        assert isinstance(node.estimator, CascadeFilter) and node.config.method == 'cascade'
    finally:
        node.destroy_node()


def test_params_file_and_shipped_yaml_hold_every_default(
        ros_context: Context, tmp_path: Path) -> None:
    shipped = yaml.safe_load((REPO / 'config' / 'observer.yaml').read_text())
    checks = {k: list(v) if isinstance(v, tuple) else v
              for k, v in dataclasses.asdict(ReferenceCheckSettings()).items()}
    assert shipped['/**']['ros__parameters'] == {**dataclasses.asdict(ObserverConfig()), **checks}
    assert ObserverConfig().mass_matrix == SUPPLY_M.reshape(-1).tolist()
    assert ObserverConfig().damping_matrix == SUPPLY_D.reshape(-1).tolist()
    params_file = tmp_path / 'observer.yaml'
    params_file.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
        'method': 'cascade', 'ndof': 1, 'sample_time': 1.0, 'wave_peak_freq': 0.7}}}))
    node = ObserverNode(context=ros_context,
                        cli_args=['--ros-args', '--params-file', str(params_file)])
    try:
        assert node.config == ObserverConfig(method='cascade', ndof=1, sample_time=1.0,
                                             wave_peak_freq=0.7)
        assert node.wave_peak_freq == 0.7
    finally:
        node.destroy_node()
    node = ObserverNode(context=ros_context, cli_args=[
        '--ros-args', '--params-file', str(REPO / 'config' / 'observer.yaml')])
    try:
        assert node.config == ObserverConfig()
    finally:
        node.destroy_node()


@pytest.mark.parametrize('method', ['passive_observer', 'cascade'])
def test_reference_faults_are_flagged_counted_and_kept_out_of_the_estimator(
        ros_context: Context, method: str) -> None:
    """A 3 m spike and a 10 s freeze: rejected before the estimator, counted, level raised.

    The same checks as the predictor node's (an A/B test sees the same reference). The freeze
    is found after `frozen_time` (3 s): the samples before that are taken, then the segment
    restarts, so the estimator never filters across the fault; the output stays finite.
    """
    node = _make(ros_context, method=method, wave_peak_freq=WAVE_PEAK_FREQ)
    try:
        fed = poses_fed_to(node.estimator)
        t, poses = _poses()
        poses[150, 0] += 3.0  # a 3 m spike (the aligner's speed limit alone passes 10 m)
        poses[200:220] = poses[199]  # frozen for 10 s
        published = []
        node._lf_pub.publish = published.append  # type: ignore[method-assign]
        for k in range(N_SAMPLES):
            node.on_thrust(wrench_to_msg(np.zeros(3), float(t[k])))
            node.on_pose(pose_to_msg(poses[k], float(t[k])))
        level, message, values = node.diagnostic_values()
        assert values['ref_jump'] == 1 and values['ref_frozen'] == 1, values
        # the pose of 99.5 s repeated from 100 s: identical for 3 s at 102.5 s (the 6th repeat),
        # rejected from there to the end of the freeze (15 samples)
        assert values['ref_rejected'] == 1 + 15, values
        assert not any(np.allclose(p, poses[150]) for p in fed)  # the spike never got in
        assert sum(np.allclose(p, poses[199]) for p in fed) == 1 + 5  # then the restart
        assert values['poses_accepted'] == N_SAMPLES - values['ref_rejected']
        # one lf_pose per grid sample: the spike's slot is bridged by the aligner (a gap of one
        # sample), the freeze's is not (the restart)
        assert len(published) == len(fed) == values['samples'] == values['poses_accepted'] + 1
        assert all(np.all(np.isfinite(msg_to_pose(m))) for m in published)
        assert values['callback_errors'] == 0 and values['ref_faults'] == 'none'
        assert level == 'OK', message  # the freeze ended: the reference is good again
        # while frozen the level was ERROR with the reason
        node.on_pose(pose_to_msg(poses[-1], float(t[-1]) + SAMPLE_TIME))
        for k in range(1, 8):
            node.on_pose(pose_to_msg(poses[-1], float(t[-1]) + (k + 1) * SAMPLE_TIME))
        level, message, values = node.diagnostic_values()
        assert level == 'ERROR' and 'frozen' in message and values['ref_frozen'] == 2
    finally:
        node.destroy_node()


def test_reference_checks_follow_run_time_parameters(ros_context: Context) -> None:
    node = _make(ros_context)
    try:
        results = node.set_parameters([Parameter('jump_gate', value=8.0)])
        assert results[0].successful and node.checker.settings.jump_gate == 8.0
        results = node.set_parameters([Parameter('jump_gate', value=-1.0)])
        assert not results[0].successful and 'jump_gate' in results[0].reason
        assert node.checker.settings.jump_gate == 8.0
        # a change the estimator refuses (a singular inertia) applies nothing, not even the
        # valid reference-check change that came with it
        result = node.set_parameters_atomically([Parameter('jump_gate', value=9.0),
                                                 Parameter('mass_matrix', value=[0.0] * 9)])
        assert not result.successful, result.reason
        assert node.checker.settings.jump_gate == 8.0
        assert node.config.mass_matrix == ObserverConfig().mass_matrix
    finally:
        node.destroy_node()


def test_help_prints_the_parameter_table_and_exits_0(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        observer_node.main(['observer', '--help'])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    for field in dataclasses.fields(ObserverConfig):
        assert f'\n  {field.name} ' in out
    assert 'vessel length L for the K3/K4 scaling (bias_gains) [m]' in out


def test_a_reoffered_sample_is_answered_again_with_the_same_lf_pose(
        ros_context: Context) -> None:
    """A lockstep simulator re-offers its first sample until it hears an answer."""
    node = _make(ros_context, method='cascade', wave_peak_freq=WAVE_PEAK_FREQ)
    published: list[PoseStamped] = []
    node._lf_pub.publish = published.append  # type: ignore[method-assign]  # noqa: SLF001
    try:
        t, poses = _poses()
        for k in range(3):
            node.on_pose(pose_to_msg(poses[k], float(t[k])))
        assert len(published) == 3
        node.on_pose(pose_to_msg(poses[2], float(t[2])))  # offered again
        values = node.diagnostic_values()[2]
        assert len(published) == 4 and published[-1] == published[-2]
        assert values['reoffers_answered'] == 1 and values['out_of_order'] == 0
        node.on_pose(pose_to_msg(poses[2] + 0.1, float(t[2])))  # other values: out of order
        values = node.diagnostic_values()[2]
        assert len(published) == 4 and values['out_of_order'] == 1
        node.on_pose(pose_to_msg(poses[3], float(t[3])))
        assert len(published) == 5 and values['samples'] == 3
    finally:
        node.destroy_node()
