"""Simulator node: vessel + sea in simulated time, published on the interface-contract topics.

Thin adapter around ``sim_ros.simulation.Simulator`` (the ROS-free core). Each simulation step
advances one output sample period with the held ``thrust_command`` and publishes, all stamped with
the simulated time of the sample:

- ``/clock`` (rosgraph_msgs/Clock): the simulator owns simulated time;
- ``thrust`` (WrenchStamped, ``base_link_fsd``): forces actually applied (allocation, saturation);
- ``truth/pose``, ``truth/lf_pose`` (PoseStamped, ``map_ned``) when ``publish_truth``;
- ``measured_pose`` (PoseStamped, ``map_ned``), skipped on a sensor dropout, published last so
  that a consumer triggered by it already has the thrust of the same sample.

``/diagnostics`` (1 Hz wall): wave peak frequency, missing-command flag (WARN), speed factor
achieved, lockstep timeouts.

The first tick publishes the initial state (t = 0, zero thrust) before any step, so a controller
answers it exactly as ``sim_ros.simulation.simulate`` calls its PID before the first step.

Commands: zero-order hold of the last ``thrust_command``. With no command yet, or when the last
one was received more than ``command_timeout`` simulated seconds ago, the vessel gets zero thrust
and the diagnostics say WARN.

Timing. Steps are driven by a wall-clock (steady) timer, so the node runs whether or not anyone
uses simulated time (it must not wait on the /clock it publishes). Every ``tick_period`` it makes
as many steps as needed to keep simulated time at ``speed_factor`` × wall time (re-anchoring when
it falls more than ``MAX_BACKLOG`` behind rather than bursting); ``speed_factor = 0`` steps as fast
as possible, yielding to the executor after one ``tick_period`` of work.

Lockstep (``lockstep:=true``), for deterministic closed loops over DDS at 20–100× real time and
beyond. After publishing the sample at time t_k the simulator does not step again until a
``thrust_command`` stamped ≥ t_k has arrived; controllers stamp their command with the stamp of
the pose they answered (measured pose and truth at t_k, a predictor's lf_pose at t_k + h), so
"stamped ≥ t_k" means "computed from the newest sample". The step is then made inside the
command callback, so a step costs one DDS round trip and no timer latency. This makes the closed
loop independent of scheduling: the same seed gives the same run at any speed. Fallbacks:

- before the first command (controller not started or not yet discovered), the simulator waits
  indefinitely and re-publishes the sample every ``lockstep_timeout`` wall seconds, so discovery
  order and start-up time do not change the run; it offers the first sample only once a
  ``thrust_command`` publisher has been discovered and ``DISCOVERY_GRACE`` has passed, so the
  single answer of a controller behind an estimator (which ignores a re-offered stamp) is not
  lost to a publisher that has not matched the subscription yet; with ``start_subscriptions``
  (e.g. ``['measured_pose=2', 'truth/lf_pose=1']``) it also waits until each listed publisher has
  matched that many subscriptions, so a recorder that the graph already shows has matched too
  and records the run from t = 0 (without it a demo bag once began at 67 s, once had no
  simulator topic at all: the recorder's subscriptions matched seconds after the loop started);
- afterwards, when no answer comes within ``lockstep_timeout`` wall seconds (e.g. a sensor dropout
  skipped ``measured_pose`` and the controller listens to it, or a best-effort pose was lost), it
  steps on with the held command and counts a ``lockstep_timeouts`` in the diagnostics: a run
  with zero timeouts is reproducible. It then goes on at ``speed_factor`` from that instant: the
  wall time spent waiting is not caught up in a burst of steps (``StepPacer.resync``).

Lockstep through a slower estimator (``lockstep_period`` > 0 [s sim], a multiple of the sample
time). A predictor in the loop answers only once per its own sample time h (e.g. 0.5 s) while the
simulator steps at 0.1 s. The simulator then steps freely between lockstep instants
t_k = k · ``lockstep_period`` and waits only at them. Its command answers the pose of t_k but is
stamped with the predictor's lf_pose stamp t_k + h, so the wait at t_k is for a command stamped
≥ t_k + ``lockstep_lead`` (set the lead to h): a plain "stamped ≥ t_k" would already be met by
the previous instant's answer (stamped t_{k-1} + h = t_k for h = period), the simulator would
run one period ahead of its controller and the run would depend on scheduling. A command
stamped later than needed also counts (it only comes later). It cannot deadlock: every wait
after the first command ends within ``lockstep_timeout`` wall seconds (counted), e.g. when a
dropout removed the pose of t_k; the late answer is held from its arrival and the next instant
waits for its own answer again, so the loop re-synchronizes at once. ``command_timeout`` must
exceed ``lockstep_period``, else the held command would go stale between two answers.

Run: ``simulator --ros-args --params-file config/simulator.yaml -p speed_factor:=0
-p lockstep:=true`` (with a predictor at h = 0.5 s: ``-p lockstep_period:=0.5
-p lockstep_lead:=0.5``).
"""
# rclpy's Node, Future and logger methods are untyped in Jazzy.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
import math
import sys
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
import numpy as np
from numpy.typing import NDArray
import rclpy
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rclpy.task import Future
from rclpy.utilities import remove_ros_args
from rosgraph_msgs.msg import Clock as ClockMsg

from lf_predictor_ros.nodes.conversions import (
    msg_to_force,
    ns_to_stamp,
    pose_to_msg,
    sec_to_ns,
    stamp_to_ns,
    wrench_to_msg,
)
from lf_predictor_ros.nodes.diagnostics import make_diagnostic_array
from lf_predictor_ros.nodes.params import LiveParameters
from lf_predictor_ros.nodes.qos import command_qos, publisher_qos
from lf_predictor_ros.nodes.runner import spin_node
from sim_ros.physics.schedule import constant
from sim_ros.simulation import Scenario, SimSample, Simulator, load_scenario

NODE_NAME = 'simulator'
MAX_BACKLOG = 1.0  # [s wall] lag behind the speed factor after which pacing re-anchors
# [s wall] lockstep start: time between discovering a thrust_command publisher and offering the
# first sample, so that publisher has matched this node's subscription too (discovery is not
# simultaneous at both ends)
DISCOVERY_GRACE = 0.5
# the data topics whose start `start_subscriptions` can wait for
START_TOPICS = ('measured_pose', 'thrust', 'truth/pose', 'truth/lf_pose')
START_WAIT_LOG_PERIOD = 5.0  # [s wall] between two 'still waiting' lines at the start


def parse_start_subscriptions(entries: Sequence[str]) -> dict[str, int]:
    """``['measured_pose=2', …]`` → {topic: subscriptions}; ValueError says what is wrong."""
    out: dict[str, int] = {}
    for entry in entries:
        topic, sep, count = entry.partition('=')
        topic = topic.strip().lstrip('/')
        if not sep or topic not in START_TOPICS or not count.strip().isdigit() or \
                int(count) < 1:
            raise ValueError(f"start_subscriptions entry {entry!r} must be 'topic=count' with "
                             f'topic one of {START_TOPICS} and count >= 1, e.g. '
                             "'measured_pose=2'")
        out[topic] = int(count)
    return out


def _doc(doc: str, unit: str = '', read_only: bool = False) -> dict[str, Any]:
    meta: dict[str, Any] = {'doc': doc, 'read_only': read_only}
    if unit:
        meta['unit'] = unit
    return meta


@dataclass(frozen=True)
class SimulatorConfig:
    """Parameters of the simulator node (validated; see the module docstring for timing)."""

    scenario: str = field(default='supply_closed_loop', metadata=_doc(
        'scenario name in config/scenarios/ or a YAML path', read_only=True))
    seed: int = field(default=0, metadata=_doc(
        'seed of every noise source; one seed reproduces a run', read_only=True))
    speed_factor: float = field(default=1.0, metadata=_doc(
        'simulated seconds per wall second; 0 = as fast as possible', '-'))
    lockstep: bool = field(default=False, metadata=_doc(
        'wait for the thrust_command answering each sample before the next step'))
    lockstep_timeout: float = field(default=0.5, metadata=_doc(
        'wall time to wait for a command in lockstep before stepping on', 's'))
    lockstep_period: float = field(default=0.0, metadata=_doc(
        'lockstep: wait only at multiples of this simulated time (a multiple of the sample '
        'time); 0 = wait after every step', 's', read_only=True))
    lockstep_lead: float = field(default=0.0, metadata=_doc(
        'lockstep: how far ahead of the answered sample the controller stamps its command '
        '(the predictor sample time h when the controller follows lf_pose)', 's',
        read_only=True))
    command_timeout: float = field(default=1.0, metadata=_doc(
        'simulated age after which the held thrust_command is dropped (zero thrust)', 's'))
    publish_truth: bool = field(default=True, metadata=_doc(
        'publish truth/pose and truth/lf_pose'))
    duration: float = field(default=0.0, metadata=_doc(
        'simulated time after which the node stops and exits; 0 = run until shut down', 's'))
    initial_pose: list[float] = field(default_factory=list, metadata=_doc(
        "scenario override: initial pose [north m, east m, yaw rad]; [] = the scenario's",
        read_only=True))
    wave_peak_freq: float = field(default=0.0, metadata=_doc(
        "scenario override: constant wave peak frequency ω0 (a RAO sea: Tp = 2π/ω0); 0 = the "
        "scenario's schedule",
        'rad/s', read_only=True))
    tick_period: float = field(default=0.01, metadata=_doc(
        'wall period of the stepping timer', 's', read_only=True))
    diagnostics_period: float = field(default=1.0, metadata=_doc(
        'wall period of /diagnostics', 's', read_only=True))
    start_subscriptions: list[str] = field(default_factory=list, metadata=_doc(
        "lockstep start: 'topic=count' entries (topics measured_pose, thrust, truth/pose, "
        'truth/lf_pose); the first sample is offered only once each has matched that many '
        'subscriptions; [] = no wait', read_only=True))

    def __post_init__(self) -> None:
        """Check every rule; the message says what to change."""
        if not self.scenario:
            raise ValueError('scenario must name a scenario or a YAML file, e.g. '
                             'supply_closed_loop')
        if not (math.isfinite(self.speed_factor) and self.speed_factor >= 0.0):
            raise ValueError(f'speed_factor must be >= 0 (0 = as fast as possible), got '
                             f'{self.speed_factor}')
        positive = {'lockstep_timeout': self.lockstep_timeout,
                    'command_timeout': self.command_timeout,
                    'tick_period': self.tick_period,
                    'diagnostics_period': self.diagnostics_period}
        for name, value in positive.items():
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'{name} must be a positive number of seconds, got {value}')
        for name, value in {'lockstep_period': self.lockstep_period,
                            'lockstep_lead': self.lockstep_lead}.items():
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f'{name} must be >= 0 s (0 = off), got {value}')
        if self.lockstep_period >= self.command_timeout:
            raise ValueError(f'command_timeout ({self.command_timeout} s) must exceed '
                             f'lockstep_period ({self.lockstep_period} s): the command answering '
                             f'one lockstep instant is held until the next; raise '
                             f'command_timeout or shorten lockstep_period')
        if not (math.isfinite(self.duration) and self.duration >= 0.0):
            raise ValueError(f'duration must be >= 0 s (0 = run forever), got {self.duration}')
        if self.initial_pose and (len(self.initial_pose) != 3 or not all(
                math.isfinite(v) for v in self.initial_pose)):
            raise ValueError(f'initial_pose must be [] or 3 finite values [north, east, yaw], '
                             f'got {self.initial_pose}')
        if not (math.isfinite(self.wave_peak_freq) and self.wave_peak_freq >= 0.0):
            raise ValueError(f'wave_peak_freq must be 0 (scenario schedule) or > 0 rad/s, got '
                             f'{self.wave_peak_freq}')
        parse_start_subscriptions(self.start_subscriptions)

    def scenario_with_overrides(self) -> Scenario:
        """Load the scenario and apply this node's overrides (validated by Scenario)."""
        scenario = load_scenario(self.scenario)
        if self.initial_pose:
            north, east, yaw = self.initial_pose
            scenario = replace(scenario, initial_pose=(north, east, yaw))
        if self.wave_peak_freq > 0.0 and scenario.waves.model == 'rao':
            # the JONSWAP sea is set by its peak period: Tp = 2π/ω0 (ω0 is derived from it)
            waves = replace(scenario.waves, tp=2.0 * math.pi / self.wave_peak_freq)
            scenario = replace(scenario, waves=waves)
        elif self.wave_peak_freq > 0.0:
            waves = replace(scenario.waves, peak_freq=constant(self.wave_peak_freq))
            scenario = replace(scenario, waves=waves)
        return scenario


def lockstep_period_ns(period: float, sample_time: float) -> int:
    """``lockstep_period`` [s] in integer ns, checked to be 0 or a multiple of ``sample_time``."""
    if period == 0.0:
        return 0
    ratio = period / sample_time
    if round(ratio) < 1 or abs(ratio - round(ratio)) > 1e-9 * max(1.0, ratio):
        raise ValueError(f'lockstep_period ({period} s) must be 0 or a whole multiple of the '
                         f"scenario's sample time ({sample_time} s), e.g. the predictor's "
                         f'sample time')
    return round(ratio) * sec_to_ns(sample_time)


class StepPacer:
    """How many steps are due at a wall time to hold simulated time at ``speed_factor``× wall."""

    def __init__(self, sample_time: float, speed_factor: float, wall_now: float) -> None:
        self._sample_time = sample_time
        self.reset(speed_factor, wall_now)

    def reset(self, speed_factor: float, wall_now: float) -> None:
        """Re-anchor: count steps from ``wall_now`` at a (new) speed factor."""
        self._speed_factor = speed_factor
        self._anchor_wall = wall_now
        self._steps_since_anchor = 0

    def due(self, wall_now: float) -> int:
        """Steps due now (a large number when the speed factor is 0)."""
        if self._speed_factor == 0.0:
            return sys.maxsize
        sim_elapsed = (wall_now - self._anchor_wall) * self._speed_factor
        due = math.floor(sim_elapsed / self._sample_time + 1e-9) - self._steps_since_anchor
        backlog_wall = due * self._sample_time / self._speed_factor
        if backlog_wall > MAX_BACKLOG:  # fell behind (slow machine, lockstep): do not burst
            self.reset(self._speed_factor, wall_now)
            return 1
        return max(due, 0)

    def stepped(self, steps: int) -> None:
        """Record steps made."""
        self._steps_since_anchor += steps

    def resync(self, wall_now: float) -> None:
        """Re-anchor so that exactly one step is due at ``wall_now`` and none of the past is.

        After a lockstep wait that ended by timeout: the wall time spent waiting for a silent
        peer is not caught up in a burst of steps (a burst would run a whole sensor dropout
        through in milliseconds, faster than any wall-clock timer, e.g. the diagnostics).
        """
        if self._speed_factor == 0.0:
            return
        self.reset(self._speed_factor, wall_now - self._sample_time / self._speed_factor)


@dataclass
class _Published:
    """The messages of the last step, kept for lockstep re-publication."""

    messages: list[tuple[Any, Any]] = field(default_factory=list)


class SimulatorNode(Node):
    """Steps a ``Simulator`` in wall-clock-paced or lockstep simulated time."""

    def __init__(self, **node_kwargs: Any) -> None:
        super().__init__(NODE_NAME, **node_kwargs)
        self._params = LiveParameters(self, SimulatorConfig, on_change=self._on_config_change)
        config = self._params.value
        self._sim = Simulator(config.scenario_with_overrides(), seed=config.seed)
        self._sample_time = float(self._sim.sample_time)
        self._lockstep_period_ns = lockstep_period_ns(config.lockstep_period, self._sample_time)
        self._lockstep_lead_ns = sec_to_ns(config.lockstep_lead)
        self.done: Future = Future()

        qos = publisher_qos()
        self._clock_pub = self.create_publisher(ClockMsg, '/clock', qos)
        self._measured_pub = self.create_publisher(PoseStamped, 'measured_pose', qos)
        self._thrust_pub = self.create_publisher(WrenchStamped, 'thrust', qos)
        self._truth_pub = self.create_publisher(PoseStamped, 'truth/pose', qos)
        self._truth_lf_pub = self.create_publisher(PoseStamped, 'truth/lf_pose', qos)
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', qos)
        command_sub = self.create_subscription(WrenchStamped, 'thrust_command', self._on_command,
                                               command_qos())
        self._command_topic: str = command_sub.topic_name
        self._peer_seen_at: float | None = None  # [s wall] first sight of a command publisher
        publishers = {'measured_pose': self._measured_pub, 'thrust': self._thrust_pub,
                      'truth/pose': self._truth_pub, 'truth/lf_pose': self._truth_lf_pub}
        self._start_subscriptions = [
            (publishers[topic], count)
            for topic, count in parse_start_subscriptions(config.start_subscriptions).items()]
        self._start_wait_logged = -math.inf  # [s wall]

        self._command: NDArray[np.float64] | None = None
        self._command_stamp_ns = -1
        self._command_received_t = -math.inf  # [s sim]
        self._last_step_ns: int | None = None
        self._last_published = _Published()
        self._wait_start = time.monotonic()  # [s wall] start of the current lockstep wait
        self._steps = 0
        self._lockstep_timeouts = 0
        self._lockstep_timeout_times: list[float] = []  # [s sim]
        self._dropouts = 0
        self._invalid_commands = 0
        self._wave_peak_freq = math.nan
        self._pacer = StepPacer(self._sample_time, config.speed_factor, time.monotonic())
        self._resync_pacer = False  # set by a lockstep timeout: _advance re-anchors the pacer
        self._diag_mark = (time.monotonic(), float(self._sim.t))

        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(config.tick_period, self._advance, clock=steady)
        self.create_timer(config.diagnostics_period, self._publish_diagnostics, clock=steady)
        self.get_logger().info(
            f'scenario {config.scenario!r} seed {config.seed}: {self._sim.ndof}-DOF, sample time '
            f'{self._sample_time} s, speed factor {config.speed_factor}, lockstep '
            f'{config.lockstep}')

    @property
    def config(self) -> SimulatorConfig:
        """Current validated parameters."""
        return self._params.value

    @property
    def sim_time(self) -> float:
        """Simulated time of the last step [s]."""
        return float(self._sim.t)

    @property
    def steps(self) -> int:
        """Number of steps made."""
        return self._steps

    @property
    def lockstep_timeouts(self) -> int:
        """Lockstep waits that ended by timeout after the first command."""
        return self._lockstep_timeouts

    @property
    def lockstep_timeout_times(self) -> list[float]:
        """Simulated times [s] of the samples whose lockstep wait ended by timeout."""
        return list(self._lockstep_timeout_times)

    def restart_lockstep_wait(self) -> None:
        """Start the wall-clock wait for the current lockstep answer again from now.

        For a callback on the same executor that blocks on purpose (a test's relay that waits
        for the predictor's trainings before it forwards a pose): the time it blocked then does
        not count against ``lockstep_timeout``, so a slow training under load cannot release the
        lockstep and change the loop's course.
        """
        self._wait_start = time.monotonic()

    def _on_config_change(self, config: SimulatorConfig) -> None:
        self._pacer.reset(config.speed_factor, time.monotonic())

    # -- commands -------------------------------------------------------------------------
    def _on_command(self, msg: WrenchStamped) -> None:
        try:
            force = msg_to_force(msg)
        except ValueError as error:
            self._invalid_commands += 1
            self.get_logger().warning(f'ignoring thrust_command: {error}',
                                      throttle_duration_sec=5.0)
            return
        self._command = force
        self._command_stamp_ns = stamp_to_ns(msg.header.stamp)
        self._command_received_t = float(self._sim.t)
        if self.config.lockstep:
            self._advance()

    def held_command(self) -> tuple[NDArray[np.float64], bool]:
        """The command applied to the next step and whether it is missing (zero thrust)."""
        age = float(self._sim.t) - self._command_received_t
        if self._command is None or age > self.config.command_timeout:
            return np.zeros(3), True
        return self._command.copy(), False

    # -- stepping -------------------------------------------------------------------------
    def _lockstep_ready(self) -> bool:
        """Whether lockstep allows the next step (always true without lockstep)."""
        if not self.config.lockstep or self._last_step_ns is None:
            return True
        if self._lockstep_period_ns > 0 and self._last_step_ns % self._lockstep_period_ns != 0:
            return True  # between lockstep instants: step freely with the held command
        if self._command_stamp_ns >= self._last_step_ns + self._lockstep_lead_ns:
            return True
        if time.monotonic() - self._wait_start < self.config.lockstep_timeout:
            return False
        if self._command is None:  # controller not up yet: offer the sample again, keep waiting
            self._republish()
            self._wait_start = time.monotonic()
            return False
        self._lockstep_timeouts += 1
        self._lockstep_timeout_times.append(float(self._sim.t))
        self._resync_pacer = True
        self.get_logger().warning(
            f'lockstep: no command for t={float(self._sim.t):.1f} s within '
            f'{self.config.lockstep_timeout} s wall; stepping on with the held command '
            f'({self._lockstep_timeouts} so far)', throttle_duration_sec=5.0)
        return True

    def _advance(self) -> None:
        """Make the steps that are due and allowed, for at most one tick of wall time."""
        if self.done.done():
            return
        if self._last_step_ns is None:  # first call: offer the initial state (t = 0)
            if not self._start_ready():
                return
            self._publish_sample(self._sim.sample)
        config = self.config
        start = time.monotonic()
        due = self._pacer.due(start)
        made = 0
        while made < due and self._lockstep_ready():
            if self._resync_pacer:  # a wait ended by timeout: go on at pace, no catching up
                self._resync_pacer = False
                now = time.monotonic()
                self._pacer.resync(now)
                made, due = 0, self._pacer.due(now)
            self._step()
            made += 1
            if config.duration > 0.0 and float(self._sim.t) >= config.duration - 1e-9:
                self._finish()
                break
            if time.monotonic() - start > config.tick_period:
                break
        self._pacer.stepped(made)

    def _start_ready(self) -> bool:
        """Lockstep start: wait until a thrust_command publisher is known, plus a grace time.

        The answer to the initial sample is published once; if it went out before the
        controller's publisher had matched this node's subscription it would be lost and the
        loop would never start (an estimator drops the re-offered sample as a repeated stamp).
        The publishers of ``start_subscriptions`` must have matched their subscriptions first.
        """
        if not self.config.lockstep:
            return True
        now = time.monotonic()
        missing = [f'{pub.topic_name} {pub.get_subscription_count()}/{count}'
                   for pub, count in self._start_subscriptions
                   if pub.get_subscription_count() < count]
        if missing and now - self._start_wait_logged >= START_WAIT_LOG_PERIOD:
            self._start_wait_logged = now
            self.get_logger().info('lockstep start waits for subscriptions (matched/needed): '
                                   + ', '.join(missing))
        if missing or self.count_publishers(self._command_topic) == 0:
            self._peer_seen_at = None
            return False
        if self._peer_seen_at is None:
            self._peer_seen_at = now
            self.get_logger().info('thrust_command publisher discovered; starting lockstep in '
                                   f'{DISCOVERY_GRACE} s')
        return now - self._peer_seen_at >= DISCOVERY_GRACE

    def _step(self) -> None:
        tau, _ = self.held_command()
        self._publish_sample(self._sim.step(tau))
        self._steps += 1

    def _publish_sample(self, sample: SimSample) -> None:
        stamp = ns_to_stamp(sec_to_ns(float(sample.t)))
        messages: list[tuple[Any, Any]] = [(self._clock_pub, ClockMsg(clock=stamp)),
                                           (self._thrust_pub, wrench_to_msg(sample.thrust, stamp))]
        if self.config.publish_truth:
            messages.append((self._truth_pub, pose_to_msg(sample.truth_pose, stamp)))
            messages.append((self._truth_lf_pub, pose_to_msg(sample.truth_lf_pose, stamp)))
        if bool(sample.measured_valid):
            messages.append((self._measured_pub, pose_to_msg(sample.measured_pose, stamp)))
        else:
            self._dropouts += 1
        self._wave_peak_freq = float(sample.wave_peak_freq)
        self._last_step_ns = stamp_to_ns(stamp)
        self._last_published = _Published(messages)
        self._wait_start = time.monotonic()
        for publisher, message in messages:
            publisher.publish(message)

    def _republish(self) -> None:
        for publisher, message in self._last_published.messages:
            if publisher is not self._clock_pub:
                publisher.publish(message)

    def _finish(self) -> None:
        self._publish_diagnostics()
        self.get_logger().info(f'duration {self.config.duration} s reached after {self._steps} '
                               f'steps; stopping')
        self.done.set_result(True)

    # -- diagnostics ----------------------------------------------------------------------
    def _publish_diagnostics(self) -> None:
        wall_now, sim_now = time.monotonic(), float(self._sim.t)
        wall_then, sim_then = self._diag_mark
        self._diag_mark = (wall_now, sim_now)
        achieved = (sim_now - sim_then) / (wall_now - wall_then) if wall_now > wall_then else 0.0
        _, missing = self.held_command()
        config = self.config
        if missing:
            level, message = 'WARN', 'no thrust_command (or stale): applying zero thrust'
        else:
            level, message = 'OK', 'running'
        values: dict[str, float | int | bool | str] = {
            'sim_time': sim_now,
            'steps': self._steps,
            'wave_peak_freq': self._wave_peak_freq,
            'command_missing': missing,
            'command_age': sim_now - self._command_received_t,
            'speed_factor': config.speed_factor,
            'speed_factor_achieved': achieved,
            'lockstep': config.lockstep,
            'lockstep_period': config.lockstep_period,
            'lockstep_timeouts': self._lockstep_timeouts,
            'sensor_dropouts': self._dropouts,
            'invalid_commands': self._invalid_commands,
            'scenario': config.scenario,
            'seed': config.seed,
        }
        self._diag_pub.publish(make_diagnostic_array(
            f'{self.get_name()}: simulation', level, message, values,
            stamp=ns_to_stamp(sec_to_ns(sim_now))))


def _parse_cli(argv: Sequence[str]) -> None:
    """Handle ``--help`` (exit 0) and reject unknown non-ROS arguments (exit 2)."""
    parser = argparse.ArgumentParser(
        prog=NODE_NAME,
        description='Vessel and sea simulator node (publishes measured_pose, thrust, '
                    'truth/pose, truth/lf_pose, /clock, /diagnostics; subscribes thrust_command).',
        epilog='ROS arguments: --ros-args -p speed_factor:=0 -p lockstep:=true '
               '--params-file config/simulator.yaml -r __ns:=/vessel. Parameters: '
               + ', '.join(f.name for f in SimulatorConfig.__dataclass_fields__.values()) + '.')
    parser.parse_args(list(remove_ros_args(list(argv)))[1:])


def main(args: list[str] | None = None) -> int:
    """Console script ``simulator``; returns the exit code."""
    _parse_cli(sys.argv if args is None else args)
    rclpy.init(args=args)

    def until(node: Node) -> Future | None:
        assert isinstance(node, SimulatorNode)
        return node.done if node.config.duration > 0.0 else None  # exit at the scenario's end
    return spin_node(SimulatorNode, config_errors=(ValueError, FileNotFoundError),
                     logger_name=NODE_NAME, until=until)


if __name__ == '__main__':
    sys.exit(main())
