"""DP controller node: nonlinear MIMO PID on a pose topic, publishing ``thrust_command``.

Thin adapter around ``sim_ros.control.pid`` (MSS ``PIDnonlinearMIMO.m``, anchors §5):
subscribes ``lf_pose`` (remap to ``measured_pose`` or ``truth/lf_pose``; sensor-data QoS),
publishes one ``thrust_command`` (WrenchStamped, ``base_link_fsd``) per accepted pose, stamped
with that pose's stamp, so a lockstep simulator knows which sample the command answers.

Velocity for the D term (``velocity_source``, read-only). ``difference`` (default): ν from the
filtered finite difference of the poses. ``odometry``: the node subscribes ``odom_topic``
(nav_msgs/Odometry, default ``lf_odom``) *instead of* ``lf_pose``, takes the pose for the P and I
terms from it and its twist [u, v, r] (``base_link_fsd``) as ν for the D term. A message whose
``child_frame_id`` is not ``base_link_fsd`` or whose twist is not finite still gives its pose;
its twist is not used (counted, warned once per reason). The D term then uses the last valid
twist while it is at most ``velocity_timeout`` older than the pose (stamps), else the finite
difference, reported as a WARN in ``/diagnostics`` and logged on each switch. The finite
difference runs on the poses all the time, so the fallback starts warm.

dt is the difference of consecutive pose stamps (never the wall clock), so the controller is
correct in simulated time at any speed, with or without ``use_sim_time``. A pose whose stamp is
not newer than the last accepted one is ignored and counted in ``/diagnostics``, except the last
accepted sample offered again (same stamp and pose), which is answered again with the same
command without stepping the PID (a lockstep simulator re-offers its first sample until it
hears an answer, and the first answer can be lost before the publishers match). The first pose
(no previous stamp) uses ``nominal_dt``; a gap longer than ``max_dt`` restarts the controller
from the new pose (reference filter, integrator and velocity estimate reset; counted).

Tuning. ``scenario`` (read-only, default ``supply_closed_loop``) supplies the defaults of every
other parameter: the vessel's mass and linear damping diagonals (``Simulator.true_model()``), the
force limit (the scenario's ``controller.tau_max`` or its actuator capacity) and the scenario's
controller section (setpoint, bandwidth, ζ, T_f, T_v, sample time as ``nominal_dt``). Any of
them can be overridden with ``-p``/``--params-file``; ``scenario:=''`` uses the built-in MSS
supply-vessel values. Gains: Kp = M ω_n², Kd = 2ζω_n M − D, Ki = ω_n/10 Kp
(``gains_from_bandwidth``). Setpoint, setpoint schedule, bandwidth, ζ, limits, filter times and
``velocity_timeout`` may be changed at run time (``ros2 param set``); invalid values are rejected
with the reason.

Setpoint schedule. ``setpoint_schedule`` (default: the scenario's ``controller.setpoint_schedule``)
is a flat list of rows ``[t s, north m, east m, yaw rad]`` (ROS parameters cannot nest lists):
from the pose stamp t on, the setpoint is that row; before the first row, ``setpoint``. This is
``ControllerConfig.setpoint_at`` of the in-process simulation, with t the pose stamp (the
simulator's clock starts at 0, as ``Simulator.t`` does).

With the same scenario, a stamped pose stream at the sample time and the same seed, this node
in lockstep with the simulator node reproduces ``sim_ros.simulation.simulate`` in closed loop.
"""
# rclpy's Node, Future and logger methods are untyped in Jazzy.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass, field
import math
import sys
import time
from typing import Any

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from nav_msgs.msg import Odometry
import numpy as np
import rclpy
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rclpy.utilities import remove_ros_args

from lf_predictor_ros.nodes.conversions import (
    FRAME_BODY,
    msg_to_pose,
    odometry_pose_from_msg,
    odometry_twist_from_msg,
    stamp_to_ns,
    stamp_to_sec,
    wrench_to_msg,
)
from lf_predictor_ros.nodes.diagnostics import make_diagnostic_array
from lf_predictor_ros.nodes.params import LiveParameters, declare_and_load
from lf_predictor_ros.nodes.params import param_meta as _meta
from lf_predictor_ros.nodes.qos import publisher_qos, sensor_qos
from lf_predictor_ros.nodes.runner import spin_node
from sim_ros.control.pid import (
    VELOCITY_SOURCES,
    PidGains,
    PidState,
    gains_from_bandwidth,
    pid_step,
)
from sim_ros.physics.vessels import SUPPLY_M
from sim_ros.simulation import ControllerConfig, Simulator, load_scenario

NODE_NAME = 'dp_controller'
NS_PER_S = 1e9  # [ns/s]
SCHEDULE_ROW = 4  # [t s, north m, east m, yaw rad]


@dataclass(frozen=True)
class ControllerSource:
    """Where the controller's defaults come from."""

    scenario: str = field(default='supply_closed_loop', metadata=_meta(
        "scenario whose vessel and controller section give the defaults; '' = built-in "
        'MSS supply vessel values', read_only=True))


def _check_vector(name: str, values: Sequence[float], lower: float, strict: bool) -> None:
    ok = len(values) == 3 and all(
        math.isfinite(v) and (v > lower if strict else v >= lower) for v in values)
    if not ok:
        rule = f'> {lower}' if strict else f'>= {lower}'
        raise ValueError(f'{name} must be 3 finite values {rule} (surge, sway, yaw), got '
                         f'{list(values)}')


@dataclass(frozen=True)
class DpControllerConfig:
    """Validated controller parameters (defaults: MSS supply vessel, anchors §2 and §5)."""

    setpoint: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0], metadata=_meta(
        'desired pose [north m, east m, yaw rad] in map_ned'))
    bandwidth: list[float] = field(default_factory=lambda: [0.1, 0.1, 0.2], metadata=_meta(
        'closed-loop natural frequency ω_n per DOF', 'rad/s'))
    zeta: float = field(default=1.0, metadata=_meta('relative damping ζ of the closed loop'))
    setpoint_filter_time: float = field(default=10.0, metadata=_meta(
        'time constant T_f of the setpoint filter 1/(T_f s + 1)', 's'))
    velocity_filter_time: float = field(default=1.0, metadata=_meta(
        'time constant of the low-pass on the finite-difference velocity', 's'))
    mass_diag: list[float] = field(
        default_factory=lambda: [float(v) for v in np.diag(SUPPLY_M)], metadata=_meta(
            'vessel mass diagonal incl. added mass [kg, kg, kg·m²]'))
    damping_diag: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0], metadata=_meta(
        'vessel linear damping diagonal subtracted from Kd [N·s/m, N·s/m, N·m·s]'))
    tau_max: list[float] = field(default_factory=list, metadata=_meta(
        'force limit per DOF [N, N, N·m] with anti-windup; [] = no limit'))
    nominal_dt: float = field(default=0.1, metadata=_meta(
        'dt used for the first pose (no previous stamp): the pose period', 's'))
    max_dt: float = field(default=5.0, metadata=_meta(
        'a longer gap between pose stamps restarts the controller', 's'))
    setpoint_schedule: list[float] = field(default_factory=list, metadata=_meta(
        'setpoint changes as flat rows [t s, north m, east m, yaw rad, ...], times '
        'non-decreasing: from pose stamp t on the setpoint is that row; [] = setpoint only'))
    velocity_source: str = field(default='difference', metadata=_meta(
        "D-term velocity: 'difference' (filtered finite difference of lf_pose) or 'odometry' "
        '(pose and twist from odom_topic, nav_msgs/Odometry)', read_only=True))
    odom_topic: str = field(default='lf_odom', metadata=_meta(
        "Odometry topic read when velocity_source is 'odometry'", read_only=True))
    velocity_timeout: float = field(default=2.0, metadata=_meta(
        'an odometry twist older than this (pose stamps) is not used: finite difference '
        'instead', 's'))

    def __post_init__(self) -> None:
        """Check every rule; the message says what to change."""
        _check_vector('setpoint', self.setpoint, -math.inf, strict=True)
        if self.velocity_source not in VELOCITY_SOURCES:
            raise ValueError(f'velocity_source must be one of {VELOCITY_SOURCES}, got '
                             f"{self.velocity_source!r}; 'odometry' reads pose and twist from "
                             'odom_topic')
        if not self.odom_topic:
            raise ValueError("odom_topic must be a topic name, e.g. 'lf_odom'")
        if not (math.isfinite(self.velocity_timeout) and self.velocity_timeout > 0.0):
            raise ValueError(f'velocity_timeout must be a finite number > 0 s, got '
                             f'{self.velocity_timeout}; e.g. 2 predictor periods')
        if len(self.setpoint_schedule) % SCHEDULE_ROW:
            raise ValueError(f'setpoint_schedule must be flat rows of {SCHEDULE_ROW} numbers '
                             f'[t s, north m, east m, yaw rad, ...], got '
                             f'{len(self.setpoint_schedule)} values')
        self.schedule()  # ControllerConfig checks the rows (finite, ordered times >= 0)
        _check_vector('bandwidth', self.bandwidth, 0.0, strict=True)
        _check_vector('mass_diag', self.mass_diag, 0.0, strict=True)
        _check_vector('damping_diag', self.damping_diag, 0.0, strict=False)
        if self.tau_max:
            _check_vector('tau_max', self.tau_max, 0.0, strict=True)
        for name in ('zeta', 'setpoint_filter_time', 'velocity_filter_time', 'nominal_dt'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'{name} must be a finite number > 0, got {value}')
        if not self.max_dt > self.nominal_dt:
            raise ValueError(f'max_dt ({self.max_dt} s) must exceed nominal_dt '
                             f'({self.nominal_dt} s)')

    def schedule(self) -> ControllerConfig:
        """Setpoint and schedule as the simulation's ControllerConfig (``setpoint_at(t)``)."""
        values = self.setpoint_schedule
        rows = tuple((values[i], values[i + 1], values[i + 2], values[i + 3])
                     for i in range(0, len(values), SCHEDULE_ROW))
        setpoint = (self.setpoint[0], self.setpoint[1], self.setpoint[2])
        return ControllerConfig(setpoint=setpoint, setpoint_schedule=rows)

    def gains(self) -> PidGains:
        """PID gains from bandwidth and vessel model (anchors §5)."""
        return gains_from_bandwidth(self.mass_diag, self.bandwidth, self.zeta,
                                    self.damping_diag, self.setpoint_filter_time,
                                    self.velocity_filter_time)


def scenario_defaults(name: str) -> dict[str, Any]:
    """Controller defaults from a scenario: vessel model, force limit, controller section."""
    scenario = load_scenario(name)
    sim = Simulator(scenario)
    model = sim.true_model()
    ctl = scenario.controller
    limit = ctl.tau_max if ctl.tau_max is not None else sim.actuator_limit()
    return {
        'setpoint': [float(v) for v in ctl.setpoint],
        'bandwidth': [float(v) for v in ctl.bandwidth],
        'zeta': float(ctl.zeta),
        'setpoint_filter_time': float(ctl.setpoint_filter_time),
        'velocity_filter_time': float(ctl.velocity_filter_time),
        'mass_diag': [float(v) for v in np.diag(model.mass)],
        'damping_diag': [float(v) for v in np.diag(model.damping)],
        'tau_max': [] if limit is None else [float(v) for v in limit],
        'nominal_dt': float(scenario.sample_time),
        'setpoint_schedule': [float(v) for row in ctl.setpoint_schedule for v in row],
    }


class DpControllerNode(Node):
    """One PID step per pose (or odometry) message; dt from the stamps."""

    def __init__(self, **node_kwargs: Any) -> None:
        super().__init__(NODE_NAME, **node_kwargs)
        source = declare_and_load(self, ControllerSource)
        defaults = scenario_defaults(source.scenario) if source.scenario else None
        self._params = LiveParameters(self, DpControllerConfig, on_change=self._on_config_change,
                                      defaults=defaults)
        self._gains = self._params.value.gains()
        self._schedule = self._params.value.schedule()
        self._state = PidState()
        self._last_stamp_ns: int | None = None
        self._last_pose: np.ndarray | None = None
        self._poses = 0
        self._non_increasing = 0
        self._invalid = 0
        self._restarts = 0
        self._last_dt = math.nan
        self._last_tau = np.zeros(3)
        self._saturated = False
        # odometry twist for the D term (velocity_source 'odometry')
        self._twist: np.ndarray | None = None
        self._twist_stamp_ns = 0
        self._twists_used = 0
        self._twists_wrong_frame = 0
        self._twists_nonfinite = 0
        self._fallback_steps = 0
        self._d_term = 'none'  # what the last step's D term came from
        self._warned: set[str] = set()

        self._command_pub = self.create_publisher(WrenchStamped, 'thrust_command',
                                                  publisher_qos())
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', publisher_qos())
        config = self._params.value
        if config.velocity_source == 'odometry':
            self.create_subscription(Odometry, config.odom_topic, self._on_odometry,
                                     sensor_qos())
            inputs = f'pose and twist from {config.odom_topic!r}'
        else:
            self.create_subscription(PoseStamped, 'lf_pose', self._on_pose, sensor_qos())
            inputs = "pose from 'lf_pose', D term from its finite difference"
        self.create_timer(1.0, self._publish_diagnostics,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._diag_wall = time.monotonic()
        self.get_logger().info(
            f'scenario {source.scenario!r}: setpoint {config.setpoint}'
            f'{" with a schedule" if config.setpoint_schedule else ""}, bandwidth '
            f'{config.bandwidth} rad/s, zeta {config.zeta}, tau_max {config.tau_max or "none"}; '
            f'{inputs}')

    @property
    def config(self) -> DpControllerConfig:
        """Current validated parameters."""
        return self._params.value

    @property
    def counters(self) -> dict[str, int]:
        """Poses used, ignored (non-increasing stamp, invalid) and controller restarts."""
        return {'poses': self._poses, 'non_increasing_stamps': self._non_increasing,
                'invalid_poses': self._invalid, 'restarts': self._restarts}

    @property
    def velocity_counters(self) -> dict[str, int]:
        """Odometry twists used for the D term, rejected (by reason), finite-difference steps.

        ``difference_steps`` counts the steps in ``odometry`` mode whose D term fell back to the
        finite difference (no valid twist within ``velocity_timeout``).
        """
        return {'twists_used': self._twists_used,
                'twists_wrong_frame': self._twists_wrong_frame,
                'twists_nonfinite': self._twists_nonfinite,
                'difference_steps': self._fallback_steps}

    def _on_config_change(self, config: DpControllerConfig) -> None:
        self._gains = config.gains()
        self._schedule = config.schedule()

    def _warn_once(self, key: str, text: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            self.get_logger().warning(f'{text} (counted in /diagnostics; not repeated)')

    def _on_pose(self, msg: PoseStamped) -> None:
        try:
            pose = msg_to_pose(msg)
        except ValueError as error:
            self._invalid += 1
            self.get_logger().warning(f'ignoring pose: {error}', throttle_duration_sec=5.0)
            return
        self._control(pose, msg.header.stamp, None)

    def _on_odometry(self, msg: Odometry) -> None:
        try:
            pose = odometry_pose_from_msg(msg)
        except ValueError as error:
            self._invalid += 1
            self.get_logger().warning(f'ignoring odometry: {error}', throttle_duration_sec=5.0)
            return
        stamp_ns = stamp_to_ns(msg.header.stamp)
        if self._last_stamp_ns is not None and stamp_ns <= self._last_stamp_ns:
            self._non_increasing += 1
            return
        if msg.child_frame_id != FRAME_BODY:
            self._twists_wrong_frame += 1
            self._warn_once('frame', f'not using the twist of {self.config.odom_topic}: '
                                     f'child_frame_id {msg.child_frame_id!r} is not '
                                     f'{FRAME_BODY!r}; publish the twist in the body frame')
        else:
            try:
                self._twist = odometry_twist_from_msg(msg)
                self._twist_stamp_ns = stamp_ns
                self._twists_used += 1
            except ValueError as error:
                self._twists_nonfinite += 1
                self._warn_once('nonfinite', f'not using the twist of '
                                             f'{self.config.odom_topic}: {error}')
        velocity = None
        if (self._twist is not None and (stamp_ns - self._twist_stamp_ns) / NS_PER_S
                <= self.config.velocity_timeout):
            velocity = self._twist
        self._control(pose, msg.header.stamp, velocity)

    def _control(self, pose: np.ndarray, stamp: Time, velocity: np.ndarray | None) -> None:
        """One PID step on a valid pose; ``velocity`` [u, v, r] for the D term or None."""
        stamp_ns = stamp_to_ns(stamp)
        if self._is_reoffer(stamp_ns, pose):
            # the same sample offered again (a lockstep simulator re-offers its first sample
            # until it hears an answer; the first answer can be lost while the publisher has
            # not matched yet): answer it again, the PID does not step
            self._command_pub.publish(wrench_to_msg(self._last_tau, stamp))
            return
        if self._last_stamp_ns is not None and stamp_ns <= self._last_stamp_ns:
            self._non_increasing += 1
            return
        config = self.config
        if self._last_stamp_ns is None:
            dt = config.nominal_dt
        else:
            dt = (stamp_ns - self._last_stamp_ns) / NS_PER_S
            if dt > config.max_dt:
                self._restarts += 1
                self._state = PidState()
                dt = config.nominal_dt
        self._last_stamp_ns = stamp_ns
        tau_max = config.tau_max or None
        setpoint = self._schedule.setpoint_at(stamp_to_sec(stamp))
        tau, self._state = pid_step(self._state, self._gains, pose, setpoint, dt, tau_max,
                                    velocity)
        if config.velocity_source == 'odometry':
            self._note_d_term('odometry' if velocity is not None else 'difference')
        else:
            self._d_term = 'difference'
        self._poses += 1
        self._last_dt = dt
        self._last_tau = tau
        self._last_pose = pose.copy()
        self._saturated = tau_max is not None and bool(
            np.any(np.abs(tau) >= np.asarray(tau_max) * (1.0 - 1e-12)))
        self._command_pub.publish(wrench_to_msg(tau, stamp))

    def _is_reoffer(self, stamp_ns: int, pose: np.ndarray) -> bool:
        """The last answered sample again: same stamp, same pose."""
        return (self._last_stamp_ns is not None and stamp_ns == self._last_stamp_ns
                and self._last_pose is not None and np.array_equal(pose, self._last_pose))

    def _note_d_term(self, source: str) -> None:
        """Count and log the switches between the odometry twist and the fallback."""
        if source == 'difference':
            self._fallback_steps += 1
            if self._d_term != 'difference':
                self.get_logger().warning(
                    f'D term from the finite difference of the poses: no valid '
                    f'{self.config.odom_topic} twist newer than {self.config.velocity_timeout} s')
        elif self._d_term == 'difference':
            self.get_logger().info(f'D term from the {self.config.odom_topic} twist again')
        self._d_term = source

    def _publish_diagnostics(self) -> None:
        wall_now = time.monotonic()
        idle = self._poses == 0
        odometry = self.config.velocity_source == 'odometry'
        fallback = odometry and self._d_term == 'difference'
        level = 'WARN' if idle or self._saturated or fallback else 'OK'
        waiting = f'waiting for {self.config.odom_topic}' if odometry else 'waiting for poses'
        message = (waiting if idle else
                   'command saturated' if self._saturated else
                   f'D term from the finite difference: no fresh {self.config.odom_topic} '
                   'twist' if fallback else 'controlling')
        error = (np.asarray(self._state.last_pose) - np.asarray(self._state.setpoint_filtered)
                 if self._state.initialized else np.full(3, math.nan))
        twist_age = (math.nan if self._twist is None or self._last_stamp_ns is None
                     else (self._last_stamp_ns - self._twist_stamp_ns) / NS_PER_S)
        values: dict[str, float | int | bool | str] = {
            **self.counters,
            'last_dt': self._last_dt,
            'saturated': self._saturated,
            'error_north': float(error[0]), 'error_east': float(error[1]),
            'error_yaw': float(math.remainder(float(error[2]), 2.0 * math.pi)),
            'tau_surge': float(self._last_tau[0]), 'tau_sway': float(self._last_tau[1]),
            'tau_yaw': float(self._last_tau[2]),
            'velocity_source': self.config.velocity_source,
            'd_term': self._d_term,
            **self.velocity_counters,
            'twist_age': twist_age,
            'wall_since_last_report': wall_now - self._diag_wall,
        }
        self._diag_wall = wall_now
        self._diag_pub.publish(make_diagnostic_array(
            f'{self.get_name()}: pid', level, message, values))


def _parse_cli(argv: Sequence[str]) -> None:
    """Handle ``--help`` (exit 0) and reject unknown non-ROS arguments (exit 2)."""
    parser = argparse.ArgumentParser(
        prog=NODE_NAME,
        description='DP controller node (nonlinear MIMO PID): subscribes lf_pose (or lf_odom '
                    'with velocity_source:=odometry, its twist for the D term), publishes '
                    'thrust_command stamped with the pose stamp, and /diagnostics.',
        epilog='ROS arguments: --ros-args -r lf_pose:=truth/lf_pose -p bandwidth:="[0.1, 0.1, '
               '0.2]" --params-file config/dp_controller.yaml. Parameters: scenario, '
               + ', '.join(DpControllerConfig.__dataclass_fields__) + '.')
    parser.parse_args(list(remove_ros_args(list(argv)))[1:])


def main(args: list[str] | None = None) -> int:
    """Console script ``dp_controller``; returns the exit code."""
    _parse_cli(sys.argv if args is None else args)
    rclpy.init(args=args)
    return spin_node(DpControllerNode, config_errors=(ValueError, FileNotFoundError),
                     logger_name=NODE_NAME)


if __name__ == '__main__':
    sys.exit(main())
