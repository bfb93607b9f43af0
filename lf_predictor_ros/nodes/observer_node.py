"""Observer node: the classical wave filters behind the predictor's topics, for A/B tests.

Same input path and outputs as the ``predictor`` node (thin adapter: message → numpy → core →
message): ``thrust`` (WrenchStamped) → ``InputAligner.add_force``; ``measured_pose``
(PoseStamped) → ``InputAligner.add_pose`` → for each grid sample the estimator's ``update`` →
``lf_pose`` (PoseStamped, ``header.stamp`` = the sample time: a baseline estimates the LF pose
*now*, it does not predict) and ``/diagnostics``. Inputs use the sensor-data QoS, publishers are
reliable keep_last 10; all data times are message stamps.

``method``:
- ``passive_observer``: nonlinear passive observer (Fossen & Strand 1999; Fossen 2011 §11.4.1;
  MSS ``exPassiveObs.m``) with the vessel model ``mass_matrix``/``damping_matrix`` (defaults: the
  MSS supply vessel, ``sim_ros.physics.vessels`` SUPPLY_M/SUPPLY_D) and K3/K4 from
  ``bias_gains(vessel_mass, vessel_length)``;
- ``cascade``: causal notch + low-pass (Fossen 2011 §11.3.2; MSS ``notchFilter.m``).

ω0: ``wave_peak_freq`` > 0 fixes it. With 0 it follows the ``wave_peak_frequency`` topic
(published by a predictor node) and uses ``default_wave_peak_freq`` until the first message; a
change above ``RETUNE_TOLERANCE`` retunes the filter (state kept).

``ndof`` 3 (default) estimates north, east and heading; with ``ndof`` 1 only north is estimated
and the east and heading of ``lf_pose`` are the measured ones passed through unfiltered (never a
made-up 0), as in the predictor node.

Position-reference checks: the predictor node's (``core.reference_checks``, the same
``ReferenceCheckSettings`` parameters and defaults), so that an A/B test of the two nodes sees
the same reference. A rejected pose never reaches the aligner or the estimator (no ``lf_pose``
for it); a fault found after the fact (frozen, no wave motion, step, drift) restarts the data
segment and the estimator; a dropout is never bridged. The drift test compares each sample with
the estimator's previous output (a baseline estimates the LF pose now, so its last output is its
prediction for the next sample). Faults raise the ``/diagnostics`` level (WARN or ERROR with the
reason) and are counted (``ref_frozen``, ``ref_no_wave_motion``, ``ref_jump``, ``ref_step``,
``ref_drift``, ``ref_dropout``, ``ref_rejected``, ``ref_faults``). The cascade has no model to
coast on: after a rejected sample it continues with the next accepted one. A latched drift is
cleared by the service ``~/clear_reference_faults`` (std_srvs/Trigger), as on the predictor.

Runtime parameter changes are validated (the reason of a rejection is returned); an accepted
change re-creates the estimator and the aligner (its state restarts from the next pose); a change
of the reference checks restarts their statistics (counters kept).
Exceptions in callbacks are caught, counted (``callback_errors``) and reported in diagnostics.
A re-offered sample (the stamp and values of the pose whose ``lf_pose`` was published last: a
lockstep simulator's first sample) is answered with the same ``lf_pose`` (``reoffers_answered``),
as in the predictor node.
"""
# rclpy's Node and logger methods are untyped in Jazzy.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass, field
import math
import sys
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
import numpy as np
from numpy.typing import NDArray
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.utilities import remove_ros_args
from std_msgs.msg import Float64
from std_srvs.srv import Trigger

from lf_predictor_ros.core.alignment import AlignedSample, AlignerSettings, InputAligner
from lf_predictor_ros.core.baselines.cascade import CascadeFilter
from lf_predictor_ros.core.baselines.observer import PassiveObserver, bias_gains
from lf_predictor_ros.core.reference_checks import ReferenceChecker, ReferenceCheckSettings
from lf_predictor_ros.nodes.conversions import (
    FRAME_EARTH,
    pose_to_msg,
    sec_to_stamp,
)
from lf_predictor_ros.nodes.diagnostics import (
    DiagnosticValue,
    input_values,
    make_diagnostic_array,
    worse,
)
from lf_predictor_ros.nodes.health import InputHealth, ReofferAnswers
from lf_predictor_ros.nodes.params import (
    declare_and_load,
    parameter_table,
    validated_update,
)
from lf_predictor_ros.nodes.params import (
    param_meta as _meta,
)
from lf_predictor_ros.nodes.qos import publisher_qos, sensor_qos
from lf_predictor_ros.nodes.runner import spin_node
from sim_ros.physics.vessels import SUPPLY_D, SUPPLY_LENGTH, SUPPLY_M, SUPPLY_MASS

NODE_NAME = 'observer'
METHODS = ('passive_observer', 'cascade')
RETUNE_TOLERANCE = 1e-3  # [rad/s] smaller ω0 changes from the topic do not retune the filter

FloatArray = NDArray[np.float64]


def _row_major(matrix: FloatArray) -> list[float]:
    return [float(v) for v in np.asarray(matrix, dtype=np.float64).reshape(-1)]


@dataclass(frozen=True)
class ObserverConfig:
    """Parameters of the observer node (validated; see the module docstring)."""

    method: str = field(default='passive_observer', metadata=_meta(
        'baseline: passive_observer (Fossen & Strand 1999) or cascade (notch + low-pass)'))
    wave_peak_freq: float = field(default=0.0, metadata=_meta(
        'fixed wave peak frequency ω0; 0 = follow the wave_peak_frequency topic', 'rad/s'))
    default_wave_peak_freq: float = field(default=0.8, metadata=_meta(
        'ω0 used until the wave_peak_frequency topic has spoken (wave_peak_freq = 0)', 'rad/s'))
    mass_matrix: list[float] = field(default_factory=lambda: _row_major(SUPPLY_M), metadata=_meta(
        'vessel inertia M incl. added mass, 9 values row-major (MSS supply vessel)',
        'kg, kg·m, kg·m²'))
    damping_matrix: list[float] = field(
        default_factory=lambda: _row_major(SUPPLY_D), metadata=_meta(
            'linear damping D, 9 values row-major (MSS supply vessel)',
            'N·s/m, N·s, N·m·s'))
    vessel_mass: float = field(default=SUPPLY_MASS, metadata=_meta(
        'vessel mass m for the K3/K4 scaling (bias_gains)', 'kg'))
    vessel_length: float = field(default=SUPPLY_LENGTH, metadata=_meta(
        'vessel length L for the K3/K4 scaling (bias_gains)', 'm'))
    ndof: int = field(default=3, metadata=_meta('degrees of freedom estimated: 1 (surge) or 3'))
    sample_time: float = field(default=0.5, metadata=_meta('estimator sample time h', 's'))
    frame_id: str = field(default=FRAME_EARTH, metadata=_meta(
        'frame of measured_pose (expected) and of lf_pose (published)'))
    max_gap: float = field(default=5.0, metadata=_meta(
        'pose gap that starts a new data segment (estimator restarts)', 's'))
    thrust_timeout: float = field(default=2.0, metadata=_meta(
        'thrust older than this counts as stale (zero force used)', 's'))
    backward_jump: float = field(default=5.0, metadata=_meta(
        'backward stamp jump that restarts the stream', 's'))
    max_speed: float = field(default=20.0, metadata=_meta(
        'pose jumps faster than this are dropped as outliers', 'm/s'))
    average_poses: bool = field(default=True, metadata=_meta(
        'grid sample = mean of the poses received in its interval (anti-aliasing of a sensor '
        'faster than sample_time); false: the pose interpolated at the grid instant'))
    diagnostics_period: float = field(default=1.0, metadata=_meta(
        '/diagnostics period on the node clock', 's', read_only=True))

    def __post_init__(self) -> None:
        """Check every rule; the message says what to change."""
        if self.method not in METHODS:
            raise ValueError(f'method must be one of {METHODS}, got {self.method!r}')
        if self.ndof not in (1, 3):
            raise ValueError(f'ndof must be 1 (surge) or 3 (surge, sway, yaw), got {self.ndof}')
        if not (math.isfinite(self.wave_peak_freq) and self.wave_peak_freq >= 0.0):
            raise ValueError(f'wave_peak_freq must be 0 (follow the topic) or > 0 rad/s, got '
                             f'{self.wave_peak_freq}')
        for name in ('default_wave_peak_freq', 'vessel_mass', 'vessel_length', 'sample_time',
                     'diagnostics_period'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'{name} must be a positive finite number, got {value}')
        for name in ('mass_matrix', 'damping_matrix'):
            values = getattr(self, name)
            if len(values) != 9 or not all(math.isfinite(v) for v in values):
                raise ValueError(f'{name} must be 9 finite numbers (3×3 row-major), got '
                                 f'{len(values)} values')
        if not self.frame_id:
            raise ValueError("frame_id must not be empty: use the pose frame, e.g. 'map_ned'")
        self.aligner_settings()  # raises for invalid aligner rules

    def aligner_settings(self) -> AlignerSettings:
        """Aligner rules of this configuration."""
        return AlignerSettings(sample_time=self.sample_time, max_gap=self.max_gap,
                               thrust_timeout=self.thrust_timeout,
                               backward_jump=self.backward_jump, max_speed=self.max_speed,
                               average_poses=self.average_poses)

    def initial_wave_peak_freq(self) -> float:
        """ω0 [rad/s] to start with: the fixed value or the default."""
        return self.wave_peak_freq if self.wave_peak_freq > 0.0 else self.default_wave_peak_freq


def make_estimator(config: ObserverConfig,
                   wave_peak_freq: float) -> CascadeFilter | PassiveObserver:
    """The baseline ``config.method`` tuned to ω0 (ValueError if the model does not fit)."""
    if config.method == 'cascade':
        return CascadeFilter(config.ndof, config.sample_time, wave_peak_freq)
    k3, k4 = bias_gains(config.vessel_mass, config.vessel_length, config.ndof)
    return PassiveObserver(
        config.ndof, config.sample_time, wave_peak_freq,
        np.reshape(config.mass_matrix, (3, 3)), np.reshape(config.damping_matrix, (3, 3)),
        k3=k3, k4=k4)


class ObserverNode(InputHealth, Node):
    """Runs a classical LF estimator (passive observer or cascade) on aligned inputs."""

    def __init__(self, **node_kwargs: Any) -> None:
        super().__init__(NODE_NAME, **node_kwargs)
        self._config: ObserverConfig = declare_and_load(self, ObserverConfig)
        self._checks = declare_and_load(self, ReferenceCheckSettings)
        self._checker = ReferenceChecker(self._checks, self._config.ndof)
        self._predicted: tuple[float, FloatArray] | None = None  # (t + h, last output)
        self._wave_peak_freq = self._config.initial_wave_peak_freq()
        self._wave_source = 'parameter' if self._config.wave_peak_freq > 0.0 else 'default'
        self._estimator = make_estimator(self._config, self._wave_peak_freq)
        self._aligner = InputAligner(self._config.aligner_settings())
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._samples = 0
        self._init_input_health()
        self._reoffers: ReofferAnswers[PoseStamped] = ReofferAnswers()
        qos = publisher_qos()
        self._lf_pub = self.create_publisher(PoseStamped, 'lf_pose', qos)
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', qos)
        self.create_subscription(WrenchStamped, 'thrust', self.on_thrust, sensor_qos())
        self.create_subscription(PoseStamped, 'measured_pose', self.on_pose, sensor_qos())
        self.create_subscription(Float64, 'wave_peak_frequency', self.on_wave_peak_frequency,
                                 sensor_qos())
        self.create_timer(self._config.diagnostics_period, self.publish_diagnostics)
        self._services = [self.create_service(Trigger, '~/clear_reference_faults',
                                              self._on_clear_faults)]
        self.get_logger().info(
            f'{self._config.method}, {self._config.ndof}-DOF, sample time '
            f'{self._config.sample_time} s, ω0 {self._wave_peak_freq:.3f} rad/s '
            f'({self._wave_source})')

    @property
    def config(self) -> ObserverConfig:
        """The parameters in use."""
        return self._config

    @property
    def checker(self) -> ReferenceChecker:
        """The position-reference checks in use."""
        return self._checker

    @property
    def estimator(self) -> CascadeFilter | PassiveObserver:
        """The baseline in use."""
        return self._estimator

    @property
    def wave_peak_freq(self) -> float:
        """ω0 in use [rad/s]."""
        return self._wave_peak_freq

    # ---- runtime parameters --------------------------------------------------------------

    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        config, reason = validated_update(self._config, parameters)
        if config is None:
            return SetParametersResult(successful=False, reason=reason)
        freq, source = self._wave_peak_freq, self._wave_source
        estimator = self._estimator
        if config is not self._config:  # everything is checked before anything is applied
            if config.wave_peak_freq > 0.0:
                freq, source = config.wave_peak_freq, 'parameter'
            elif self._wave_source != 'topic':
                freq, source = config.default_wave_peak_freq, 'default'
            try:
                estimator = make_estimator(config, freq)
            except ValueError as error:
                return SetParametersResult(successful=False, reason=str(error))
        checks, reason = validated_update(self._checks, parameters)
        if checks is None:
            return SetParametersResult(successful=False, reason=reason)
        if checks != self._checks or config.ndof != self._config.ndof:
            self._replace_checker(checks, config.ndof)  # nothing below can fail any more
        if config is self._config:
            return SetParametersResult(successful=True, reason='')
        self._config, self._estimator = config, estimator
        self._wave_peak_freq, self._wave_source = freq, source
        self._aligner = InputAligner(config.aligner_settings())
        self._reoffers.forget()
        self._predicted = None
        self.get_logger().info(f'parameters changed: {config.method} re-created, state restarts')
        return SetParametersResult(successful=True, reason='')

    def _replace_checker(self, checks: ReferenceCheckSettings, ndof: int) -> None:
        """New reference checks (statistics restart, counters kept)."""
        self._checker = self._checker.renewed(checks, ndof)
        self._checks = checks
        self.get_logger().info('reference checks changed: statistics restart')

    # ---- data path -----------------------------------------------------------------------

    def on_wave_peak_frequency(self, msg: Float64) -> None:
        """Follow ω0 from the topic when ``wave_peak_freq`` is 0."""
        try:
            value = float(msg.data)
            if self._config.wave_peak_freq > 0.0 or not (math.isfinite(value) and value > 0.0):
                return
            self._wave_source = 'topic'
            if abs(value - self._wave_peak_freq) <= RETUNE_TOLERANCE:
                return
            self._estimator.set_wave_peak_freq(value)
            self._wave_peak_freq = value
        except Exception as error:  # noqa: BLE001 - a callback must never kill the node
            self._count_error('wave_peak_frequency', error)

    def on_thrust(self, msg: WrenchStamped) -> None:
        """Store an applied force (zero-order hold in the aligner)."""
        self._feed_thrust(msg, self._aligner)

    def on_pose(self, msg: PoseStamped) -> None:
        """Align a measured pose; estimate and publish for every completed grid sample."""
        self._feed_pose(msg, self._aligner, self._config.frame_id, self._process,
                        accept=self._check_pose)

    def _check_pose(self, t: float, pose: FloatArray) -> bool:
        """Position-reference checks of one pose (before the aligner); False: rejected.

        A re-offered sample is answered with its lf_pose again (and not checked twice).
        """
        checker = self._checker
        checker.seen(self._clock_seconds())
        answer = self._reoffers.answer(t, pose)
        if answer is not None:
            self._lf_pub.publish(answer)
            return False
        verdict = checker.check_pose(t, pose, self._wave_peak_freq)
        if verdict.restart:
            self._restart_data()
        elif verdict.gap:
            self._aligner.reset()  # a dropout is never bridged
        if verdict.fault is not None:
            self._log_reference_fault(self._checker)
        return verdict.accepted

    def _restart_data(self) -> None:
        """A fault found after the fact: the next sample starts a new segment (estimator reset)."""
        self._aligner.reset()
        self._predicted = None

    def _process(self, sample: AlignedSample) -> None:
        if sample.segment_start:
            self._estimator.reset()  # never filter across a gap or a time jump
            self._predicted = None
        predicted = self._predicted
        verdict = self._checker.check_sample(
            sample.t, sample.pose,
            predicted[1] if predicted is not None and abs(predicted[0] - sample.t) < 1e-6
            else None)
        if not verdict.accepted:
            if verdict.restart:
                self._restart_data()
            self._log_reference_fault(self._checker)
            return
        lf_pose = np.array(self._estimator.update(sample.t, sample.pose, sample.force),
                           dtype=np.float64)
        self._predicted = (sample.t + self._config.sample_time, lf_pose.copy())
        if self._config.ndof == 1:  # east and yaw are not estimated: pass the measurement
            lf_pose[1:] = sample.pose[1:]  # through, never a made-up 0 (as the predictor does)
        self._samples += 1
        msg = pose_to_msg(lf_pose, sec_to_stamp(sample.t), self._config.frame_id)
        self._lf_pub.publish(msg)
        self._reoffers.published(msg)

    def _on_clear_faults(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        """Clear the reference faults (a latched drift: the operator re-selected the reference)."""
        return self._clear_reference_faults(self._checker, response, 'the estimator stays')

    # ---- diagnostics ---------------------------------------------------------------------

    def diagnostic_values(self) -> tuple[str, str, dict[str, DiagnosticValue]]:
        """(level, message, key values) of the current state, as published."""
        status = self._estimator.status()
        level, message = 'OK', f'{status.state}: {status.message}'
        self._checker.silent_for(self._clock_seconds())  # flags and counts a dropout
        ref_level, ref_reason = self._checker.status()
        level, message = worse(level, message, ref_level,
                               f'position reference {ref_reason}; {message}')
        if self._callback_errors > self._errors_reported:
            level, message = 'ERROR', f'callback error: {self._last_error}'
        values: dict[str, DiagnosticValue] = {
            'method': self._config.method,
            'state': status.state,
            'wave_peak_freq': self._wave_peak_freq,
            'wave_peak_source': self._wave_source,
            **input_values(self._aligner.counters.as_dict(), self._samples,
                           self._invalid_messages),
            'unexpected_frame': self._unexpected_frame,
            'callback_errors': self._callback_errors,
            'last_error': self._last_error,
            'reoffers_answered': self._reoffers.answered,
            **self._checker.values(),
        }
        return level, message, values

    def publish_diagnostics(self) -> None:
        """Publish one DiagnosticArray (timer callback; never raises)."""
        try:
            level, message, values = self.diagnostic_values()
            self._errors_reported = self._callback_errors
            self._diag_pub.publish(make_diagnostic_array(
                f'{self.get_name()}: {self._config.method}', level, message, values,
                stamp=self.get_clock().now().to_msg()))
        except Exception as error:  # noqa: BLE001
            self._count_error('diagnostics', error)


def _parse_cli(argv: Sequence[str]) -> None:
    """Handle ``--help`` (exit 0, parameter table) and reject unknown non-ROS arguments."""
    parser = argparse.ArgumentParser(
        prog=NODE_NAME,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description='Classical LF estimators (passive observer, notch + low-pass cascade) on '
                    'the predictor topics: subscribes measured_pose, thrust, '
                    'wave_peak_frequency; publishes lf_pose (stamped t) and /diagnostics.',
        epilog='ROS arguments: --ros-args -p method:=cascade --params-file config/observer.yaml'
               '\n\nParameters (name, default, description [unit]); a run-time change '
               're-creates the estimator:\n' + parameter_table([ObserverConfig,
                                                                 ReferenceCheckSettings]))
    parser.parse_args(list(remove_ros_args(list(argv)))[1:])


def main(args: list[str] | None = None) -> int:
    """Console script ``observer``; returns the exit code."""
    _parse_cli(sys.argv if args is None else args)
    rclpy.init(args=args)
    return spin_node(ObserverNode, config_errors=(ValueError, TypeError), logger_name=NODE_NAME)


if __name__ == '__main__':
    sys.exit(main())
