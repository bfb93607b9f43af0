"""Issue 14 "Done when": a DP controller on lf_odom (pose and twist) through a pose dropout.

Closed loop over DDS, all nodes in this process on one executor: the simulator (supply vessel in
DP, 1 Hz output, lockstep through the predictor as the demo runs it: ``lockstep_period`` =
``lockstep_lead`` = h = 1 s), a relay on the position reference, the predictor (default 3 DOF,
windows shortened so that several trainings, vessel-memory updates and calibrations happen
before the dropout) and dp_controller with ``velocity_source: odometry`` (pose for P and I and
twist for D, both from ``lf_odom``; ``lf_pose`` is not read). The relay drops the 30 poses stamped
in [DROP_START, DROP_END) while the simulator keeps publishing thrust: the predictor must dead
reckon on thrust and keep lf_odom coming, the controller must keep using its twist, the
covariance must cover the drift and the vessel must come back.

Determinism: the relay waits for every running training and vessel-memory job before it forwards
a pose (the executor is single-threaded, so the simulator waits too), as the other DDS tests
wait. During the dropout the dead-reckoned lf_odom is stamped t_k + h like every estimate, so
the controller's answer releases the lockstep wait as while tracking (before 2bd8fb9 it was
stamped t_k and every dead-reckoned sample ended with a lockstep timeout).

What is asserted about the vessel (``_assert_through_the_dropout``), on two seeds with the learned
thrust gain and one with the vessel inertia given:
- *trust*: from 10 s into the dropout to its end, the true LF pose lies inside the 99 % ellipse
  of the published (north, east) covariance (χ²₂ = 9.21): the covariance grows with the drift;
- *recovery*: 70–100 s after the dropout the vessel is back within the worst excursion (and
  heading deviation) it had before the dropout.
An absolute bound on the excursion (3.8 m throughout, until the twenty-third session) measured
the luck of one seed more than dead reckoning: with these short windows the loop's worst
excursion before the dropout alone is 1.9–5.6 m on seeds 3–10, and the 30 s dropout leaves a
dead-reckoning error of 2.2–10.7 m at its end (a loop without the dropout: 0.4–1.2 m in the
40 s after it). Both assertions held on every one of seeds 3–10 (and 3–6, 8, 10 with the
inertia given); the hold reckoner breaks the trust on seeds 3 and 4 (χ² 288 and 17 at the end)
and the recovery on seed 3 (4.8 m against 2.2 m before; on seed 4 the heading's, 0.059
against 0.019 rad); the numbers are in
``docs/BENCHMARKS.md``, "Twenty-fourth session".
"""
# rclpy's Node, executor and lifecycle methods are untyped in Jazzy.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterator
import dataclasses
import math
from pathlib import Path
import time
from typing import Any

from dds_helpers import own_executor
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from nav_msgs.msg import Odometry
import numpy as np
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
import torch
import yaml

from lf_predictor_ros.nodes.conversions import msg_to_pose, odometry_from_msg, stamp_to_ns
from lf_predictor_ros.nodes.predictor_node import PredictorNode
from sim_ros.nodes.dp_controller_node import DpControllerNode
from sim_ros.nodes.simulator_node import MAX_BACKLOG, SimulatorNode
from sim_ros.simulation import REPO_ROOT

NS_PER_S = 1_000_000_000  # [ns/s]
SEED, OTHER_SEED = 3, 4
DURATION = 330.0  # [s sim]: 100 s after the dropout to see the loop recover
SPEED_FACTOR = 30.0  # [s sim / s wall]
DROP_START, DROP_END = 200.0, 230.0  # [s) poses stamped here never reach the predictor
CHI2_2_99 = 9.21  # χ² quantile, 2 degrees of freedom, 0.99
TRUST_FROM = 10.0  # [s] into the dropout: the covariance checked from here (module docstring)
RECOVERY_WINDOW = (DURATION - 30.0, DURATION + 1.0)  # [s) 70–100 s after the dropout
WINDOWS: dict[str, Any] = {'retrain_period': 20.0, 'training_window': 200.0,
                           'transient_length': 10.0, 'filter_window': 60.0,
                           'append_length': 40.0, 'estimation_window': 600.0,
                           'max_train_seconds': 10.0}
# [s wall] the longest wait for the closed loop to finish (about 11 s paced; a hang detector,
# not a speed bound: the loop's wall time is printed, not asserted)
WALL_LIMIT = 90.0
# [s wall] the simulator's wait for a command: long enough that a slow callback under load does
# not release the lockstep (a timeout changes the loop's course: measured in the full suite,
# 2 timeouts at 0.25 s, 5.1 m before the dropout against 1.73 m alone with 1). Before the pacing
# re-anchored after a timeout (StepPacer.resync), a wait below MAX_BACKLOG was caught up in a
# burst through the whole 30 s dropout in milliseconds and no /diagnostics report fell inside it
# (one failure in a full-suite run at dea43c8); 2 × MAX_BACKLOG is kept as the margin for load.
LOCKSTEP_TIMEOUT = 2.0 * MAX_BACKLOG
# M_ii with added mass of the supply vessel (MSS supply.m: m T⁻¹ Mbis T⁻¹, sim_ros.physics.vessels)
SUPPLY_INERTIA = (6.7644e6, 1.13412e7, 4.4524e9)  # [kg, kg, kg·m²]

torch.set_num_threads(1)


def _scenario_path(directory: Path) -> Path:
    """supply_closed_loop at 1 Hz output (h of the predictor), no random sensor dropouts."""
    source = REPO_ROOT / 'config' / 'scenarios' / 'supply_closed_loop.yaml'
    scenario = yaml.safe_load(source.read_text())
    scenario['sample_time'] = 1.0
    scenario['sensors']['dropout_probability'] = 0.0
    path = directory / 'supply_1hz.yaml'
    path.write_text(yaml.safe_dump(scenario))
    return path


class Relay:
    """raw_pose → measured_pose, dropping [DROP_START, DROP_END); waits for the jobs.

    The wait blocks the executor while the simulator's lockstep clock runs; afterwards the relay
    restarts that clock (``SimulatorNode.restart_lockstep_wait``), so the time spent training
    never counts as a missing answer: under load (or with the motion gate's second training)
    the wait alone used to exceed ``lockstep_timeout``, the simulator stepped on with the held
    command and the loop took another course (measured: 3.7 / 4.0 / 7.1 m with the gate, which
    published exactly the gate-off estimate until then).
    """

    def __init__(self, node: Node, predictor: PredictorNode) -> None:
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        self.predictor = predictor
        self.simulator: SimulatorNode | None = None  # set once the simulator exists
        self.forwarded: list[float] = []
        self.dropped: list[float] = []
        self.publisher = node.create_publisher(PoseStamped, 'measured_pose', qos)
        self.subscription = node.create_subscription(PoseStamped, 'raw_pose', self.on_pose, qos)

    def on_pose(self, msg: PoseStamped) -> None:
        t = stamp_to_ns(msg.header.stamp) / NS_PER_S
        if DROP_START <= t < DROP_END:
            self.dropped.append(t)
            return
        state = self.predictor.state
        predictor = self.predictor.predictor
        assert state is not None and predictor is not None
        assert predictor.wait_for_training(timeout=60.0), 'a training did not end in 60 s'
        job = state._job  # the vessel-memory job
        if job is not None:
            job.result(timeout=60.0)
        if self.simulator is not None:
            self.simulator.restart_lockstep_wait()
        self.publisher.publish(msg)
        self.forwarded.append(t)


@dataclasses.dataclass(frozen=True)
class Loop:
    """What one closed-loop run left behind."""

    wall: float
    finished: bool
    dropped: list[float]
    forwarded: list[float]
    odom: list[Odometry]
    stamps: Any  # lf_odom stamps [s]
    mode_at: dict[float, str]  # odometry mode when each lf_odom arrived
    reports: list[Any]  # predictor DiagnosticStatus
    values: list[dict[str, str]]  # their key values
    controller_reports: list[dict[str, str]]
    counters: dict[str, int]
    velocity: dict[str, int]
    commands: list[float]  # thrust_command stamps [s]
    thrust: list[WrenchStamped]
    truth: dict[float, Any]  # true LF pose by stamp
    lockstep_timeouts: int
    lockstep_timeout_times: list[float]  # [s sim] samples whose wait ended by timeout


@pytest.fixture(scope='module')
def loop(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Loop]:
    """The closed loop with the predictor's defaults (the thrust gain is learned)."""
    yield from _closed_loop(tmp_path_factory, SEED, {})


@pytest.fixture(scope='module')
def loop_other_seed(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Loop]:
    """The same loop on another seed: what is asserted must not rest on one seed's luck."""
    yield from _closed_loop(tmp_path_factory, OTHER_SEED, {})


@pytest.fixture(scope='module')
def loop_inertia(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Loop]:
    """The same loop with the supply vessel's inertia given (``vessel_inertia``)."""
    yield from _closed_loop(tmp_path_factory, SEED, {'vessel_inertia': list(SUPPLY_INERTIA)})


def _closed_loop(tmp_path_factory: pytest.TempPathFactory, seed: int,
                 extra: dict[str, Any]) -> Iterator[Loop]:
    """Run the closed loop once (own context) and keep everything."""
    scenario_path = _scenario_path(tmp_path_factory.mktemp('dropout'))
    with own_executor() as (context, executor):
        predictor = PredictorNode(context=context, parameter_overrides=[
            Parameter(name, value=value) for name, value in
            {**WINDOWS, 'diagnostics_period': 0.1, **extra}.items()])
        controller = DpControllerNode(context=context, parameter_overrides=[
            Parameter('scenario', value=str(scenario_path)),
            Parameter('velocity_source', value='odometry')])
        assert list(controller.config.setpoint) == [0.0, 0.0, 0.0]
        assert controller.config.odom_topic == 'lf_odom'
        probe = Node('dropout_probe', context=context)
        relay = Relay(probe, predictor)
        qos = QoSProfile(depth=10_000, reliability=ReliabilityPolicy.RELIABLE)
        received: dict[str, list[Any]] = defaultdict(list)
        modes: list[tuple[float, str]] = []

        def on_odom(msg: Odometry) -> None:
            received['lf_odom'].append(msg)
            state = predictor.state
            assert state is not None
            modes.append((stamp_to_ns(msg.header.stamp) / NS_PER_S, state.odometry.mode))

        probe.create_subscription(Odometry, 'lf_odom', on_odom, qos)
        for topic, kind in (('truth/lf_pose', PoseStamped), ('thrust', WrenchStamped),
                            ('thrust_command', WrenchStamped),
                            ('/diagnostics', DiagnosticArray)):
            probe.create_subscription(kind, topic, received[topic].append, qos)
        for node in (predictor, controller, probe):
            executor.add_node(node)
        simulator = SimulatorNode(context=context, cli_args=[
            '--ros-args', '-r', 'measured_pose:=raw_pose'], parameter_overrides=[
            Parameter('scenario', value=str(scenario_path)), Parameter('seed', value=seed),
            # paced (30 × real time) so that diagnostics reports (every 0.1 s of wall time)
            # fall inside the 30 s of simulated dropout, which take < 0.1 s unpaced
            Parameter('speed_factor', value=SPEED_FACTOR), Parameter('lockstep', value=True),
            Parameter('lockstep_period', value=1.0), Parameter('lockstep_lead', value=1.0),
            Parameter('lockstep_timeout', value=LOCKSTEP_TIMEOUT),
            Parameter('command_timeout', value=3.0),
            Parameter('duration', value=DURATION)])
        relay.simulator = simulator
        executor.add_node(simulator)
        start = time.monotonic()
        executor.spin_until_future_complete(simulator.done, timeout_sec=WALL_LIMIT)
        wall = time.monotonic() - start
        end = time.monotonic() + 0.5
        while time.monotonic() < end:  # drain the last messages and diagnostics
            executor.spin_once(timeout_sec=0.02)
        reports = [m.status[0] for m in received['/diagnostics']
                   if m.status[0].name == 'predictor: lf predictor']
        odom = list(received['lf_odom'])
        yield Loop(
            wall=wall, finished=simulator.done.done(), dropped=list(relay.dropped),
            forwarded=list(relay.forwarded), odom=odom,
            stamps=np.array([stamp_to_ns(m.header.stamp) / NS_PER_S for m in odom]),
            mode_at=dict(modes), reports=reports,
            values=[{kv.key: kv.value for kv in r.values} for r in reports],
            controller_reports=[{kv.key: kv.value for kv in m.status[0].values}
                                for m in received['/diagnostics']
                                if m.status[0].name == 'dp_controller: pid'],
            counters=dict(controller.counters), velocity=dict(controller.velocity_counters),
            commands=[stamp_to_ns(m.header.stamp) / NS_PER_S
                      for m in received['thrust_command']],
            thrust=list(received['thrust']),
            truth={stamp_to_ns(m.header.stamp) / NS_PER_S: msg_to_pose(m)
                   for m in received['truth/lf_pose']},
            lockstep_timeouts=simulator.lockstep_timeouts,
            lockstep_timeout_times=simulator.lockstep_timeout_times)


@pytest.mark.dds
@pytest.mark.parametrize('which', ['loop', 'loop_other_seed', 'loop_inertia'])
def test_dp_controller_on_lf_odom_holds_the_vessel_through_a_30_s_pose_dropout(
        which: str, request: pytest.FixtureRequest) -> None:
    loop: Loop = request.getfixturevalue(which)
    assert loop.finished, f'the simulator did not finish within {loop.wall:.0f} s'
    print(f'closed loop through the dropout: {loop.wall:.1f} s wall for {DURATION:.0f} s sim')

    # the relay really dropped 30 s of poses, and nothing else
    assert loop.dropped == [float(t) for t in range(int(DROP_START), int(DROP_END))]
    assert loop.forwarded[0] == 0.0 and loop.forwarded[-1] == DURATION
    assert len(loop.forwarded) == DURATION + 1 - 30

    # lf_odom throughout: at least one estimate every 2 s, dead reckoning in the dropout with a
    # growing covariance, finite, in the body frame
    stamps, mode_at = loop.stamps, loop.mode_at
    assert np.all(np.diff(stamps) > 0.0)
    assert np.max(np.diff(stamps)) <= 2.0 + 1e-9, 'a gap in lf_odom'
    assert stamps[0] == 1.0 and stamps[-1] >= DURATION
    inside = [t for t in stamps if DROP_START + 2.0 <= t < DROP_END]
    assert inside == [float(t) for t in range(int(DROP_START) + 2, int(DROP_END))]
    assert all(mode_at[t] == 'dead_reckoning' for t in inside), [mode_at[t] for t in inside]
    assert all(mode_at[t] == 'tracking' for t in stamps if t <= DROP_START)
    decoded = [odometry_from_msg(m) for m in loop.odom]  # raises on a non-finite value
    assert {m.child_frame_id for m in loop.odom} == {'base_link_fsd'}
    assert {m.header.frame_id for m in loop.odom} == {'map_ned'}
    pose_var = {t: float(np.trace(d[1][:2, :2])) for t, d in zip(stamps, decoded, strict=True)}
    variances = [pose_var[t] for t in inside]
    assert all(b >= a for a, b in zip(variances, variances[1:], strict=False))
    assert variances[-1] > 2.0 * variances[0], (variances[0], variances[-1])

    # diagnostics: dead_reckoning (WARN) during the dropout, trained and calibrated before it
    reckoning = [(r, v) for r, v in zip(loop.reports, loop.values, strict=True)
                 if v['odom_mode'] == 'dead_reckoning']
    assert reckoning and all(r.level[0] == 1 for r, _ in reckoning)
    assert reckoning[0][0].message.startswith('dead_reckoning for ')
    first = reckoning[0][1]
    assert first['odom_calibrated'] == 'true' and first['vessel_memory'] == 'true'
    # the dead reckoner is the model, its thrust gain given or implied by the controller
    assert first['reckoner'] == 'model', first
    assert first['thrust_gain_source'] == {'loop': 'controller', 'loop_other_seed': 'controller',
                                           'loop_inertia': 'vessel_inertia'}[which], first
    assert int(first['trainings']) >= 3 and int(first['odom_calibrations']) >= 3
    # (the reports come on the wall clock: how many fall in the 30 s of simulated dropout
    # depends on the speed of the run, so only their range is checked; a first fix outside the
    # reacquisition gate is held back up to reacquire_time = 10 s, dead reckoning meanwhile)
    assert all(0.0 <= float(v['dead_reckoning_time']) <= 30.0 + 10.0 + 2.0 for _, v in reckoning)
    final = loop.values[-1]
    assert int(final['callback_errors']) == 0 and int(final['odom_lost']) == 0

    # the controller: every step took pose and twist from lf_odom, never the finite difference
    assert loop.counters['poses'] == len(loop.odom), (loop.counters, len(loop.odom))
    assert loop.counters['restarts'] == 0 and loop.counters['invalid_poses'] == 0
    assert loop.velocity['twists_used'] == len(loop.odom), loop.velocity
    assert loop.velocity['difference_steps'] == 0, loop.velocity
    assert loop.velocity['twists_wrong_frame'] == 0 and loop.velocity['twists_nonfinite'] == 0
    assert loop.commands == list(stamps)  # one command per lf_odom, with its stamp
    assert loop.controller_reports
    assert {v['d_term'] for v in loop.controller_reports[1:]} == {'odometry'}
    assert {v['velocity_source'] for v in loop.controller_reports} == {'odometry'}

    # thrust kept coming: the simulator stepped through the dropout; each dead-reckoned estimate
    # is stamped t_k + h like a tracked one, so the controller's answer releases the lockstep
    # (measured 2 timeouts: the samples before dead reckoning starts); before 2bd8fb9 the
    # estimates were stamped t_k and every one of them waited for the timeout
    thrust_t = [stamp_to_ns(m.header.stamp) / NS_PER_S for m in loop.thrust]
    assert thrust_t == [float(t) for t in range(int(DURATION) + 1)]
    dead_reckoned = sum(1 for t in stamps if mode_at[t] == 'dead_reckoning')
    assert dead_reckoned >= 25
    # and no other wait timed out: a timeout outside the dropout changes the loop's course (the
    # relay's training waits no longer count, `Relay`); measured 1, at t = 200 s
    assert 1 <= loop.lockstep_timeouts <= 2, loop.lockstep_timeout_times
    assert all(DROP_START <= t < DROP_END for t in loop.lockstep_timeout_times), \
        loop.lockstep_timeout_times

    # the thrust really held against the environment (the current alone: 90 m in 180 s)
    assert np.abs(np.array([[m.wrench.force.x, m.wrench.force.y]
                            for m in loop.thrust])).max() > 1e4


@pytest.mark.dds
@pytest.mark.parametrize('which', ['loop', 'loop_other_seed'])
def test_vessel_recovers_from_the_dropout_and_lf_odom_covers_its_drift(
        which: str, request: pytest.FixtureRequest) -> None:
    """Defaults: the dead reckoner's inertia comes from the controller's gains.

    The predictor reads Kp, Kd of dp_controller from thrust_command on its own estimates and
    dead-reckons on the inertia Kd²/(4 Kp) (core.controller_gains): the controller closes its
    loop through that model instead of pushing on a held pose. Measured (seed 3 / 4): worst
    excursion 2.20 / 2.02 m before, 3.38 / 4.76 m during the dropout; dead-reckoning error at
    its end 3.6 / 4.8 m at χ² 1.53 / 0.38 of the published covariance; 1.62 / 1.05 m in the
    recovery window. The hold reckoner on seed 3: 7.4 m during, χ² 288 at the end, 4.8 m in
    the recovery window (earlier history: at 28c8921, constant velocity from the 30 s
    low-passed twist, 1.7 / 6.6 / 13.2 m before / during / after; at 035eb44, dead reckoning
    from the last twist, 1.7-4.1 / 15.7-19.4 / 42-46 m; before f42d74e 9.0 / 16.9 / 91.6 m).
    """
    _assert_through_the_dropout(request.getfixturevalue(which))


@pytest.mark.dds
def test_with_the_vessel_inertia_the_vessel_recovers_and_lf_odom_covers_its_drift(
        loop_inertia: Loop) -> None:
    """Given M_ii, the dead reckoner is the model: the controller closes its loop through it.

    The model: thrust gain 1/M_ii, learned damping and earth-fixed force (balanced at the
    dropout). Measured (seed 3): 2.20 m before, 3.58 m during, error at the end 3.8 m at χ²
    1.81; 1.64 m in the recovery window.
    """
    _assert_through_the_dropout(loop_inertia)


def _assert_through_the_dropout(loop: Loop) -> None:
    """Trust and recovery (module docstring); the excursion is the true LF pose's."""
    thrust_t = [stamp_to_ns(m.header.stamp) / NS_PER_S for m in loop.thrust]
    assert sorted(loop.truth) == thrust_t
    times = np.array(sorted(loop.truth))
    lf = np.array([loop.truth[t] for t in times])
    excursion = np.hypot(lf[:, 0], lf[:, 1])

    def worst(values: Any, a: float, b: float) -> float:
        return float(np.abs(values[(times >= a) & (times < b)]).max())

    windows = ((0.0, DROP_START), (DROP_START, DROP_END), RECOVERY_WINDOW)
    before, during, recovered = (worst(excursion, a, b) for a, b in windows)
    yaw_before, yaw_during, yaw_recovered = (worst(lf[:, 2], a, b) for a, b in windows)

    # trust: the truth inside the published 99 % ellipse while the drift grows
    chi2: dict[float, float] = {}
    for msg, t in zip(loop.odom, loop.stamps, strict=True):
        if DROP_START + TRUST_FROM <= t < DROP_END and loop.mode_at[t] == 'dead_reckoning':
            pose, cov = odometry_from_msg(msg)[:2]
            error = pose[:2] - loop.truth[t][:2]
            chi2[float(t)] = float(error @ np.linalg.solve(cov[:2, :2], error))
    assert len(chi2) >= 15, sorted(chi2)
    last = max(chi2)
    at_last = odometry_from_msg(loop.odom[int(np.searchsorted(loop.stamps, last))])[0]
    drift = math.hypot(*(at_last[:2] - loop.truth[last][:2]))
    print(f'excursion before {before:.2f} m, during {during:.2f} m, 70-100 s after '
          f'{recovered:.2f} m; yaw {yaw_before:.3f} / {yaw_during:.3f} / {yaw_recovered:.3f} '
          f'rad; dead-reckoning error at {last:.0f} s {drift:.2f} m, chi2 {chi2[last]:.2f} '
          f'(max {max(chi2.values()):.2f}); lockstep timeouts {loop.lockstep_timeouts}')
    assert max(chi2.values()) <= CHI2_2_99, chi2
    # recovery: back within what the loop had before the dropout
    assert recovered <= before, (before, during, recovered)
    assert yaw_recovered <= yaw_before, (yaw_before, yaw_during, yaw_recovered)
