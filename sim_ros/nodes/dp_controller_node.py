"""DP controller node: nonlinear MIMO PID on a pose topic, publishing ``thrust_command``.

Thin adapter around ``sim_ros.control.pid`` (MSS ``PIDnonlinearMIMO.m``, anchors §5):
subscribes ``lf_pose`` (remap to ``measured_pose`` or ``truth/lf_pose``; sensor-data QoS),
publishes one ``thrust_command`` (WrenchStamped, ``base_link_fsd``) per accepted pose, stamped
with that pose's stamp, so a lockstep simulator knows which sample the command answers.

dt is the difference of consecutive pose stamps (never the wall clock), so the controller is
correct in simulated time at any speed, with or without ``use_sim_time``. A pose whose stamp is
not newer than the last accepted one is ignored and counted in ``/diagnostics``. The first pose
(no previous stamp) uses ``nominal_dt``; a gap longer than ``max_dt`` restarts the controller
from the new pose (reference filter, integrator and velocity estimate reset; counted).

Tuning. ``scenario`` (read-only, default ``supply_closed_loop``) supplies the defaults of every
other parameter: the vessel's mass and linear damping diagonals (``Simulator.true_model()``), the
force limit (the scenario's ``controller.tau_max`` or its actuator capacity) and the scenario's
controller section (setpoint, bandwidth, ζ, T_f, T_v, sample time as ``nominal_dt``). Any of
them can be overridden with ``-p``/``--params-file``; ``scenario:=''`` uses the built-in MSS
supply-vessel values. Gains: Kp = M ω_n², Kd = 2ζω_n M − D, Ki = ω_n/10 Kp
(``gains_from_bandwidth``). Setpoint, bandwidth, ζ, limits and filter times may be changed at
run time (``ros2 param set``); invalid values are rejected with the reason.

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

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
import numpy as np
import rclpy
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rclpy.utilities import remove_ros_args

from lf_predictor_ros.nodes.conversions import msg_to_pose, stamp_to_ns, wrench_to_msg
from lf_predictor_ros.nodes.diagnostics import make_diagnostic_array
from lf_predictor_ros.nodes.params import LiveParameters, declare_and_load
from lf_predictor_ros.nodes.params import param_meta as _meta
from lf_predictor_ros.nodes.qos import publisher_qos, sensor_qos
from lf_predictor_ros.nodes.runner import spin_node
from sim_ros.control.pid import PidGains, PidState, gains_from_bandwidth, pid_step
from sim_ros.physics.vessels import SUPPLY_M
from sim_ros.simulation import Simulator, load_scenario

NODE_NAME = 'dp_controller'
NS_PER_S = 1e9  # [ns/s]


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

    def __post_init__(self) -> None:
        """Check every rule; the message says what to change."""
        _check_vector('setpoint', self.setpoint, -math.inf, strict=True)
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
    }


class DpControllerNode(Node):
    """One PID step per pose message; dt from the pose stamps."""

    def __init__(self, **node_kwargs: Any) -> None:
        super().__init__(NODE_NAME, **node_kwargs)
        source = declare_and_load(self, ControllerSource)
        defaults = scenario_defaults(source.scenario) if source.scenario else None
        self._params = LiveParameters(self, DpControllerConfig, on_change=self._on_config_change,
                                      defaults=defaults)
        self._gains = self._params.value.gains()
        self._state = PidState()
        self._last_stamp_ns: int | None = None
        self._poses = 0
        self._non_increasing = 0
        self._invalid = 0
        self._restarts = 0
        self._last_dt = math.nan
        self._last_tau = np.zeros(3)
        self._saturated = False

        self._command_pub = self.create_publisher(WrenchStamped, 'thrust_command',
                                                  publisher_qos())
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', publisher_qos())
        self.create_subscription(PoseStamped, 'lf_pose', self._on_pose, sensor_qos())
        self.create_timer(1.0, self._publish_diagnostics,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._diag_wall = time.monotonic()
        config = self._params.value
        self.get_logger().info(
            f'scenario {source.scenario!r}: setpoint {config.setpoint}, bandwidth '
            f'{config.bandwidth} rad/s, zeta {config.zeta}, tau_max {config.tau_max or "none"}')

    @property
    def config(self) -> DpControllerConfig:
        """Current validated parameters."""
        return self._params.value

    @property
    def counters(self) -> dict[str, int]:
        """Poses used, ignored (non-increasing stamp, invalid) and controller restarts."""
        return {'poses': self._poses, 'non_increasing_stamps': self._non_increasing,
                'invalid_poses': self._invalid, 'restarts': self._restarts}

    def _on_config_change(self, config: DpControllerConfig) -> None:
        self._gains = config.gains()

    def _on_pose(self, msg: PoseStamped) -> None:
        try:
            pose = msg_to_pose(msg)
        except ValueError as error:
            self._invalid += 1
            self.get_logger().warning(f'ignoring pose: {error}', throttle_duration_sec=5.0)
            return
        stamp_ns = stamp_to_ns(msg.header.stamp)
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
        tau, self._state = pid_step(self._state, self._gains, pose,
                                    np.asarray(config.setpoint), dt, tau_max)
        self._poses += 1
        self._last_dt = dt
        self._last_tau = tau
        self._saturated = tau_max is not None and bool(
            np.any(np.abs(tau) >= np.asarray(tau_max) * (1.0 - 1e-12)))
        self._command_pub.publish(wrench_to_msg(tau, msg.header.stamp))

    def _publish_diagnostics(self) -> None:
        wall_now = time.monotonic()
        idle = self._poses == 0
        level = 'WARN' if idle or self._saturated else 'OK'
        message = ('waiting for poses' if idle else
                   'command saturated' if self._saturated else 'controlling')
        error = (np.asarray(self._state.last_pose) - np.asarray(self._state.setpoint_filtered)
                 if self._state.initialized else np.full(3, math.nan))
        values: dict[str, float | int | bool | str] = {
            **self.counters,
            'last_dt': self._last_dt,
            'saturated': self._saturated,
            'error_north': float(error[0]), 'error_east': float(error[1]),
            'error_yaw': float(math.remainder(float(error[2]), 2.0 * math.pi)),
            'tau_surge': float(self._last_tau[0]), 'tau_sway': float(self._last_tau[1]),
            'tau_yaw': float(self._last_tau[2]),
            'wall_since_last_report': wall_now - self._diag_wall,
        }
        self._diag_wall = wall_now
        self._diag_pub.publish(make_diagnostic_array(
            f'{self.get_name()}: pid', level, message, values))


def _parse_cli(argv: Sequence[str]) -> None:
    """Handle ``--help`` (exit 0) and reject unknown non-ROS arguments (exit 2)."""
    parser = argparse.ArgumentParser(
        prog=NODE_NAME,
        description='DP controller node (nonlinear MIMO PID): subscribes lf_pose, publishes '
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
