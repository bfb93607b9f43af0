"""Tests of the demo: report on synthetic arrays, lockstep through a slower estimator, full run."""
# rclpy's Parameter and Node.destroy_node are untyped in Jazzy.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

import json
import math
from pathlib import Path
import time

from geometry_msgs.msg import PoseStamped, WrenchStamped
import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter

from lf_predictor_ros.demo import demo, processes
from lf_predictor_ros.demo.report import (
    LoopRun,
    RunData,
    Trace,
    compute_metrics,
    loop_metrics,
    match_by_stamp,
    retrain_times_from_diagnostics,
    thrust_ratio_label,
    write_report,
)
from lf_predictor_ros.nodes.conversions import ns_to_stamp, sec_to_ns, stamp_to_sec, wrench_to_msg
from lf_predictor_ros.nodes.qos import publisher_qos
from sim_ros.nodes import simulator_node
from sim_ros.nodes.simulator_node import SimulatorNode

PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'


def _synthetic_run(seed: int = 3) -> RunData:
    """3-DOF run, 600 s at 0.1 s: LF drift + WF sine (0.8 rad/s) + noise; lf_pose = truth + 0.1.

    Predictor-loop thrust has a wave-band sine of amplitude 1e4 N in surge, the raw loop 1e5 N,
    so the wave-band power ratio is (1e4)² / (1e5)² = 0.01.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(1, 6001, dtype=np.float64) * 0.1  # [s]
    lf = np.column_stack([0.5 * np.sin(0.01 * t), 0.3 * np.cos(0.01 * t),
                          0.01 * np.sin(0.005 * t)])
    wave = np.sin(0.8 * t)[:, None] * np.array([0.5, 0.5, 0.01])
    measured = lf + wave + rng.normal(0.0, 0.05, (t.size, 3))
    lf_t = t[4::5]  # predictor grid 0.5, 1.0, … s
    estimate = lf[4::5] + np.array([0.1, -0.1, 0.0])
    base = np.array([3e4, 2e4, 5e5])
    thrust_pred = base + np.outer(np.sin(0.8 * t), [1e4, 0.0, 0.0])
    thrust_raw = base + np.outer(np.sin(0.8 * t), [1e5, 0.0, 0.0])
    loops = {'predictor': LoopRun(t, lf, thrust_pred), 'raw_measurement': LoopRun(t, lf,
                                                                                  thrust_raw)}
    return RunData(ndof=3, measured_pose=Trace(t, measured), truth_lf_pose=Trace(t, lf),
                   lf_pose=Trace(lf_t, estimate),
                   wave_peak_freq=Trace(np.array([200.0, 400.0]), np.array([[0.79], [0.81]])),
                   wave_peak_freq_truth=Trace(t, np.full((t.size, 1), 0.8)), loops=loops,
                   retrain_times=(200.0, 260.0), run_info={'scenario': 'synthetic', 'seed': seed})


def test_report_metrics_match_analytic_values_and_files_are_written(tmp_path: Path) -> None:
    run = _synthetic_run()
    metrics = compute_metrics(run, warmup=100.0)
    est = metrics['estimation']
    # constant offset 0.1 m: RMSE 0.1, rate error 0, lag 0
    assert est['north']['rmse'] == pytest.approx(0.1, abs=1e-12)
    assert est['east']['rmse'] == pytest.approx(0.1, abs=1e-12)
    assert est['yaw']['rmse'] == pytest.approx(0.0, abs=1e-12)
    assert est['north']['derivative_rmse'] == pytest.approx(0.0, abs=1e-9)
    assert est['samples'] == 1001  # 0.5 s grid from 100 s to 600 s
    # sine of amplitude A in the band: power A²/2 (Welch, Hann; 10 % tolerance for leakage)
    pred = metrics['closed_loop']['predictor']
    assert pred['thrust_wave_band_power']['north'] == pytest.approx(0.5e8, rel=0.1)
    assert metrics['thrust_wave_band_power_ratio']['north'] == pytest.approx(0.01, rel=0.02)
    # position offsets: max excursion = max |(n, e)| of the LF drift after 100 s
    t = run.loops['predictor'].t
    lf = run.loops['predictor'].truth_lf_pose[t >= 100.0]
    assert pred['max_excursion'] == pytest.approx(float(np.max(np.hypot(lf[:, 0], lf[:, 1]))))
    # total variation of a sine over whole periods ≈ 4 A per period
    periods = (600.0 - 100.0) * 0.8 / (2 * math.pi)
    assert pred['thrust_total_variation']['north'] == pytest.approx(4e4 * periods, rel=0.01)
    assert metrics['run']['retrain_times'] == [200.0, 260.0]

    paths = write_report(run, tmp_path, warmup=100.0)
    assert paths.png.read_bytes()[:8] == PNG_SIGNATURE and paths.png.stat().st_size > 20_000
    loaded = json.loads(paths.metrics.read_text())
    assert set(loaded) >= {'estimation', 'closed_loop', 'run', 'warmup',
                           'thrust_wave_band_power_ratio'}
    text = paths.markdown.read_text()
    assert '![report](report.png)' in text and '| north | 0.1 |' in text


def test_plot_titles_give_the_thrust_ratio_of_the_metrics_after_the_warm_up() -> None:
    run = _synthetic_run()
    metrics = compute_metrics(run, warmup=100.0)
    loops = run.loops
    label = thrust_ratio_label(run, loops['predictor'], loops['raw_measurement'], 0, metrics)
    ratio = metrics['thrust_wave_band_power_ratio']['north']
    assert label == f'\nwave-band power predictor/raw = {ratio:.3g} (t ≥ 100 s)'
    whole = thrust_ratio_label(run, loops['predictor'], loops['raw_measurement'], 0)
    assert whole.endswith('(whole run)') and float(whole.split('= ')[1].split()[0]) == \
        pytest.approx(0.01, rel=0.05)  # the synthetic run's sines: (1e4 / 1e5)²


def test_match_by_stamp_and_retrain_times() -> None:
    first = Trace(np.array([0.5, 1.0, 1.5], dtype=np.float64), np.array([[1.0], [2.0], [3.0]]))
    second = Trace(np.arange(0, 21, dtype=np.float64) * 0.1, np.arange(21, dtype=float)[:, None])
    t, a, b = match_by_stamp(first, second)
    assert t.tolist() == [0.5, 1.0, 1.5]  # 0.1 * 5 != 0.5 in floats, equal to the ns
    assert a[:, 0].tolist() == [1.0, 2.0, 3.0] and b[:, 0].tolist() == [5.0, 10.0, 15.0]
    diagnostics = [(1.0, 'predictor', {'trainings': '0'}), (2.0, 'simulator', {'steps': '3'}),
                   (3.0, 'predictor', {'trainings': '1'}), (4.0, 'predictor', {'trainings': '1'}),
                   (5.0, 'predictor', {'trainings': '3'})]
    assert retrain_times_from_diagnostics(diagnostics) == [3.0, 5.0]


def test_loop_metrics_rejects_too_short_a_run() -> None:
    loop = LoopRun(np.array([1.0, 2.0]), np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match='warm-up'):
        loop_metrics(loop, 3, (0.0, 0.0, 0.0), (0.3, 1.3), 0.0)


def test_isolated_environment_and_plan(tmp_path: Path) -> None:
    env = processes.isolated_environment({'PATH': '/bin'}, 4321)
    assert env['ROS_DOMAIN_ID'] == '22' and env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    assert processes.isolated_environment({'ROS_DOMAIN_ID': '7'}, 4321)['ROS_DOMAIN_ID'] == '7'
    assert all(1 <= processes.domain_id_from_pid(pid) <= 100 for pid in range(0, 400, 7))
    plan = demo.plan_run(demo.parse_args(['supply_closed_loop', '--duration', '30',
                                          '--output-dir', str(tmp_path)]))
    assert plan.seed == 6 and plan.duration == 30.0 and plan.predictor_sample_time == 1.0
    sim_args = demo.node_commands(plan)['simulator'][1]
    assert 'lockstep_period:=1.0' in sim_args and 'lockstep_lead:=1.0' in sim_args
    bad = tmp_path / 'bad.yaml'
    bad.write_text('/**:\n  ros__parameters:\n    sample_time: 0.25\n')
    with pytest.raises(ValueError, match='whole multiple'):
        demo.plan_run(demo.parse_args(['onedof_feedback', '--predictor-params', str(bad)]))


def _command(stamp: float) -> WrenchStamped:
    return wrench_to_msg(np.array([1e4, 0.0, 0.0]), ns_to_stamp(sec_to_ns(stamp)))


def _lockstep_node(ros_context: object, **overrides: float | list[str]) -> SimulatorNode:
    """A lockstep SimulatorNode (timeout 0.2 s) that sees a controller without one running.

    One ``_advance`` makes its steps for at most ``tick_period`` of wall time; the 1 s here keeps
    the step counts these tests assert independent of the machine's load (with the node's 0.01 s
    a loaded two-core machine made 1 step of 5 in one call: forty-second session).
    """
    values: dict[str, float | bool | list[str]] = {'lockstep': True, 'lockstep_timeout': 0.2,
                                                   'speed_factor': 0.0, 'tick_period': 1.0,
                                                   **overrides}
    node = SimulatorNode(context=ros_context, parameter_overrides=[
        Parameter(name, value=value) for name, value in values.items()])
    node._peer_seen_at = -math.inf  # no controller process here: skip the discovery wait
    node.count_publishers = lambda topic_name: 1  # type: ignore[method-assign]
    return node


def test_lockstep_period_waits_only_at_multiples_for_the_lead_stamped_answer(
        ros_context: object) -> None:
    """Sample time 0.1 s, period = lead = 0.5 s: an answer stamped t_k + 0.5 releases 5 steps."""
    node = _lockstep_node(ros_context, lockstep_period=0.5, lockstep_lead=0.5)
    try:
        node._advance()  # offers t = 0 and waits (no command yet)
        assert node.steps == 0
        node._on_command(_command(0.5))  # answer to t = 0: steps freely to 0.5
        assert node.steps == 5 and node.sim_time == pytest.approx(0.5)
        node._on_command(_command(0.5))  # a repeat of the old answer: no step
        assert node.steps == 5
        node._on_command(_command(1.0))  # answer to 0.5
        assert node.steps == 10 and node.lockstep_timeouts == 0
        time.sleep(0.25)  # no answer to 1.0 within lockstep_timeout: step on, count it
        node._advance()
        assert node.steps == 15 and node.lockstep_timeouts == 1
    finally:
        node.destroy_node()


def test_a_restarted_lockstep_wait_does_not_count_the_time_before(ros_context: object) -> None:
    """restart_lockstep_wait: 0.15 + 0.15 s without an answer is no timeout at 0.2 s."""
    node = _lockstep_node(ros_context)
    try:
        node._advance()  # offers t = 0
        node._on_command(_command(0.0))  # answers t = 0: one step to 0.1, then waits
        assert node.steps == 1 and node.lockstep_timeouts == 0
        time.sleep(0.15)
        node.restart_lockstep_wait()  # e.g. a callback that blocked on purpose
        time.sleep(0.15)
        node._advance()
        assert node.steps == 1 and node.lockstep_timeouts == 0  # 0.15 s since the restart
        time.sleep(0.1)
        node._advance()  # now 0.25 s since the restart: step on with the held command
        assert node.steps >= 2 and node.lockstep_timeouts >= 1
        assert node.lockstep_timeout_times[0] == pytest.approx(0.1)
    finally:
        node.destroy_node()


def test_after_a_lockstep_timeout_the_simulator_does_not_catch_up_the_wait(
        ros_context: object) -> None:
    """Speed 10x, period 0.5 s: a 0.25 s wait that times out releases one step, not a burst.

    Before the pacer was re-anchored after a timeout, the 0.25 s wall waited (25 samples at 10x,
    below MAX_BACKLOG) were caught up at once: all 5 free steps to the next lockstep instant.
    """
    node = _lockstep_node(ros_context, lockstep_period=0.5, lockstep_lead=0.5,
                          speed_factor=10.0)
    try:
        node._advance()  # offers t = 0
        node._on_command(_command(0.5))  # answer to t = 0
        deadline = time.monotonic() + 0.15  # paced at 10x: 5 steps in 0.05 s wall, then the
        while node.steps < 5 and time.monotonic() < deadline:  # wait at 0.5 (timeout 0.2 s)
            time.sleep(0.005)
            node._advance()
        assert node.steps == 5 and node.lockstep_timeouts == 0
        time.sleep(0.25)  # no answer within lockstep_timeout
        node._advance()
        assert node.lockstep_timeouts == 1 and node.steps == 6  # one step, at pace from now
        time.sleep(0.1)
        node._advance()
        assert node.steps == 10  # the free steps to the next instant, at 10x (0.04 s wall)
    finally:
        node.destroy_node()


def test_lockstep_start_waits_until_the_listed_publishers_have_matched(
        ros_context: object) -> None:
    """start_subscriptions: no sample before measured_pose has a subscriber; it gets t = 0."""
    from rclpy.executors import SingleThreadedExecutor

    node = _lockstep_node(ros_context, start_subscriptions=['measured_pose=1'])
    listener = rclpy.create_node('start_listener', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(listener)
    stamps: list[float] = []
    try:
        for _ in range(3):
            node._advance()
            time.sleep(0.05)
        assert node._last_step_ns is None  # nobody listens: the first sample is not offered
        listener.create_subscription(PoseStamped, '/measured_pose',
                                     lambda msg: stamps.append(stamp_to_sec(msg.header.stamp)),
                                     publisher_qos())
        deadline = time.monotonic() + 10.0
        while not stamps and time.monotonic() < deadline:  # matched, then DISCOVERY_GRACE
            node._advance()
            executor.spin_once(timeout_sec=0.05)
        assert stamps and stamps[0] == 0.0 and node.steps == 0
    finally:
        executor.shutdown()
        listener.destroy_node()
        node.destroy_node()


@pytest.mark.parametrize('entry', ['measured_pose', 'measured_pose=0', 'clock=1',
                                   'measured_pose=two'])
def test_start_subscriptions_entries_are_checked(entry: str) -> None:
    with pytest.raises(ValueError, match="must be 'topic=count'"):
        simulator_node.SimulatorConfig(start_subscriptions=[entry])
    assert simulator_node.parse_start_subscriptions(['/truth/lf_pose=1', 'thrust=2']) == {
        'truth/lf_pose': 1, 'thrust': 2}


def test_lockstep_period_must_be_a_multiple_and_below_command_timeout() -> None:
    assert simulator_node.lockstep_period_ns(0.5, 0.1) == 500_000_000
    assert simulator_node.lockstep_period_ns(0.0, 0.1) == 0
    with pytest.raises(ValueError, match='whole multiple'):
        simulator_node.lockstep_period_ns(0.25, 0.1)
    with pytest.raises(ValueError, match='command_timeout'):
        simulator_node.SimulatorConfig(lockstep_period=1.0, command_timeout=1.0)


@pytest.mark.dds
@pytest.mark.slow
def test_demo_closed_loop_over_dds_writes_every_artifact_and_holds_the_vessel(
        tmp_path: Path, dds_env: dict[str, str]) -> None:
    """Supply vessel, 480 s simulated, predictor windows shortened so trainings happen.

    Bound on the excursion: the closed loop of test/sim_ros/test_nodes.py (same forces, same
    PID, Kp = M ω_n²) keeps the LF pose within |F|max / Kp: 3.1 m north, 2.2 m east, so 3.8 m
    horizontally, when the controller sees the true LF pose. Here it sees the predictor's
    estimate; its error (a causal notch + low-pass before the first training, ≲ 1 m, the WF
    amplitude 0.5 m std) adds to the offset the PID holds, so allow 3.8 + 1.2 = 5 m. Without
    control the current alone carries the vessel 240 m in 480 s.

    The training window holds 240 samples at h = 1 s. With 100 (a 240 s run) the networks were
    worse than the fallback (estimate errors to 1.7 m) and the excursion reached 3.3–4.7 m in 5
    of 25 runs, and 5 m once, depending on when the trainings finished; with 240 the estimate
    RMSE was 0.16–0.26 m and the excursion 2.2–2.4 m (the start-up transient) in 6 of 6 runs.
    """
    params = tmp_path / 'short.yaml'
    # first training after max(α, min(γ, 2α)) = 240 s of data; a training takes a few wall
    # seconds, i.e. up to ~100 simulated seconds at 20–80x real time
    params.write_text('/**:\n  ros__parameters:\n    estimation_window: 600.0\n'
                      '    training_window: 240.0\n    retrain_period: 40.0\n'
                      '    transient_length: 10.0\n    filter_window: 120.0\n'
                      '    append_length: 60.0\n    max_epochs: 20\n'
                      '    max_train_seconds: 3.0\n')
    duration = 480.0
    start = time.monotonic()
    code = demo.main(['supply_closed_loop', '--duration', f'{duration:g}', '--output-dir',
                      str(tmp_path / 'runs'), '--predictor-params', str(params)])
    wall = time.monotonic() - start
    assert code == 0
    (run_dir,) = (tmp_path / 'runs').iterdir()
    assert {p.name for p in (run_dir / 'logs').iterdir()} == {
        'recorder.log', 'predictor.log', 'dp_controller.log', 'simulator.log'}
    # no callback of the predictor failed (two repeated first stamps once failed every pose)
    assert 'callback failed' not in (run_dir / 'logs' / 'predictor.log').read_text()
    from lf_predictor_ros.bag.series import read_series

    series = read_series(run_dir / 'run.mcap', ['/truth/lf_pose', '/lf_pose', '/measured_pose'])
    # recorded from the first sample on (start_subscriptions) to the last
    assert series['/truth/lf_pose'].stamp[0] == 0.0
    assert series['/measured_pose'].stamp[0] == 0.0
    assert series['/truth/lf_pose'].stamp[-1] == pytest.approx(duration)
    # and none lost (a recorder depth of 100 lost up to 54 in 2 of 6 runs)
    assert series['/truth/lf_pose'].stamp.size == round(duration / 0.1) + 1
    h = 1.0  # predictor sample time of config/demo.yaml: one lf_pose per h
    assert series['/lf_pose'].stamp.size > 0.9 * duration / h
    assert (run_dir / 'report.png').read_bytes()[:8] == PNG_SIGNATURE
    metrics = json.loads((run_dir / 'metrics.json').read_text())
    assert set(metrics) >= {'estimation', 'closed_loop', 'run', 'thrust_wave_band_power_ratio'}
    assert set(metrics['closed_loop']) == {'predictor', 'raw_measurement', 'ideal'}
    assert metrics['run']['trainings'] >= 1
    assert (run_dir / 'report.md').read_text().startswith('# Demo run: supply_closed_loop')
    truth = series['/truth/lf_pose'].values
    excursion = np.hypot(truth[:, 0], truth[:, 1])
    rmse = [metrics['estimation'][dof]['rmse'] for dof in ('north', 'east')]
    run_info = (f"demo: {metrics['run']['real_time_factor']:.1f}x real time, {wall:.0f} s wall "
                f"in total, lockstep timeouts {metrics['run']['lockstep_timeouts']}, trainings "
                f"{metrics['run']['trainings']} at {metrics['run']['retrain_times']}, max "
                f"excursion {excursion.max():.2f} m at "
                f"{series['/truth/lf_pose'].stamp[int(np.argmax(excursion))]:.0f} s, estimate "
                f'RMSE north/east {rmse[0]:.2f}/{rmse[1]:.2f} m')
    print(run_info)
    assert float(excursion.max()) < 5.0, run_info
    # a wave filter worse than the 0.5 m std of the wave motion it removes is no filter
    assert max(rmse) < 0.5, run_info
