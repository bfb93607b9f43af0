"""`replay`: run the adaptive LF predictor over a recorded bag, offline and deterministically.

    replay INPUT -o OUTPUT.mcap [--params-file FILE] [--pose-topic T] [--thrust-topic T]
           [--command-topic T] [--lf-topic T] [--odom-topic T] [--truth-topic T] [--seed N]
           [--metrics FILE.json] [--load-model CKPT] [--save-model CKPT] [--no-progress] [--force]

INPUT is an `.mcap` file or a rosbag2 directory (`BagReader`). Messages are taken in log-time
order; thrust (WrenchStamped, default `/thrust`) goes to `InputAligner.add_force` and pose
(PoseStamped, default `/measured_pose`) to `InputAligner.add_pose`, both at their header stamps
(the log time when a stamp is zero, i.e. unset). Every aligned sample goes to
`LfStateEstimator(params, odometry, background=False)` (the `AdaptivePredictor` + vessel memory +
LF odometry, as in the node): trainings and vessel-memory fits run inline, so a replay with the
same seed and parameters gives the same output bit for bit. Dead reckoning follows the node
(`nodes.lf_odom.OdomDriver`): a thrust stamped more than `dead_reckoning_after` after the last
sample that reached the predictor is dead-reckoned (at most once per sample time) and written
like any estimate, until `dead_reckoning_timeout`. A sample flagged
`segment_start` (other than the first) calls `restart_segment()`, as the node does. The
position-reference checks of the node (`core.reference_checks`) run on every pose before the
aligner and on every aligned sample against the previous prediction, as in the node: a rejected
pose is not replayed into the predictor, and a fault found after the fact restarts the data
segment. Dropouts are judged on the pose stamps (a stamp gap longer than `dropout_timeout`).
The DP controller's commands (WrenchStamped, default `/thrust_command`, optional) go to
`OdomDriver.command`, as in the node: the dead reckoner's inertia from the controller's gains
(`controller_inertia`). The read assumes the controller acted on the replayed estimates. The
commands of a loop closed on another estimator explain less of the regression, but not always
too little: on a 2 h log of the supply vessel's loop on the observer the read believed them
from about 30 min on, at 5-34x the true inertia, and in the benchmark's stand-in for such
logs a dead reckoning on such a read drifted 30-130 m in 120 s where holding the last pose
drifts under 1 m (docs/BENCHMARKS.md, sixty-fifth session).
A replay that fed commands ends with a warning saying so and what was read; `--command-topic
''` leaves them out.

OUTPUT gets every input message (same bytes, log and publish times; same channel types, schema
text, QoS metadata and type hash) plus, with the log time of the pose message that produced them:
- the estimate on `--lf-topic` (PoseStamped, header.stamp = sample time + sample_time) and on
  `--odom-topic` (nav_msgs/Odometry, default `/lf_odom`, same stamp and pose, twist in
  `base_link_fsd`), with the log time of the message that produced it (pose, or thrust while
  dead reckoning); the metrics score the predictor's own LF pose of every sample;
- `/wave_peak_frequency` (Float64) with every estimate once ω0 is known;
- `/diagnostics` (DiagnosticArray) every `diagnostics_period` (1 s) of bag time, with the keys of
  the predictor node (`predictor_diagnostics`).
An input topic with the name of an output estimate topic (a bag recorded with a live predictor)
is not copied (a warning says so); input `/diagnostics` are copied and ours added.

`--params-file` is a ROS 2 parameters YAML as used by the predictor node (`/**:` and/or
`predictor:` → `ros__parameters:`): PredictorParams fields, aligner settings (`max_gap`,
`thrust_timeout`, `backward_jump`, `max_speed`, `max_abs_position`, `average_poses`), the
position-reference check settings (`ReferenceCheckSettings`), the odometry settings
(`OdometryParams`), `frame_id`, `dead_reckoning_after` and `diagnostics_period` are used; the
node-only keys `model_path`, `autostart` and `use_sim_time` are ignored (use `--load-model`);
any other key is refused. `--seed` overrides `seed`.

When the truth topic (default `/truth/lf_pose`) is present, a metrics table compares, after
warm-up (from the first sample whose estimate came from a trained network; from the start if none
did), the predictor, the raw measurement and the causal notch + low-pass cascade tuned to the
final ω0 estimate, each against the truth linearly interpolated to the estimate's stamp
(`core.evaluation.score`). `--metrics` writes them with the run information as JSON. A bag
whose rosbag2 custom data say its DP loop ran on the true LF pose (`sim_bag --loop-estimator
truth`, `bag.provenance`) gets a warning and `LEAKS` in the metrics heading: its thrust encodes
the truth, so the metrics flatter every estimator that uses thrust.

Exit codes: 0 success; 1 data problem (missing topic, corrupt or foreign file, wrong message
type, no pose in the bag, incompatible checkpoint, nothing to save); 2 usage (bad arguments,
bad parameters file, output exists without `--force`). An incomplete input (writer killed, no
summary) is replayed as far as it can be read; the run is flagged `partial` (warning on stderr,
`partial: true` in the metrics JSON and in every diagnostics message).
"""
# rclpy's message constructors are untyped.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

import argparse
from array import array
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field, fields
import json
import math
import os
from pathlib import Path
import sys
import time
from typing import Any, TextIO

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
from numpy.typing import NDArray
import yaml

from lf_predictor_ros.bag.mcap_reader import BagError, BagReader
from lf_predictor_ros.bag.mcap_writer import BagWriter
from lf_predictor_ros.bag.provenance import leak_warning
from lf_predictor_ros.bag.ros_codec import (
    StampedFields,
    diagnostic_array_cdr,
    estimate_cdr,
    float64_cdr,
    offered_qos_yaml,
    serialize,
    stamped_fields,
)
from lf_predictor_ros.core.alignment import AlignedSample, AlignerSettings, InputAligner
from lf_predictor_ros.core.baselines.cascade import CascadeFilter
from lf_predictor_ros.core.estimator import EstimatorStatus
from lf_predictor_ros.core.evaluation import DEFAULT_WAVE_BAND, Metrics, format_table, score
from lf_predictor_ros.core.heading import wrap_angle
from lf_predictor_ros.core.lf_state import ControllerRead, LfStateEstimator
from lf_predictor_ros.core.math_threads import use_one_math_thread
from lf_predictor_ros.core.odometry import OdometryEstimate
from lf_predictor_ros.core.odometry_params import OdometryParams
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.predictor import AdaptivePredictor
from lf_predictor_ros.core.reference_checks import ReferenceChecker, ReferenceCheckSettings
from lf_predictor_ros.nodes.conversions import (
    FRAME_BODY,
    FRAME_EARTH,
    NS_PER_S,
    force_from_fields,
    pose_from_fields,
    sec_nanosec_to_ns,
    sec_to_stamp,
)
from lf_predictor_ros.nodes.diagnostics import (
    DiagnosticValue,
    input_values,
    make_diagnostic_array,
    predictor_values,
    status_fields,
    with_reference_and_odometry,
)
from lf_predictor_ros.nodes.lf_odom import OdomDriver, dead_reckoning_silence
from lf_predictor_ros.nodes.qos import publisher_qos

FloatArray = NDArray[np.float64]

EXIT_OK = 0
EXIT_DATA = 1  # the bag, a checkpoint or the data in it is the problem
EXIT_USAGE = 2  # the command line or the parameters file is the problem

POSE_TYPE = 'geometry_msgs/msg/PoseStamped'
WRENCH_TYPE = 'geometry_msgs/msg/WrenchStamped'
ODOMETRY_TYPE = 'nav_msgs/msg/Odometry'
FLOAT_TYPE = 'std_msgs/msg/Float64'
DIAGNOSTICS_TYPE = 'diagnostic_msgs/msg/DiagnosticArray'
WAVE_TOPIC = '/wave_peak_frequency'
DIAGNOSTICS_TOPIC = '/diagnostics'
DIAGNOSTICS_NAME = 'replay: lf predictor'
DEFAULT_DIAGNOSTICS_PERIOD = 1.0  # [s of bag time]
PROGRESS_PERIOD = 0.2  # [s wall] between two progress-bar redraws
PROGRESS_WIDTH = 30  # [characters] of the bar itself

ALIGNER_KEYS = tuple(f.name for f in fields(AlignerSettings) if f.name != 'sample_time')
NODE_KEYS_USED = ('frame_id', 'diagnostics_period', 'dead_reckoning_after')
ODOMETRY_KEYS = tuple(f.name for f in fields(OdometryParams))
NODE_KEYS_IGNORED = ('model_path', 'autostart', 'use_sim_time')
_LEVEL_OF_STATE = {'warming_up': 'OK', 'trained': 'OK', 'ok': 'OK', 'fallback': 'WARN',
                   'error': 'ERROR'}


class UsageError(Exception):
    """The command line or the parameters file is wrong (exit code 2)."""


# ---------------------------------------------------------------------------------- options
@dataclass(frozen=True)
class ReplayOptions:
    """Command-line options of `replay`."""

    input: str
    output: str
    params_file: str | None = None
    pose_topic: str = '/measured_pose'
    thrust_topic: str = '/thrust'
    command_topic: str = '/thrust_command'
    lf_topic: str = '/lf_pose'
    odom_topic: str = '/lf_odom'
    truth_topic: str = '/truth/lf_pose'
    seed: int | None = None
    metrics: str | None = None
    load_model: str | None = None
    save_model: str | None = None
    progress: bool = True
    force: bool = False


def build_parser() -> argparse.ArgumentParser:
    """The argparse parser of `replay` (usage errors exit 2)."""
    parser = argparse.ArgumentParser(
        prog='replay',
        description='Run the adaptive LF predictor over a recorded bag (offline, deterministic '
                    'for a seed) and write a new bag with the estimates, and metrics.')
    parser.add_argument('input', help='.mcap file or rosbag2 directory')
    parser.add_argument('-o', '--output', required=True, help='output .mcap file')
    parser.add_argument('--params-file', metavar='FILE',
                        help='ROS 2 parameters YAML of the predictor node')
    parser.add_argument('--pose-topic', default='/measured_pose', metavar='T',
                        help='measured pose topic (default /measured_pose)')
    parser.add_argument('--thrust-topic', default='/thrust', metavar='T',
                        help='applied thrust topic (default /thrust)')
    parser.add_argument('--command-topic', default='/thrust_command', metavar='T',
                        help='DP controller command topic, optional (default /thrust_command): '
                             "its gains give the dead reckoner's inertia (controller_inertia)")
    parser.add_argument('--lf-topic', default='/lf_pose', metavar='T',
                        help='output LF estimate topic (default /lf_pose)')
    parser.add_argument('--odom-topic', default='/lf_odom', metavar='T',
                        help='output LF odometry topic, nav_msgs/Odometry (default /lf_odom)')
    parser.add_argument('--truth-topic', default='/truth/lf_pose', metavar='T',
                        help='true LF pose topic for metrics (default /truth/lf_pose)')
    parser.add_argument('--seed', type=int, metavar='N',
                        help='network initialization seed (overrides the params file)')
    parser.add_argument('--metrics', metavar='FILE.json', help='write metrics and run info')
    parser.add_argument('--load-model', metavar='CKPT',
                        help='warm start from a checkpoint (motion_gate: the twin from CKPT.twin '
                             'when it is there)')
    parser.add_argument('--save-model', metavar='CKPT',
                        help='save the network in service at the end (motion_gate: the twin '
                             'to CKPT.twin)')
    parser.add_argument('--no-progress', action='store_true',
                        help='no progress bar (it is shown only on a terminal anyway)')
    parser.add_argument('--force', action='store_true', help='overwrite OUTPUT if it exists')
    return parser


def parse_args(argv: Sequence[str] | None) -> ReplayOptions:
    """Parse the arguments (without the program name); argparse exits 2 on usage errors."""
    ns = build_parser().parse_args(list(argv) if argv is not None else sys.argv[1:])
    return ReplayOptions(input=ns.input, output=ns.output, params_file=ns.params_file,
                         pose_topic=ns.pose_topic, thrust_topic=ns.thrust_topic,
                         command_topic=ns.command_topic, lf_topic=ns.lf_topic,
                         odom_topic=ns.odom_topic,
                         truth_topic=ns.truth_topic, seed=ns.seed,
                         metrics=ns.metrics, load_model=ns.load_model,
                         save_model=ns.save_model, progress=not ns.no_progress,
                         force=ns.force)


# ---------------------------------------------------------------------------- params file
@dataclass(frozen=True)
class ReplayConfig:
    """Everything taken from the parameters file (and --seed)."""

    params: PredictorParams
    aligner: AlignerSettings
    checks: ReferenceCheckSettings = field(default_factory=ReferenceCheckSettings)
    frame_id: str = FRAME_EARTH
    diagnostics_period: float = DEFAULT_DIAGNOSTICS_PERIOD  # [s of bag time]
    odometry: OdometryParams = field(default_factory=OdometryParams)
    dead_reckoning_after: float = 0.0  # [s] 0 = 2 × sample_time


def _node_sections(document: Any, path: str) -> list[Mapping[str, Any]]:
    """The `ros__parameters` mappings for the predictor node, `/**` first."""
    if not isinstance(document, Mapping):
        raise UsageError(f'parameters file {path!r} is not a ROS 2 parameters YAML (a mapping '
                         'of node names to ros__parameters); see config/predictor.yaml')
    wildcard, specific = [], []
    for name, section in document.items():
        key = str(name)
        if key in ('/**', '**'):
            wildcard.append(section)
        elif key.rstrip('/').split('/')[-1] == 'predictor':
            specific.append(section)
    found = []
    for section in wildcard + specific:
        if not isinstance(section, Mapping) or not isinstance(
                section.get('ros__parameters'), Mapping):
            raise UsageError(f'parameters file {path!r}: a node section has no '
                             '`ros__parameters:` mapping; write `/**:` then '
                             '`  ros__parameters:` then the parameters')
        found.append(section['ros__parameters'])
    if not found:
        raise UsageError(f'parameters file {path!r} has no `/**:` or `predictor:` section (it '
                         f'has {[str(k) for k in document]}); put the parameters under '
                         '`/**: ros__parameters:`')
    return found


def _flatten(values: Mapping[str, Any], prefix: str = '') -> dict[str, Any]:
    """Nested parameter mappings to ROS dotted names."""
    flat: dict[str, Any] = {}
    for key, value in values.items():
        name = f'{prefix}{key}'
        if isinstance(value, Mapping):
            flat.update(_flatten(value, f'{name}.'))
        else:
            flat[name] = value
    return flat


def load_config(params_file: str | None, seed: int | None = None) -> ReplayConfig:
    """PredictorParams, aligner settings and node settings from a ROS 2 params file.

    Raises UsageError naming the file and the broken rule (unreadable file, unknown key,
    invalid value).
    """
    values: dict[str, Any] = {}
    if params_file is not None:
        try:
            document = yaml.safe_load(Path(params_file).read_text(encoding='utf-8'))
        except OSError as err:
            raise UsageError(f'cannot read parameters file {params_file!r}: '
                             f'{err.strerror or err}') from None
        except yaml.YAMLError as err:
            raise UsageError(f'parameters file {params_file!r} is not valid YAML: '
                             f'{" ".join(str(err).split())}') from None
        for section in _node_sections(document, params_file):
            values.update(_flatten(section))
    for key in NODE_KEYS_IGNORED:
        values.pop(key, None)
    check_keys = ReferenceCheckSettings.field_names()
    known = set(PredictorParams.field_names()) | set(ALIGNER_KEYS) | set(NODE_KEYS_USED) | \
        set(check_keys) | set(ODOMETRY_KEYS)
    unknown = sorted(set(values) - known)
    if unknown:
        raise UsageError(f'parameters file {params_file!r}: unknown key(s) {unknown}; valid '
                         f'keys are the PredictorParams fields, the aligner settings '
                         f'{list(ALIGNER_KEYS)}, the reference checks {list(check_keys)}, the '
                         f'odometry settings {list(ODOMETRY_KEYS)} and {list(NODE_KEYS_USED)}')
    if seed is not None:
        values['seed'] = seed
    predictor_values = {k: v for k, v in values.items() if k in PredictorParams.field_names()}
    aligner_values = {k: v for k, v in values.items() if k in ALIGNER_KEYS}
    try:
        params = PredictorParams.from_dict(predictor_values)
        aligner = AlignerSettings(sample_time=params.sample_time, **aligner_values)
        check_values: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v
                                        for k, v in values.items() if k in check_keys}
        checks = ReferenceCheckSettings(**check_values)
        frame_id = str(values.get('frame_id', FRAME_EARTH))
        period = float(values.get('diagnostics_period', DEFAULT_DIAGNOSTICS_PERIOD))
        odometry_values: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v
                                           for k, v in values.items() if k in ODOMETRY_KEYS}
        odometry = OdometryParams(**odometry_values)
        dead_reckoning_after = float(values.get('dead_reckoning_after', 0.0))
        dead_reckoning_silence(dead_reckoning_after, params.sample_time)
    except (TypeError, ValueError) as err:
        raise UsageError(f'parameters file {params_file!r}: {err}') from None
    if not (period > 0.0 and math.isfinite(period)):
        raise UsageError(f'parameters file {params_file!r}: diagnostics_period must be > 0 s, '
                         f'got {period}')
    return ReplayConfig(params, aligner, checks, frame_id, period, odometry,
                        dead_reckoning_after)


# --------------------------------------------------------------------------- diagnostics
def predictor_diagnostics(status: EstimatorStatus, counters: Mapping[str, int],
                          aligner_counters: Mapping[str, int], stamp: Time, *,
                          samples: int, name: str = DIAGNOSTICS_NAME,
                          extra: Mapping[str, DiagnosticValue] | None = None,
                          reference: tuple[str, str] = ('OK', ''),
                          odometry: tuple[str, str] = ('OK', '')) -> DiagnosticArray:
    """/diagnostics of the predictor with the predictor node's level, message and keys.

    Level by state: warming_up / trained → OK, fallback → WARN, error → ERROR; message
    '<state>: <status message>'. Keys as `nodes.predictor_node` publishes them: state,
    wave_peak_freq, last_loss, train_seconds, model_age, buffer_fill (nan when unknown),
    trainings, rejected_trainings, overruns, training_errors, guard_trips, segments, samples,
    dropped (= invalid + out_of_order + outliers), invalid, out_of_order, outliers, gaps, resets,
    stale_thrust; then `extra`. ``reference`` (level, reason) of the position-reference checks
    and ``odometry`` (level, message) of the LF odometry raise the level as in the node
    (`nodes.diagnostics.with_reference_and_odometry`).
    """
    level, message, values = predictor_diagnostics_fields(
        status, counters, aligner_counters, samples=samples, extra=extra, reference=reference,
        odometry=odometry)
    return make_diagnostic_array(name, level, message, values, stamp=stamp)


def predictor_diagnostics_fields(
        status: EstimatorStatus, counters: Mapping[str, int],
        aligner_counters: Mapping[str, int], *, samples: int,
        extra: Mapping[str, DiagnosticValue] | None = None,
        reference: tuple[str, str] = ('OK', ''), odometry: tuple[str, str] = ('OK', ''),
) -> tuple[str, str, dict[str, DiagnosticValue]]:
    """(level, message, values) of `predictor_diagnostics`."""
    values: dict[str, DiagnosticValue] = {
        **predictor_values(status, counters),
        **input_values(aligner_counters, samples),
    }
    values.update(extra or {})
    level = _LEVEL_OF_STATE.get(status.state, 'WARN')
    message = f'{status.state}: {status.message}'
    level, message = with_reference_and_odometry(level, message, reference, odometry)
    return level, message, values


# ------------------------------------------------------------------------------ progress
class Progress:
    """A one-line text progress bar on a terminal stream; silent when disabled."""

    def __init__(self, stream: TextIO, start_ns: int, end_ns: int, enabled: bool) -> None:
        self._stream = stream
        self._start_ns = start_ns
        self._span_ns = max(1, end_ns - start_ns)
        self._enabled = enabled
        self._last_draw = -math.inf
        self._drawn = False

    def update(self, log_time_ns: int, messages: int, force: bool = False) -> None:
        """Redraw at most every PROGRESS_PERIOD wall seconds."""
        if not self._enabled:
            return
        now = time.monotonic()
        if not force and now - self._last_draw < PROGRESS_PERIOD:
            return
        self._last_draw = now
        fraction = min(1.0, max(0.0, (log_time_ns - self._start_ns) / self._span_ns))
        filled = int(round(fraction * PROGRESS_WIDTH))
        bar = '#' * filled + '-' * (PROGRESS_WIDTH - filled)
        self._stream.write(f'\rreplay [{bar}] {100.0 * fraction:5.1f} % {messages} msgs')
        self._stream.flush()
        self._drawn = True

    def finish(self) -> None:
        """End the bar's line."""
        if self._drawn:
            self._stream.write('\n')
            self._stream.flush()


# -------------------------------------------------------------------------------- replay
REPLAY_CHUNK_SECONDS = 3600.0  # [s of log time] chunks close by size (256 KiB) well before this


class PoseRows:
    """Growable (n, 3) float64 table in one flat buffer (8 bytes a value).

    An 8-hour replay keeps every sample's pose, force, estimate and truth for the metrics; as
    separate numpy objects in lists that grew the process by ~1 MB/s of replay (≈ 11 % over 8 h),
    in one buffer it is 24 bytes a row.
    """

    def __init__(self) -> None:
        self._flat = array('d')

    def append(self, row: FloatArray) -> None:
        """Add one 3-vector."""
        self._flat.extend((float(row[0]), float(row[1]), float(row[2])))

    def __len__(self) -> int:
        return len(self._flat) // 3

    def __getitem__(self, k: int) -> FloatArray:
        k = k + len(self) if k < 0 else k
        if not 0 <= k < len(self):
            raise IndexError(k)
        return np.array(self._flat[3 * k:3 * k + 3])

    def __iter__(self) -> Iterator[FloatArray]:
        table = self.__array__()
        return iter(table)

    def __array__(self, dtype: Any = None, copy: Any = None) -> FloatArray:
        table = np.frombuffer(self._flat, dtype=np.float64).reshape(-1, 3).copy()
        return table if dtype is None else table.astype(dtype)


@dataclass
class SampleLog:
    """What the replay produced per aligned sample, for the metrics (compact storage)."""

    t: array[float] = field(default_factory=lambda: array('d'))  # [s] grid time of the sample
    pose: PoseRows = field(default_factory=PoseRows)  # aligned measured pose at t
    force: PoseRows = field(default_factory=PoseRows)
    estimate: PoseRows = field(default_factory=PoseRows)  # predicted for t + h
    segment_start: list[bool] = field(default_factory=list)
    network: list[bool] = field(default_factory=list)  # estimate came from the network


@dataclass
class ReplayResult:
    """Outcome of one replay."""

    messages_in: int = 0
    messages_out: int = 0
    estimates: int = 0
    wall_time: float = 0.0  # [s]
    bag_duration: float = 0.0  # [s] log-time span of the input
    partial: bool = False
    problem: str | None = None
    warnings: list[str] = field(default_factory=list)
    counters: dict[str, int] = field(default_factory=dict)
    aligner_counters: dict[str, int] = field(default_factory=dict)
    final_wave_peak_freq: float | None = None
    final_state: str = ''
    samples: SampleLog = field(default_factory=SampleLog)
    truth_t: array[float] = field(default_factory=lambda: array('d'))
    truth_pose: PoseRows = field(default_factory=PoseRows)
    metrics: dict[str, Metrics] | None = None
    evaluation_start: float | None = None  # [s]
    recording: dict[str, str] = field(default_factory=dict)  # the input's rosbag2 custom data
    leaks_truth: bool = False  # the input says its DP loop ran on the true LF pose
    commands: int = 0  # messages on the command topic handed to the controller read

    @property
    def realtime_factor(self) -> float:
        """Bag seconds replayed per wall second."""
        return self.bag_duration / self.wall_time if self.wall_time > 0.0 else math.inf


def command_warning(topic: str, read: ControllerRead | None) -> str:
    """The caveat of a replay that fed a bag's DP controller commands to the controller read.

    The read assumes the controller acted on this predictor's estimates. A log of a DP loop
    closed on another estimator is a foreign controller's, which the read can believe after
    some 30 minutes with an inertia several times off, and a dead reckoning on it then drifts
    tens of metres in 120 s (docs/BENCHMARKS.md, sixty-fifth session).
    """
    outcome = 'no read in force at the end' if read is None else \
        f'the read in force at the end: {read.note}'
    return (f'{topic!r} was fed to the controller read ({outcome}). The read assumes the DP '
            "controller acted on this replay's estimates; if the recorded loop ran on another "
            'estimator, the read can believe a wrong inertia and the dead reckoning drift far: '
            "replay again with --command-topic '' to leave the commands out")


def _stamp_seconds(fields: StampedFields, log_time_ns: int) -> float:
    """Header stamp [s]; the log time when the stamp is unset (zero)."""
    ns = sec_nanosec_to_ns(fields.sec, fields.nanosec)
    return (ns if ns > 0 else log_time_ns) / NS_PER_S


def _pose_of(fields: StampedFields) -> FloatArray:
    """``msg_to_pose`` of the message (ValueError for a non-finite pose or a zero quaternion)."""
    x, y, _, qx, qy, qz, qw = fields.values
    return pose_from_fields(x, y, qw, qx, qy, qz)


def _force_of(fields: StampedFields) -> FloatArray:
    """``msg_to_force`` of the message (ValueError for a non-finite force)."""
    surge, sway, _, _, _, yaw_moment = fields.values
    return force_from_fields(surge, sway, yaw_moment)


def _check_input_topics(reader: BagReader, options: ReplayOptions) -> dict[str, str]:
    topics = reader.topics()
    for topic, expected in ((options.pose_topic, POSE_TYPE), (options.thrust_topic, WRENCH_TYPE)):
        if topic not in topics:
            raise BagError(f'topic {topic!r} is not in bag {str(reader.path)!r}; it has '
                           f'{sorted(topics)} (choose with --pose-topic / --thrust-topic)')
        if topics[topic] != expected:
            raise BagError(f'topic {topic!r} in bag {str(reader.path)!r} has type '
                           f'{topics[topic]}, expected {expected}')
    truth = options.truth_topic
    if truth in topics and topics[truth] != POSE_TYPE:
        raise BagError(f'truth topic {truth!r} has type {topics[truth]}, expected {POSE_TYPE}')
    command = options.command_topic
    if command in topics and topics[command] != WRENCH_TYPE:
        raise BagError(f'command topic {command!r} has type {topics[command]}, expected '
                       f'{WRENCH_TYPE} (choose with --command-topic)')
    return topics


class _Replayer:
    """Streams one bag through aligner and predictor into the writer."""

    def __init__(self, options: ReplayOptions, config: ReplayConfig, reader: BagReader,
                 writer: BagWriter, result: ReplayResult) -> None:
        self.options = options
        self.config = config
        self.reader = reader
        self.writer = writer
        self.result = result
        self.h = config.params.sample_time
        self.aligner = InputAligner(config.aligner)
        self.predictor = AdaptivePredictor(config.params, background=False)
        self.odom = OdomDriver(
            LfStateEstimator(config.params, config.odometry, background=False,
                             predictor=self.predictor),
            dead_reckoning_silence(config.dead_reckoning_after, config.params.sample_time),
            config.aligner.backward_jump)
        self.checker = ReferenceChecker(config.checks, config.params.ndof)
        self.predicted: tuple[float, FloatArray] | None = None  # (valid at, estimate)
        self.next_diagnostics: float | None = None
        self.first_sample = True
        self.channels: dict[int, int] = {}
        qos = offered_qos_yaml([publisher_qos()])
        self.lf_channel = writer.add_topic(options.lf_topic, POSE_TYPE, qos)
        self.odom_channel = writer.add_topic(options.odom_topic, ODOMETRY_TYPE, qos)
        self.wave_channel = writer.add_topic(WAVE_TOPIC, FLOAT_TYPE, qos)
        self.replaced = {options.lf_topic, options.odom_topic, WAVE_TOPIC}
        self._copy_channels(qos)

    def _copy_channels(self, qos: str) -> None:
        diagnostics_channel = None
        for info in self.reader.topic_infos().values():
            if info.topic in self.replaced:
                self.result.warnings.append(
                    f'input topic {info.topic!r} is replaced by the replay output, not copied')
                continue
            if info.topic == DIAGNOSTICS_TOPIC and info.type_name != DIAGNOSTICS_TYPE:
                raise BagError(f'input topic {DIAGNOSTICS_TOPIC!r} has type {info.type_name}, '
                               f'expected {DIAGNOSTICS_TYPE}')
            channel = self.writer.add_topic(info.topic, info.type_name,
                                            info.offered_qos_profiles or None,
                                            type_hash=info.type_hash,
                                            definition=info.definition or None)
            if info.topic == DIAGNOSTICS_TOPIC:
                diagnostics_channel = channel
        self._diagnostics_channel = diagnostics_channel if diagnostics_channel is not None \
            else self.writer.add_topic(DIAGNOSTICS_TOPIC, DIAGNOSTICS_TYPE, qos)

    def load(self, path: str) -> None:
        """Warm start (ValueError for an incompatible or corrupt checkpoint)."""
        self.predictor.load(path)

    def run(self, progress: Progress) -> None:
        """Copy every message, feed pose and thrust, write the estimates."""
        out_channels: dict[str, int] = {}
        for channel, message in self.reader.records():
            topic = channel.topic
            self.result.messages_in += 1
            if topic not in self.replaced:
                out = out_channels.get(topic)
                if out is None:
                    out = out_channels[topic] = self.writer.add_topic(
                        topic, self.reader.topics()[topic])
                self._write(out, message.log_time, message.data, message.publish_time)
            if topic == self.options.thrust_topic:
                self._thrust(message.data, message.log_time)
            elif topic == self.options.pose_topic:
                self._pose(message.data, message.log_time)
            elif topic == self.options.truth_topic:
                self._truth(message.data, message.log_time)
            elif topic == self.options.command_topic:
                self._command(message.data, message.log_time)
            progress.update(message.log_time, self.result.messages_in)
        progress.update(self.reader.end_time_ns, self.result.messages_in, force=True)

    def _write(self, channel: int, log_time_ns: int, data: bytes,
               publish_time_ns: int | None = None) -> None:
        self.writer.write(channel, log_time_ns, data, publish_time_ns)
        self.result.messages_out += 1

    def _decode(self, data: bytes, type_name: str, topic: str) -> StampedFields:
        try:
            return stamped_fields(data, type_name)
        except Exception as err:  # rclpy raises plain exceptions on malformed CDR
            raise BagError(f'a message on {topic!r} does not decode as {type_name} ({err}); '
                           'the bag is corrupt') from None

    def _thrust(self, data: bytes, log_time_ns: int) -> None:
        message = self._decode(data, WRENCH_TYPE, self.options.thrust_topic)
        try:
            force: object = _force_of(message)
        except ValueError:
            force = np.full(3, np.nan)  # the aligner drops and counts it
        t = _stamp_seconds(message, log_time_ns)
        if self.aligner.add_force(t, force) and isinstance(force, np.ndarray):
            estimate = self.odom.thrust(t, force)
            if estimate is not None:
                self._write_estimate(estimate, log_time_ns)
            if self.odom.state.odometry.mode != 'tracking':
                self._maybe_diagnostics(t, log_time_ns)

    def _command(self, data: bytes, log_time_ns: int) -> None:
        message = self._decode(data, WRENCH_TYPE, self.options.command_topic)
        try:
            force = _force_of(message)
        except ValueError:
            force = np.full(3, np.nan)  # counted by the driver (commands_invalid)
        self.odom.command(_stamp_seconds(message, log_time_ns), force)
        self.result.commands += 1

    def _truth(self, data: bytes, log_time_ns: int) -> None:
        message = self._decode(data, POSE_TYPE, self.options.truth_topic)
        try:
            pose = _pose_of(message)
        except ValueError:
            return
        self.result.truth_t.append(_stamp_seconds(message, log_time_ns))
        self.result.truth_pose.append(pose)

    def _pose(self, data: bytes, log_time_ns: int) -> None:
        message = self._decode(data, POSE_TYPE, self.options.pose_topic)
        try:
            pose: object = _pose_of(message)
        except ValueError:
            pose = np.full(3, np.nan)  # the aligner drops and counts it
        t = _stamp_seconds(message, log_time_ns)
        if isinstance(pose, np.ndarray) and np.all(np.isfinite(pose)):
            verdict = self.checker.check_pose(t, pose, self.predictor.wave_peak_freq)
            if verdict.restart:
                self._restart_data()
            elif verdict.gap:
                self.aligner.reset()  # a dropout is never bridged (as the node)
            if not verdict.accepted:
                return
        for sample in self.aligner.add_pose(t, pose):
            self._sample(sample, log_time_ns)

    def _restart_data(self) -> None:
        """A reference fault found after the fact: the next sample starts a new segment."""
        self.aligner.reset()
        self.predicted = None

    def _sample(self, sample: AlignedSample, log_time_ns: int) -> None:
        if sample.segment_start and not self.first_sample:
            self.odom.state.restart_segment()  # the odometry keeps its state across it
            self.predicted = None
        self.first_sample = False
        expected = self.predicted[1] if self.predicted is not None and \
            abs(self.predicted[0] - sample.t) < 1e-6 else None
        verdict = self.checker.check_sample(sample.t, sample.pose, expected)
        if not verdict.accepted:
            if verdict.restart:
                self._restart_data()
            return
        lf_pose, odometry = self.odom.update(sample.t, sample.pose, sample.force,
                                             sample.segment_start)
        if lf_pose is None:  # older than an estimate already dead-reckoned: not written
            self.predicted = None
            return
        estimate = lf_pose
        self.predicted = (sample.t + self.h, estimate)
        status = self.predictor.status()
        log = self.result.samples
        log.t.append(sample.t)
        log.pose.append(sample.pose)
        log.force.append(sample.force)
        log.estimate.append(estimate)
        log.segment_start.append(sample.segment_start)
        log.network.append(status.state == 'trained')
        self.result.estimates += 1
        if odometry is not None:  # None: lost, the fix held back
            self._write_estimate(odometry, log_time_ns)
        freq = self.predictor.wave_peak_freq
        if freq is not None:
            self._write(self.wave_channel, log_time_ns, float64_cdr(float(freq)))
        self._maybe_diagnostics(sample.t, log_time_ns)

    def _maybe_diagnostics(self, t: float, log_time_ns: int) -> None:
        """Diagnostics every diagnostics_period of bag time (samples; thrust when not tracking)."""
        if self.next_diagnostics is None or t >= self.next_diagnostics - 1e-9:
            self._diagnostics(t, log_time_ns, self.predictor.status())
            period = self.config.diagnostics_period
            base = t if self.next_diagnostics is None else self.next_diagnostics
            steps = max(1, math.floor((t - base) / period + 1e-9) + 1)
            self.next_diagnostics = base + steps * period

    def _write_estimate(self, estimate: OdometryEstimate, log_time_ns: int) -> None:
        """One estimate on the lf and odom topics (same stamp and pose)."""
        lf_data, odom_data = estimate_cdr(
            sec_to_stamp(estimate.stamp), self.config.frame_id, FRAME_BODY, estimate.pose,
            estimate.pose_cov, estimate.twist, estimate.twist_cov)
        self._write(self.lf_channel, log_time_ns, lf_data)
        self._write(self.odom_channel, log_time_ns, odom_data)

    def _diagnostics(self, t: float, log_time_ns: int, status: EstimatorStatus) -> None:
        extra: dict[str, DiagnosticValue] = {
            'warm_start': bool(self.options.load_model),
            'model_file': self.options.load_model or '',
            'partial': self.result.partial,
        }
        extra.update(self.checker.values())
        extra['ndof'] = self.config.params.ndof
        extra['unfiltered_dofs'] = 'east yaw' if self.config.params.ndof == 1 else 'none'
        extra.update(self.odom.values())
        stamp = sec_to_stamp(t)
        level, message, values = predictor_diagnostics_fields(
            status, self.predictor.counters, self.aligner.counters.as_dict(),
            samples=self.result.estimates, extra=extra, reference=self.checker.status(),
            odometry=self.odom.status())
        fields = status_fields(DIAGNOSTICS_NAME, level, message, values)
        data = diagnostic_array_cdr(stamp.sec, stamp.nanosec, '', [fields])
        if data is None:  # a NUL in a string: rclpy's encoder
            data = serialize(make_diagnostic_array(DIAGNOSTICS_NAME, level, message, values,
                                                   stamp=stamp))
        self._write(self._diagnostics_channel, log_time_ns, data)


def replay(options: ReplayOptions, config: ReplayConfig,
           progress_stream: TextIO | None = None) -> ReplayResult:
    """Run the replay; raises BagError (data), UsageError (arguments) or ValueError (model)."""
    output = Path(options.output)
    if output.exists() and not options.force:
        raise UsageError(f'output {options.output!r} exists already; choose another path or '
                         'pass --force to overwrite it')
    if output.exists() and output.resolve() == _input_file(options.input).resolve():
        raise UsageError('output must not be the input bag; choose another path')
    result = ReplayResult()
    wall_start = time.monotonic()
    with BagReader(options.input, allow_incomplete=True) as reader:
        _check_input_topics(reader, options)
        result.recording = reader.custom_data()
        leak = leak_warning(result.recording)
        if leak is not None:
            result.leaks_truth = True
            result.warnings.append(leak)
        if not reader.complete:
            result.partial = True
            result.problem = reader.problem
            result.warnings.append(f'input bag is incomplete ({reader.problem}); replaying the '
                                   'readable part, results are flagged partial')
        result.bag_duration = max(0.0, (reader.end_time_ns - reader.start_time_ns) / NS_PER_S)
        stream = progress_stream if progress_stream is not None else sys.stderr
        progress = Progress(stream, reader.start_time_ns, reader.end_time_ns,
                            options.progress and stream.isatty())
        try:
            # Offline: no crash-safety need for 1 s chunks; size-bound chunks keep the summary's
            # chunk index (held in memory until close) small on multi-hour bags.
            with BagWriter(output, overwrite=options.force,
                           max_chunk_duration=REPLAY_CHUNK_SECONDS) as writer:
                replayer = _Replayer(options, config, reader, writer, result)
                if options.load_model:
                    replayer.load(options.load_model)
                try:
                    replayer.run(progress)
                finally:
                    progress.finish()
                    replayer.odom.state.close()
        except BaseException:
            output.unlink(missing_ok=True)
            raise
    result.wall_time = time.monotonic() - wall_start
    result.counters = dict(replayer.predictor.counters)
    result.aligner_counters = replayer.aligner.counters.as_dict()
    result.final_wave_peak_freq = replayer.predictor.wave_peak_freq
    result.final_state = replayer.predictor.status().state
    if result.commands:
        result.warnings.append(command_warning(options.command_topic,
                                               replayer.odom.state.controller_read))
    if result.estimates == 0:
        output.unlink(missing_ok=True)
        raise BagError(f'bag {options.input!r} ends without any usable pose on '
                       f'{options.pose_topic!r}: nothing to replay')
    if options.save_model:
        try:
            replayer.predictor.save(options.save_model)
        except (OSError, ValueError) as err:
            raise ValueError(f'cannot save the model to {options.save_model!r}: {err}') from None
    if result.truth_t:
        result.metrics, result.evaluation_start = evaluate(result, config)
    return result


def _input_file(path: str) -> Path:
    bag = Path(path)
    if bag.is_dir():
        return bag / '__directory__'
    return bag


# ---------------------------------------------------------------------------- evaluation
def _interpolate_pose(t_query: FloatArray, t: FloatArray, poses: FloatArray) -> FloatArray:
    """Linear interpolation of poses (n, 3) at t_query; heading along the unwrapped path."""
    order = np.argsort(t, kind='stable')
    t_sorted, p_sorted = t[order], poses[order]
    out = np.empty((t_query.size, 3))
    for column in range(3):
        values = np.unwrap(p_sorted[:, column]) if column == 2 else p_sorted[:, column]
        out[:, column] = np.interp(t_query, t_sorted, values)
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def _cascade_estimates(log: SampleLog, params: PredictorParams,
                       wave_peak_freq: float) -> FloatArray:
    """The causal cascade at a fixed ω0 over the aligned samples (reset at segment starts)."""
    cascade = CascadeFilter(params.ndof, params.sample_time, wave_peak_freq,
                            notch_zeta=params.notch_zeta, notch_depth=params.notch_depth,
                            lowpass_offset=params.lowpass_offset)
    out = np.empty((len(log.t), 3))
    for k, (t, pose, force) in enumerate(zip(log.t, log.pose, log.force, strict=True)):
        if log.segment_start[k] and k > 0:
            cascade.reset()
        out[k] = cascade.update(t, pose, force)
    return out


def evaluate(result: ReplayResult,
             config: ReplayConfig) -> tuple[dict[str, Metrics] | None, float | None]:
    """Predictor, raw measurement and cascade vs truth on common stamps after warm-up.

    The predictor's estimate from the sample at t is valid at t + h; the measurement and the
    cascade at t. All three are compared on the grid stamps where each has a value, from the
    first sample whose estimate came from the network (from the start if none did), inside the
    truth's time span. Returns (None, None) when fewer than 3 stamps remain.
    """
    params = config.params
    log = result.samples
    h = params.sample_time
    t = np.asarray(log.t, dtype=np.float64)
    grid = np.rint(t / h).astype(np.int64)
    network_k = [k for k, used in enumerate(log.network) if used]
    start = float(t[network_k[0]]) if network_k else float(t[0])
    freq = result.final_wave_peak_freq
    if freq is None:
        freq = math.sqrt(params.wave_band[0] * params.wave_band[1])
    series = {
        'predictor': dict(zip((grid + 1).tolist(), log.estimate, strict=True)),
        'measurement': dict(zip(grid.tolist(), log.pose, strict=True)),
        'cascade': dict(zip(grid.tolist(), _cascade_estimates(log, params, freq), strict=True)),
    }
    truth_t = np.asarray(result.truth_t, dtype=np.float64)
    truth_pose = np.asarray(result.truth_pose, dtype=np.float64).reshape(-1, 3)
    common = set(series['predictor']) & set(series['measurement'])
    keys = np.array(sorted(k for k in common
                           if k * h >= start - 1e-9 and truth_t.min() <= k * h <= truth_t.max()),
                    dtype=np.int64)
    if keys.size < 3:
        result.warnings.append('fewer than 3 samples overlap the truth after warm-up: '
                               'no metrics')
        return None, start
    stamps = (keys * h).astype(np.float64)
    truth = _interpolate_pose(stamps, truth_t, truth_pose)
    metrics = {name: score(stamps, np.array([values[k] for k in keys.tolist()]), truth,
                           params.ndof, DEFAULT_WAVE_BAND)
               for name, values in series.items()}
    return metrics, start


# ------------------------------------------------------------------------------- report
def summary_lines(result: ReplayResult, options: ReplayOptions) -> list[str]:
    """Human-readable summary (stdout)."""
    counters = result.counters
    lines = [
        f'replay: {result.messages_in} messages in, {result.messages_out} out '
        f'({result.estimates} estimates) -> {options.output}',
        f'replay: {counters.get("trainings", 0)} trainings '
        f'({counters.get("rejected_trainings", 0)} rejected, '
        f'{counters.get("training_errors", 0)} errors), final state {result.final_state}, '
        f'wave peak frequency {_fmt(result.final_wave_peak_freq)} rad/s',
        f'replay: {result.bag_duration:.1f} s of bag in {result.wall_time:.2f} s wall '
        f'({result.realtime_factor:.1f} x real time)' + (' [PARTIAL]' if result.partial else ''),
    ]
    if result.metrics:
        leaks = ' [LEAKS: thrust computed from the truth, see the warning]'
        lines.append(f'metrics vs {options.truth_topic} from t = {result.evaluation_start:.1f} s '
                     f'(after warm-up){leaks if result.leaks_truth else ""}:')
        lines.append(format_table(result.metrics))
    elif result.metrics is None and result.truth_t:
        lines.append('replay: no metrics (too little overlap with the truth)')
    else:
        lines.append(f'replay: no {options.truth_topic} in the bag: no metrics')
    return lines


def _fmt(value: float | None) -> str:
    return 'unknown' if value is None else f'{value:.4g}'


def metrics_document(result: ReplayResult, options: ReplayOptions,
                     config: ReplayConfig) -> dict[str, Any]:
    """The JSON written by --metrics."""
    return {
        'input': str(options.input),
        'output': str(options.output),
        'partial': result.partial,
        'problem': result.problem,
        'seed': config.params.seed,
        'params': config.params.to_dict(),
        'topics': {'pose': options.pose_topic, 'thrust': options.thrust_topic,
                   'command': options.command_topic,
                   'lf': options.lf_topic, 'odom': options.odom_topic,
                   'truth': options.truth_topic},
        'messages_in': result.messages_in,
        'messages_out': result.messages_out,
        'estimates': result.estimates,
        'wall_time': result.wall_time,
        'bag_duration': result.bag_duration,
        'realtime_factor': result.realtime_factor,
        'trainings': result.counters.get('trainings', 0),
        'counters': result.counters,
        'aligner_counters': result.aligner_counters,
        'final_state': result.final_state,
        'final_wave_peak_freq': result.final_wave_peak_freq,
        'evaluation_start': result.evaluation_start,
        'recording': result.recording,
        'metrics_leak_truth': result.leaks_truth,
        'wave_band': list(DEFAULT_WAVE_BAND),
        'metrics': (None if result.metrics is None
                    else {name: m.to_dict() for name, m in result.metrics.items()}),
    }


def _write_json(path: str, document: Mapping[str, Any]) -> None:
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(target.name + '.tmp')
    tmp.write_text(json.dumps(document, indent=2, allow_nan=True) + '\n', encoding='utf-8')
    os.replace(tmp, target)


# --------------------------------------------------------------------------------- main
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `replay` executable; returns the exit code."""
    options = parse_args(argv)
    use_one_math_thread()  # BLAS and torch: deterministic, polite on shared cores, the node's
    try:
        config = load_config(options.params_file, options.seed)
        result = replay(options, config)
    except UsageError as err:
        print(f'replay: error: {err}', file=sys.stderr)
        return EXIT_USAGE
    except (BagError, ValueError, OSError) as err:
        print(f'replay: error: {err}', file=sys.stderr)
        return EXIT_DATA
    except KeyboardInterrupt:
        print('replay: interrupted; output removed', file=sys.stderr)
        return 130
    for warning in result.warnings:
        print(f'replay: warning: {warning}', file=sys.stderr)
    print('\n'.join(summary_lines(result, options)))
    if options.metrics:
        try:
            _write_json(options.metrics, metrics_document(result, options, config))
        except OSError as err:
            print(f'replay: error: cannot write metrics {options.metrics!r}: '
                  f'{err.strerror or err}', file=sys.stderr)
            return EXIT_DATA
    return EXIT_OK


if __name__ == '__main__':
    sys.exit(main())
