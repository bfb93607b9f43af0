"""Predictor node: the adaptive LF pose predictor (thesis Algorithm 4.1) behind ROS topics.

A ``rclpy`` lifecycle node and a thin adapter: message → numpy → ``core`` → message.

Data path (all times are message stamps, so the node works with ``use_sim_time`` and bags):
``thrust`` (WrenchStamped, sensor-data QoS) → ``InputAligner.add_force``; ``measured_pose``
(PoseStamped, sensor-data QoS) → ``InputAligner.add_pose`` → for each aligned grid sample
``LfStateEstimator.update`` (the ``AdaptivePredictor`` + vessel memory + LF odometry,
``core.lf_state``) → ``lf_pose`` (PoseStamped, ``header.stamp`` = sample time + ``sample_time``,
the instant the prediction is valid for, frame ``frame_id``), ``lf_odom`` (nav_msgs/Odometry,
same stamp and pose, ``header.frame_id`` = ``frame_id``, ``child_frame_id`` ``base_link_fsd``:
body-frame LF twist, calibrated covariances; the layout of ``nodes.conversions.odometry_to_msg``,
published already serialized by ``bag.ros_codec.estimate_cdr``) and
``wave_peak_frequency`` (Float64 [rad/s], once ω0 is known). While tracking ``lf_pose`` is the
predictor's LF pose bit for bit. A sample that starts a new data segment (gap, time jump, reset)
restarts the predictor's segment; the trained network stays, and so does the odometry's state.

Dead reckoning (``nodes.lf_odom.OdomDriver``): when no sample has gone to the predictor for more
than ``dead_reckoning_after`` (0 = 2 × sample_time) of thrust stamps (poses silent, or rejected
by the position-reference checks) while thrust keeps coming, ``LfStateEstimator.coast`` runs for
the thrust stamp + sample_time (at most once per sample_time; the stamp rule of every estimate)
and its estimate is published on ``lf_pose`` and
``lf_odom`` with a pose covariance growing with the elapsed time (state ``dead_reckoning``, WARN).
After ``dead_reckoning_timeout`` without an accepted fix nothing is published (state ``lost``,
ERROR) rather than a guess. The first samples after the dropout go through ``update``: the
odometry gates them for plausibility and blends from the dead-reckoned pose
(``reacquire_blend_time``), so ``lf_pose`` does not step. Every ``OdometryParams`` field is a
node parameter (``core/odometry_params.py``, ``config/predictor.yaml``: the dead-reckoning
timeout and start velocity, the covariance scales and priors, the twist bandwidth, the
reacquisition gate).
``thrust_command`` (WrenchStamped, command QoS; optional) → ``OdomDriver.command``: the DP
controller's commands, from which the vessel memory reads the controller's gains and the inertia
they imply for dead reckoning (``controller_inertia``, ``core.controller_gains``).

Training runs on the core's worker thread; no callback ever waits for it. With ``model_path``
set, the node loads that checkpoint at configure time (warm start) and the worker saves after
each accepted training (after a run-time change of the network structure the file then holds the
new shape). With ``motion_gate`` the ramp-invariant twin has its own checkpoint beside it,
``model_path + '.twin'``: loaded with the holding network (a missing one: the twin starts cold,
``model_file`` in the diagnostics says so) and saved by the twin's worker after each of its
accepted trainings. A file (or twin file) that does not fit the parameters or is corrupt is
refused with an ERROR log, the node starts cold and does not save over the refused files.

Position-reference checks (``core.reference_checks``, parameters ``reference_checks``,
``frozen_time``, ``motion_*``, ``jump_*``, ``drift_*``, ``dropout_timeout``) run on every pose
before the aligner: a frozen, jumping or drifting reference is rejected (it never enters the
aligner, the predictor or a training), a fault found after the fact drops the buffered data (new
segment, a running training discarded; the network in service stays), and a pose silence longer
than ``dropout_timeout`` on the node clock is a dropout (counted once; the first pose after
it starts a new data segment: a dropout is never bridged by interpolation). A drift latches until
``~/clear_reference_faults`` (or ``~/reset``).

A re-offered sample: a pose with the stamp and the values of the pose whose estimate was the
last one published (a lockstep simulator offers its first sample again until it hears an answer,
and the first answer can be lost while publishers are still matching) is answered again with the
same ``lf_pose`` and ``lf_odom``, without a new estimate, and counted (``reoffers_answered``).
Without this the loop of a demo run hung at t = 0 once (1 of 6 runs): the simulator re-offered
its first sample for 190 s and the node ignored every repeat as out of order.

Default 3 DOF. With ``ndof`` 1 only north is estimated; east and yaw of ``lf_pose`` are the
measured east and yaw passed through unfiltered (never a made-up 0): the node logs a WARN at
configure, publishes ``unfiltered_dofs`` in the diagnostics, and the level is WARN once the
passed-through DOFs move (a 3-DOF vessel run with ndof 1).

``/diagnostics`` (DiagnosticArray, every ``diagnostics_period`` of the node clock): level OK
while warming up or trained, WARN in fallback, ERROR in error (or after a callback failed since
the last report); the position-reference status raises it (WARN for a rejected outlier in the
last 10 s, ERROR for frozen, no wave motion, a step, drift or dropout, with the reason as the
message); key values: predictor status and counters, aligner counters, frames, ``ref_*``
counters of each reference fault (``ref_frozen``, ``ref_no_wave_motion``, ``ref_jump``,
``ref_step``, ``ref_drift``, ``ref_dropout``), ``ref_rejected``, ``ref_faults`` (active now),
``pose_silence`` [s], ``ndof``, ``unfiltered_dofs``. The odometry: ``odom_mode`` (tracking,
dead_reckoning, lost), ``dead_reckoning_time`` [s], ``reckoner`` (model, constant_velocity,
hold), ``odom_calibrated``, ``vessel_memory``, ``vessel_memory_error``, the ``odom_*`` counters
(dead_reckoning_episodes, lost, reacquired, reacquired_outside_gate, fixes_held_back,
calibrations, memory_updates, late_samples, time_jumps, coasts). While dead reckoning the level
is WARN with the elapsed time and the reckoner leading the message (the reference fault that
caused it follows); once lost it is ERROR ``lost: no accepted position reference for > T s: not
publishing``.

Services: ``~/retrain`` (std_srvs/Trigger: ``request_retrain()``'s answer), ``~/reset``
(forget the network, data, ω0, counters of trainings and the odometry; state becomes
warming_up; reference faults cleared) and ``~/clear_reference_faults`` (the operator re-selects
the position reference: latched faults and the checks' statistics are cleared, the network
stays).

Lifecycle: parameters are declared and validated at construction (invalid → FATAL, exit 1);
configure builds aligner, predictor, publishers, subscriptions, services and the diagnostics
timer; activate enables publishing and data input (inputs are ignored while inactive); cleanup
and shutdown stop training and release everything. ``autostart`` (default true) configures and
activates at start, so ``ros2 run lf_predictor_ros predictor`` just works.

Runtime parameter changes are validated (the reason of a rejection is returned) and applied as:
- ``PredictorParams`` fields: the predictor is re-created with the new values (logged). When
  neither the network structure (ndof, nu, ny, nfb, hidden_units, hidden_layers,
  regressor_frame, ramp_invariant, ramp_order) nor sample_time changes, the trained network and
  ω0 are carried over (warm start), and so is the motion gate's trained twin unless its own
  structure (``motion_gate_ny``) changed (then the twin alone starts cold, as it does when
  ``motion_gate`` is switched on); otherwise it starts cold. Collected data restarts in both
  cases (the next training needs a full window).
- aligner settings (max_gap, thrust_timeout, backward_jump, max_speed, average_poses): a new
  aligner, a new data segment. ``frame_id``: immediately.
- reference-check settings (and ``ndof``): new checks with fresh statistics (counters kept).
- odometry settings (``OdometryParams``) and ``dead_reckoning_after``: from the next sample on.
  A re-created predictor keeps the odometry (dead reckoning, calibration, vessel memory) unless
  ``ndof`` or ``sample_time`` changed.
- ``model_path``, ``diagnostics_period``, ``autostart``: read-only (set them at start).

Never does an exception in a callback kill the node: it is caught, counted (``callback_errors``),
logged and reported in the diagnostics. An input whose ``frame_id`` is not the expected one
(``frame_id`` for poses, ``base_link_fsd`` for thrust) is used, counted (``unexpected_frame``) and
warned about once per topic.
"""
# rclpy's Node, lifecycle and logger methods are untyped in Jazzy.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass, field
import math
import os
import sys
import tempfile
from typing import TYPE_CHECKING, Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.parameter import Parameter
from rclpy.utilities import remove_ros_args
from std_msgs.msg import Float64
from std_srvs.srv import Trigger

from lf_predictor_ros.bag.ros_codec import estimate_cdr, float64_cdr
from lf_predictor_ros.core.alignment import AlignedSample, AlignerSettings, InputAligner
from lf_predictor_ros.core.estimator import EstimatorStatus
from lf_predictor_ros.core.odometry import OdometryEstimate
from lf_predictor_ros.core.odometry_params import OdometryParams
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.reference_checks import ReferenceChecker, ReferenceCheckSettings
from lf_predictor_ros.nodes.conversions import (
    FRAME_BODY,
    FRAME_EARTH,
    msg_to_force,
    sec_to_stamp,
    stamp_to_sec,
)
from lf_predictor_ros.nodes.diagnostics import (
    DiagnosticValue,
    input_values,
    make_diagnostic_array,
    predictor_values,
    with_reference_and_odometry,
    worse,
)
from lf_predictor_ros.nodes.health import FloatArray, InputHealth, ReofferAnswers
from lf_predictor_ros.nodes.lf_odom import OdomDriver, dead_reckoning_silence
from lf_predictor_ros.nodes.params import declare_and_load, parameter_table, validated_update
from lf_predictor_ros.nodes.params import param_meta as _meta
from lf_predictor_ros.nodes.qos import command_qos, publisher_qos, sensor_qos
from lf_predictor_ros.nodes.runner import spin_node

if TYPE_CHECKING:  # torch is imported on configure, so --help and bad parameters answer fast
    from lf_predictor_ros.core.lf_state import LfStateEstimator
    from lf_predictor_ros.core.predictor import AdaptivePredictor

NODE_NAME = 'predictor'
# PredictorParams fields that change the network (or its time base): a change starts cold.
STRUCTURE_FIELDS = ('ndof', 'nu', 'ny', 'nfb', 'hidden_units', 'hidden_layers', 'sample_time',
                    'regressor_frame', 'ramp_invariant', 'ramp_order')
NOTE_STRUCTURE = ' (run-time change: re-creates the predictor cold, data restarts)'
NOTE_TUNING = (' (run-time change: re-creates the predictor keeping the trained network, '
               'data restarts)')
# PredictorParams fields that change only the motion gate twin's network: a change keeps the
# holding network, the twin starts cold.
TWIN_STRUCTURE_FIELDS = ('motion_gate_ny',)
NOTE_TWIN = (' (run-time change: re-creates the predictor keeping the trained network; the '
             'motion gate twin starts cold, data restarts)')


@dataclass(frozen=True)
class PredictorNodeSettings:
    """Node settings besides the ``PredictorParams`` (validated; see the module docstring)."""

    model_path: str = field(default='', metadata=_meta(
        "checkpoint: loaded at start (warm start), saved after each accepted training; '' = "
        "none; with motion_gate the twin's checkpoint is model_path + '.twin'", read_only=True))
    frame_id: str = field(default=FRAME_EARTH, metadata=_meta(
        'frame of measured_pose (expected) and of lf_pose (published)'))
    max_gap: float = field(default=5.0, metadata=_meta(
        'pose gap that starts a new data segment (no interpolation across)', 's'))
    thrust_timeout: float = field(default=2.0, metadata=_meta(
        'thrust older than this counts as stale (zero force used)', 's'))
    backward_jump: float = field(default=5.0, metadata=_meta(
        'backward stamp jump that restarts the stream (simulator reset, bag loop)', 's'))
    max_speed: float = field(default=20.0, metadata=_meta(
        'pose jumps faster than this are dropped as outliers', 'm/s'))
    average_poses: bool = field(default=True, metadata=_meta(
        'grid sample = mean of the poses received in its interval (anti-aliasing of a sensor '
        'faster than sample_time); false: the pose interpolated at the grid instant'))
    dead_reckoning_after: float = field(default=0.0, metadata=_meta(
        'pose silence (thrust stamp minus the last accepted sample) after which lf_pose and '
        'lf_odom are dead-reckoned on thrust; 0 = 2 × sample_time; must exceed the delay of '
        'the pose stream behind the thrust stream', 's'))
    diagnostics_period: float = field(default=1.0, metadata=_meta(
        '/diagnostics period on the node clock', 's', read_only=True))
    autostart: bool = field(default=True, metadata=_meta(
        'configure and activate at start (false: wait for lifecycle transitions)',
        read_only=True))

    def __post_init__(self) -> None:
        """Check every rule; the message says what to change."""
        if not self.frame_id:
            raise ValueError("frame_id must not be empty: use the pose frame, e.g. 'map_ned'")
        for name in ('max_gap', 'thrust_timeout', 'backward_jump', 'max_speed',
                     'diagnostics_period'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'{name} must be a positive finite number, got {value}')
        if not (math.isfinite(self.dead_reckoning_after) and self.dead_reckoning_after >= 0.0):
            raise ValueError('dead_reckoning_after must be a finite number >= 0 s (0 = 2 × '
                             f'sample_time), got {self.dead_reckoning_after}')

    def aligner_settings(self, sample_time: float) -> AlignerSettings:
        """Aligner rules at the predictor's sample time (ValueError if they do not fit).

        Also checks ``dead_reckoning_after`` against the sample time.
        """
        dead_reckoning_silence(self.dead_reckoning_after, sample_time)
        return AlignerSettings(sample_time=sample_time, max_gap=self.max_gap,
                               thrust_timeout=self.thrust_timeout,
                               backward_jump=self.backward_jump, max_speed=self.max_speed,
                               average_poses=self.average_poses)


def _change_note(name: str) -> str:
    if name in STRUCTURE_FIELDS:
        return NOTE_STRUCTURE
    return NOTE_TWIN if name in TWIN_STRUCTURE_FIELDS else NOTE_TUNING


def diagnostic_level(status: EstimatorStatus) -> str:
    """Level of a predictor state: warming_up/trained/ok → OK, fallback → WARN, error → ERROR."""
    return {'fallback': 'WARN', 'error': 'ERROR'}.get(status.state, 'OK')


class PredictorNode(InputHealth, LifecycleNode):
    """Lifecycle node running ``AdaptivePredictor`` on aligned pose and thrust messages."""

    def __init__(self, **node_kwargs: Any) -> None:
        super().__init__(NODE_NAME, **node_kwargs)
        self._params = declare_and_load(self, PredictorParams, note=_change_note)
        self._settings = declare_and_load(self, PredictorNodeSettings)
        self._checks = declare_and_load(self, ReferenceCheckSettings)
        self._odom_params = declare_and_load(self, OdometryParams)
        self._settings.aligner_settings(self._params.sample_time)  # cross-check at start
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._aligner: InputAligner | None = None
        self._predictor: AdaptivePredictor | None = None
        self._odom: OdomDriver | None = None  # the LfStateEstimator around the predictor
        self._checker: ReferenceChecker | None = None
        self._predicted: tuple[float, FloatArray] | None = None  # (valid at, lf_pose) last out
        self._reoffers: ReofferAnswers[OdometryEstimate] = ReofferAnswers()
        self._passthrough_moving = False  # ndof 1 and the measured east/yaw are not all 0
        self._active = False
        self._subscriptions_in_use: list[Any] = []
        self._services_in_use: list[Any] = []
        self._timer: Any = None
        self._lf_pub: Any = None
        self._odom_pub: Any = None
        self._freq_pub: Any = None
        self._diag_pub: Any = None
        self._samples = 0  # aligned samples processed in total
        self._samples_in_run = 0  # since the predictor was (re-)created or reset
        self._init_input_health()
        self._warm_start = False
        self._model_file = 'none'
        self._save_path: str | None = None
        if self._settings.autostart:
            if self.trigger_configure() != TransitionCallbackReturn.SUCCESS:
                raise RuntimeError('autostart: configure failed (see the ERROR above)')
            self.trigger_activate()

    # ---- read-only views -----------------------------------------------------------------

    @property
    def samples(self) -> int:
        """Aligned samples processed in total (the diagnostics' ``samples``)."""
        return self._samples

    @property
    def params(self) -> PredictorParams:
        """The predictor parameters in use."""
        return self._params

    @property
    def settings(self) -> PredictorNodeSettings:
        """The node settings in use."""
        return self._settings

    @property
    def checks(self) -> ReferenceCheckSettings:
        """The position-reference check settings in use."""
        return self._checks

    @property
    def checker(self) -> ReferenceChecker | None:
        """The position-reference checks (None while unconfigured)."""
        return self._checker

    @property
    def predictor(self) -> AdaptivePredictor | None:
        """The predictor (None while unconfigured)."""
        return self._predictor

    @property
    def odometry_params(self) -> OdometryParams:
        """The LF odometry settings in use."""
        return self._odom_params

    @property
    def state(self) -> LfStateEstimator | None:
        """The LF state estimator around the predictor (None while unconfigured)."""
        return self._odom.state if self._odom is not None else None

    # ---- lifecycle -----------------------------------------------------------------------

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Build aligner, predictor (warm start), publishers, inputs, services and timer."""
        try:
            self._aligner = InputAligner(self._settings.aligner_settings(self._params.sample_time))
            self._predictor = self._new_predictor(self._params)
            self._checker = ReferenceChecker(self._checks, self._params.ndof)
            self._load_model()
            self._odom = OdomDriver(
                self._new_state(self._params, self._predictor),
                dead_reckoning_silence(self._settings.dead_reckoning_after,
                                       self._params.sample_time),
                self._settings.backward_jump)
        except (ValueError, OSError) as error:
            self.get_logger().error(f'configure failed: {error}')
            return TransitionCallbackReturn.FAILURE
        qos = publisher_qos()
        self._lf_pub = self.create_lifecycle_publisher(PoseStamped, 'lf_pose', qos)
        self._odom_pub = self.create_lifecycle_publisher(Odometry, 'lf_odom', qos)
        self._freq_pub = self.create_lifecycle_publisher(Float64, 'wave_peak_frequency', qos)
        self._diag_pub = self.create_lifecycle_publisher(DiagnosticArray, '/diagnostics', qos)
        self._subscriptions_in_use = [
            self.create_subscription(WrenchStamped, 'thrust', self.on_thrust, sensor_qos()),
            self.create_subscription(PoseStamped, 'measured_pose', self.on_pose, sensor_qos()),
            self.create_subscription(WrenchStamped, 'thrust_command', self.on_command,
                                     command_qos())]
        self._services_in_use = [
            self.create_service(Trigger, '~/retrain', self._on_retrain),
            self.create_service(Trigger, '~/reset', self._on_reset),
            self.create_service(Trigger, '~/clear_reference_faults', self._on_clear_faults)]
        self._timer = self.create_timer(self._settings.diagnostics_period,
                                        self.publish_diagnostics)
        p = self._params
        fit = ('linear network, least squares' if p.hidden_units == 0
               else f'{p.hidden_units} tanh units, trainer {p.trainer}')
        self.get_logger().info(
            f'configured: {p.ndof}-DOF, sample time {p.sample_time} s, retrain every '
            f'{p.retrain_period} s on {p.training_window} s, {fit}; model '
            f'{self._model_file}; reference checks '
            f'{"on" if self._checks.reference_checks else "OFF"}')
        self._warn_passthrough()
        return super().on_configure(state)

    def _warn_passthrough(self) -> None:
        if self._params.ndof == 1:
            self.get_logger().warning(
                'ndof 1: only north is estimated; east and yaw of lf_pose are the measurement '
                'passed through UNFILTERED (set ndof 3 for a 3-DOF vessel)')

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Enable the publishers and the data input."""
        self._active = True
        self.get_logger().info('active: predicting on measured_pose + thrust')
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop publishing; inputs are ignored until activated again (state is kept)."""
        self._active = False
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop training and release predictor, publishers, inputs, services and timer."""
        self._release()
        return super().on_cleanup(state)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Same as cleanup, from any state."""
        self._release()
        return super().on_shutdown(state)

    def _release(self) -> None:
        self._active = False
        if self._odom is not None:
            self._odom.state.close()  # the predictor's: waits ≤ 5 s for the next epoch boundary
        elif self._predictor is not None:
            self._predictor.close()
        self._predictor = None
        self._odom = None
        self._aligner = None
        self._checker = None
        self._predicted = None
        self._reoffers.forget()
        for subscription in self._subscriptions_in_use:
            self.destroy_subscription(subscription)
        for service in self._services_in_use:
            self.destroy_service(service)
        if self._timer is not None:
            self.destroy_timer(self._timer)
        self._subscriptions_in_use, self._services_in_use, self._timer = [], [], None
        for publisher in (self._lf_pub, self._odom_pub, self._freq_pub, self._diag_pub):
            if publisher is not None:
                self.destroy_lifecycle_publisher(publisher)
        self._lf_pub = self._odom_pub = self._freq_pub = self._diag_pub = None

    def destroy_node(self) -> None:
        """Stop a running training before the node goes."""
        if self._odom is not None:
            self._odom.state.close()
        elif self._predictor is not None:
            self._predictor.close()
        super().destroy_node()

    # ---- predictor construction ----------------------------------------------------------

    def _new_predictor(self, params: PredictorParams) -> AdaptivePredictor:
        from lf_predictor_ros.core.predictor import AdaptivePredictor  # torch: loaded on first use

        self._samples_in_run = 0
        return AdaptivePredictor(params, background=True, checkpoint_path=self._save_path)

    def _new_state(self, params: PredictorParams,
                   predictor: AdaptivePredictor) -> LfStateEstimator:
        from lf_predictor_ros.core.lf_state import LfStateEstimator  # torch: loaded on first use

        return LfStateEstimator(params, self._odom_params, background=True, predictor=predictor)

    def _load_model(self) -> None:
        """Warm start from ``model_path`` when it exists; refuse a file that does not fit."""
        from lf_predictor_ros.core.predictor import twin_checkpoint_path  # torch: already imported

        assert self._predictor is not None
        path = self._settings.model_path
        self._warm_start = False
        self._save_path = path or None
        if not path:
            self._model_file = 'none'
        elif not os.path.exists(path):
            self._model_file = f'{path} (not found: cold start, saved after training)'
        else:
            try:
                self._predictor.load(path)
            except (ValueError, OSError) as error:
                self._save_path = None  # never overwrite a file we could not read
                self._model_file = f'{path} refused: {error}'
                self.get_logger().error(
                    f'model file {path} refused, starting cold and not saving over it: {error}')
            else:
                self._warm_start = True
                twin = ''
                if self._predictor.params.motion_gate:
                    twin = ', motion gate twin ' + (
                        'restored' if self._predictor.twin_model is not None else
                        f'cold: no {twin_checkpoint_path(path)}')
                self._model_file = f'{path} (warm start{twin})'
                self.get_logger().info(f'warm start from {path}{twin}')
        self._predictor.checkpoint_path = self._save_path

    def _replace_predictor(self, params: PredictorParams) -> None:
        """Re-create the predictor; carry the network over when its structure is unchanged.

        The motion gate twin comes with it when its own structure is unchanged too (else the
        twin starts cold: ``strict_twin`` False).
        """
        old = self._predictor
        keep = old is not None and old.model is not None and all(
            getattr(old.params, name) == getattr(params, name) for name in STRUCTURE_FIELDS)
        new = self._new_predictor(params)
        if old is not None and keep:
            with tempfile.TemporaryDirectory() as folder:
                path = os.path.join(folder, 'carry_over.pt')
                old.save(path)  # with the gate: carry_over.pt.twin too
                new.load(path, strict_twin=False)
        if old is not None:
            old.reset()  # drops a running training without waiting for it
        self._predictor = new
        state = self._new_state(params, new)
        driver = self._odom
        if driver is not None:
            odometry = driver.state.odometry
            if odometry.ndof == params.ndof and odometry.sample_time == params.sample_time:
                # dead reckoning, calibration, memory and the controller read carry over
                state.carry_over(driver.state)
            else:
                driver.reset()  # a new odometry: a new timeline
            driver.state = state
        how = 'trained network kept' if keep else 'starting cold'
        if keep and params.motion_gate:
            how += ', motion gate twin ' + ('kept' if new.twin_model is not None else 'cold')
        self.get_logger().info(f'parameters changed: predictor re-created ({how}); data restarts')

    # ---- runtime parameters --------------------------------------------------------------

    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        new_params, reason = validated_update(self._params, parameters)
        if new_params is None:
            return SetParametersResult(successful=False, reason=reason)
        new_settings, reason = validated_update(self._settings, parameters)
        if new_settings is None:
            return SetParametersResult(successful=False, reason=reason)
        new_checks, reason = validated_update(self._checks, parameters)
        if new_checks is None:
            return SetParametersResult(successful=False, reason=reason)
        new_odom, reason = validated_update(self._odom_params, parameters)
        if new_odom is None:
            return SetParametersResult(successful=False, reason=reason)
        try:
            aligner_settings = new_settings.aligner_settings(new_params.sample_time)
        except ValueError as error:
            return SetParametersResult(successful=False, reason=str(error))
        try:
            self._apply(new_params, new_settings, aligner_settings, new_checks)
            self._apply_odometry(new_odom)
        except Exception as error:  # noqa: BLE001 - keep the node alive, report the reason
            self._count_error('parameter change', error)
            return SetParametersResult(successful=False, reason=f'could not apply: {error}')
        return SetParametersResult(successful=True, reason='')

    def _apply(self, params: PredictorParams, settings: PredictorNodeSettings,
               aligner_settings: AlignerSettings, checks: ReferenceCheckSettings) -> None:
        configured = self._predictor is not None
        if configured and params != self._params:
            self._replace_predictor(params)
            self._predicted = None
        if self._aligner is not None and aligner_settings != self._aligner.settings:
            self._aligner = InputAligner(aligner_settings)
            self.get_logger().info('aligner settings changed: new data segment')
        old = self._checker
        if old is not None and (checks != self._checks or params.ndof != self._params.ndof):
            self._checker = old.renewed(checks, params.ndof)
            self.get_logger().info('reference checks changed: statistics restart')
        if params.ndof != self._params.ndof:
            self._passthrough_moving = False
        self._params, self._settings, self._checks = params, settings, checks
        if self._odom is not None:
            self._odom.dead_reckoning_after = dead_reckoning_silence(
                settings.dead_reckoning_after, params.sample_time)
            self._odom.backward_jump = settings.backward_jump
        if configured and params.ndof == 1:
            self._warn_passthrough()

    def _apply_odometry(self, odometry: OdometryParams) -> None:
        """New odometry settings: used from the next sample on (state kept)."""
        if odometry == self._odom_params:
            return
        self._odom_params = odometry
        if self._odom is not None:
            self._odom.state.odometry.params = odometry
            self.get_logger().info('odometry settings changed: used from the next sample on')

    # ---- data path -----------------------------------------------------------------------

    def on_thrust(self, msg: WrenchStamped) -> None:
        """Store an applied force (zero-order hold in the aligner); dead-reckon when due."""
        if self._active and self._aligner is not None:
            accepted = self._feed_thrust(msg, self._aligner)
            if accepted is not None and self._odom is not None:
                try:
                    estimate = self._odom.thrust(*accepted)
                    if estimate is not None:
                        self._publish(estimate)
                except Exception as error:  # noqa: BLE001 - a callback must never kill the node
                    self._count_error('dead reckoning', error)

    def on_command(self, msg: WrenchStamped) -> None:
        """Log a DP controller command (its gains imply the dead reckoner's inertia)."""
        if self._active and self._odom is not None:
            try:
                force = self._converted('thrust_command', msg, FRAME_BODY, msg_to_force)
                if force is not None:
                    self._odom.command(stamp_to_sec(msg.header.stamp), force)
            except Exception as error:  # noqa: BLE001 - a callback must never kill the node
                self._count_error('thrust_command', error)

    def on_pose(self, msg: PoseStamped) -> None:
        """Align a measured pose; predict and publish for every completed grid sample."""
        if self._active and self._aligner is not None:
            self._feed_pose(msg, self._aligner, self._settings.frame_id, self._process,
                            accept=self._check_pose)

    def _check_pose(self, t: float, pose: FloatArray) -> bool:
        """Position-reference checks of one pose (before the aligner); False: rejected."""
        checker, predictor = self._checker, self._predictor
        assert checker is not None and predictor is not None
        checker.seen(self._clock_seconds())
        answer = self._reoffers.answer(t, pose)
        if answer is not None:  # a re-offered sample: the same estimate again
            self._send(answer)
            return False
        verdict = checker.check_pose(t, pose, predictor.wave_peak_freq)
        if verdict.restart:
            self._restart_data()
        elif verdict.gap and self._aligner is not None:
            self._aligner.reset()  # a dropout is never bridged: no made-up sample is trained on
        if verdict.fault is not None:
            self._log_reference_fault(checker)
        return verdict.accepted

    def _restart_data(self) -> None:
        """A fault was found after the fact: drop the buffered data and a running training."""
        assert self._aligner is not None and self._predictor is not None
        self._aligner.reset()  # the next sample starts a new segment (predictor buffers cleared)
        self._predictor.discard_running_job()
        self._predicted = None

    def _prediction_for(self, t: float) -> FloatArray | None:
        if self._predicted is None or abs(self._predicted[0] - t) > 1e-6:
            return None
        return self._predicted[1]

    def _process(self, sample: AlignedSample) -> None:
        predictor, checker, driver = self._predictor, self._checker, self._odom
        assert predictor is not None and checker is not None and driver is not None
        if sample.segment_start and self._samples_in_run > 0:
            driver.state.restart_segment()  # the odometry keeps its state across it
            self._predicted = None
        verdict = checker.check_sample(sample.t, sample.pose, self._prediction_for(sample.t))
        if not verdict.accepted:
            if verdict.restart:
                self._restart_data()
            self._log_reference_fault(checker)
            return
        lf_pose, estimate = driver.update(sample.t, sample.pose, sample.force,
                                          sample.segment_start)
        self._predicted = None if lf_pose is None else \
            (sample.t + self._params.sample_time, lf_pose)
        if self._params.ndof == 1 and (sample.pose[1] != 0.0 or sample.pose[2] != 0.0):
            self._passthrough_moving = True
        self._samples += 1
        self._samples_in_run += 1
        if estimate is not None:  # None: lost (fix held back) or late
            self._publish(estimate)  # stamp t + h, pose = lf_pose while tracking
            self._reoffers.published(estimate)
        wave_peak_freq = predictor.wave_peak_freq
        if wave_peak_freq is not None:
            self._freq_pub.publish(float64_cdr(float(wave_peak_freq)))

    def _publish(self, estimate: OdometryEstimate) -> None:
        """One estimate on lf_pose and lf_odom; no re-offer answered with it unless noted."""
        self._reoffers.forget()  # _process notes it again when it answers the pose being fed
        self._send(estimate)

    def _send(self, estimate: OdometryEstimate) -> None:
        """Publish one estimate on lf_pose and lf_odom (same stamp, same pose).

        Published serialized (`estimate_cdr`: the bytes rclpy would send for `pose_to_msg` and
        `odometry_to_msg`, without building the messages).
        """
        lf_data, odom_data = estimate_cdr(
            sec_to_stamp(estimate.stamp), self._settings.frame_id, FRAME_BODY, estimate.pose,
            estimate.pose_cov, estimate.twist, estimate.twist_cov)
        self._lf_pub.publish(lf_data)
        self._odom_pub.publish(odom_data)

    # ---- services ------------------------------------------------------------------------

    def _on_retrain(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        try:
            if self._predictor is None:
                response.success, response.message = False, 'predictor not configured'
            else:
                response.success, response.message = self._predictor.request_retrain()
        except Exception as error:  # noqa: BLE001
            self._count_error('~/retrain', error)
            response.success, response.message = False, f'retrain failed: {error}'
        return response

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        try:
            if self._predictor is None or self._aligner is None:
                response.success, response.message = False, 'predictor not configured'
                return response
            if self._odom is not None:
                self._odom.state.reset()  # predictor, odometry and vessel memory
                self._odom.reset()
            else:
                self._predictor.reset()
            self._aligner.reset()
            if self._checker is not None:
                self._checker.reset()
            self._predicted = None
            self._reoffers.forget()
            self._samples_in_run = 0
            self._warm_start = False
            status = self._predictor.status()
            response.success = True
            response.message = (f'predictor reset: state {status.state}, network, data, ω0 '
                                'and the odometry forgotten')
            self.get_logger().info(response.message)
        except Exception as error:  # noqa: BLE001
            self._count_error('~/reset', error)
            response.success, response.message = False, f'reset failed: {error}'
        return response

    def _on_clear_faults(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        return self._clear_reference_faults(self._checker, response, 'the network stays')

    # ---- diagnostics ---------------------------------------------------------------------

    def diagnostic_values(self) -> tuple[str, str, dict[str, DiagnosticValue]]:
        """(level, message, key values) of the current state, as published."""
        predictor, aligner, checker = self._predictor, self._aligner, self._checker
        driver = self._odom
        if predictor is None or aligner is None or checker is None or driver is None:
            return 'WARN', 'not configured', {}
        status = predictor.status()
        level, message = diagnostic_level(status), f'{status.state}: {status.message}'
        silence = checker.silent_for(self._clock_seconds())
        level, message = with_reference_and_odometry(level, message, checker.status(),
                                                     driver.status())
        unfiltered = 'east yaw' if self._params.ndof == 1 else 'none'
        if self._passthrough_moving:
            level, message = worse(level, message, 'WARN',
                                   f'ndof 1: east and yaw are the measurement, unfiltered; '
                                   f'{message}')
        if self._callback_errors > self._errors_reported:
            level, message = 'ERROR', f'callback error: {self._last_error}'
        values: dict[str, DiagnosticValue] = {
            **predictor_values(status, predictor.counters),
            **input_values(aligner.counters.as_dict(), self._samples, self._invalid_messages),
            'unexpected_frame': self._unexpected_frame,
            'callback_errors': self._callback_errors,
            'reoffers_answered': self._reoffers.answered,
            'last_error': self._last_error,
            **checker.values(),
            'pose_silence': math.nan if silence is None else silence,
            **driver.values(),
            'ndof': self._params.ndof,
            'unfiltered_dofs': unfiltered,
            'omega_fits_here': predictor.omega_fits_here,
            'warm_start': self._warm_start,
            'model_file': self._model_file,
            'active': self._active,
        }
        return level, message, values

    def publish_diagnostics(self) -> None:
        """Publish one DiagnosticArray (timer callback; never raises)."""
        try:
            level, message, values = self.diagnostic_values()
            self._errors_reported = self._callback_errors
            if self._diag_pub is not None:
                self._diag_pub.publish(make_diagnostic_array(
                    f'{self.get_name()}: lf predictor', level, message, values,
                    stamp=self.get_clock().now().to_msg()))
        except Exception as error:  # noqa: BLE001
            self._count_error('diagnostics', error)


def _parse_cli(argv: Sequence[str]) -> None:
    """Handle ``--help`` (exit 0, parameter table) and reject unknown non-ROS arguments."""
    parser = argparse.ArgumentParser(
        prog=NODE_NAME,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description='Learned LF pose predictor (lifecycle node). Subscribes measured_pose '
                    '(PoseStamped) and thrust (WrenchStamped); publishes lf_pose (stamped t + '
                    'sample_time), lf_odom (nav_msgs/Odometry), wave_peak_frequency, '
                    '/diagnostics; services ~/retrain, ~/reset.',
        epilog='ROS arguments: --ros-args -p NAME:=VALUE --params-file config/predictor.yaml '
               '-r __ns:=/vessel\n\nParameters (name, default, description [unit]). A run-time '
               'change of a predictor parameter re-creates the predictor (the trained network is '
               'kept unless ndof, nu, ny, nfb, hidden_units, hidden_layers or sample_time '
               'change); collected data restarts.\n'
               + parameter_table([PredictorParams, PredictorNodeSettings,
                                  ReferenceCheckSettings, OdometryParams]))
    parser.parse_args(list(remove_ros_args(list(argv)))[1:])


def main(args: list[str] | None = None) -> int:
    """Console script ``predictor``; returns the exit code."""
    _parse_cli(sys.argv if args is None else args)
    rclpy.init(args=args)
    return spin_node(PredictorNode, config_errors=(ValueError, TypeError, RuntimeError),
                     logger_name=NODE_NAME)

if __name__ == '__main__':
    sys.exit(main())
