"""100 Hz pose through DDS into the real `predictor` process: delivery, memory, CPU (issue 7).

    python -m lf_predictor_ros.benchmark.dds_soak [--minutes 30] [--speed 20] [--rate 100]
        [--canary-every 10] [--probe] [--log-dir DIR]

Starts the `predictor` node as its own process (``python -m lf_predictor_ros.nodes.predictor_node
--ros-args -p ndof:=3``, shipped defaults otherwise; localhost discovery and a private
ROS_DOMAIN_ID, as the demo does). This process publishes simulated supply-vessel pose
(``/measured_pose``) and applied thrust (``/thrust``) at ``--rate`` Hz, ``--speed`` × real time,
stamped in simulated time (``simulate('supply_closed_loop')`` resampled like
``benchmark/latency.py``), with the contract's publisher QoS (reliable, keep_last 10; the node
reads them best effort, keep_last 5, so the connection is best effort). It subscribes to
``/lf_pose`` and ``/diagnostics``.

What is counted:
- poses and thrusts sent, and how far the publisher fell behind its schedule (``max_lag_s``);
- poses the node received, exactly: its ``poses_accepted`` diagnostics key counts the valid
  poses its aligner took, so ``1 − poses_accepted / poses_sent`` is the pose loss
  (``pose_loss_exact``; out-of-order and outliers, none in this clean stream, would count as
  lost). Before that key existed, and still for the split before / after the first training
  (the diagnostics arrive once a second, the canaries give a running count): every
  ``--canary-every``-th pose is followed by a *canary*, an extra pose with the same stamp and a
  NaN position. The node drops and counts it as ``invalid`` without touching its data, so
  ``invalid`` on ``/diagnostics`` = canaries the node's callback saw; the fraction missing
  estimates the node's pose loss (0 disables canaries);
- ``/lf_pose`` outputs against the grid samples the inputs span (one per sample time), gaps in
  their stamps, and whether all are finite;
- with ``--probe``: a second process subscribing ``/measured_pose`` with the node's QoS that
  counts every pose and sequence gap. If the probe gets everything and the node misses canaries,
  the node's executor is too slow (its keep_last 5 reader queue overflows); if the probe misses
  them too, DDS / the machine drops them; a growing ``max_lag_s`` points at the publisher;
- node memory: the resident set of the node's PID every simulated minute (`rss_bytes`): first
  sample after the first training, last sample, growth %; node CPU seconds (utime + stime of
  ``/proc/PID/stat``) per simulated hour.

Prints a compact table and one JSON line. ``--minutes 2 --speed 20`` takes ≈ 20 s of wall time.
"""
# rclpy's Node, executor and publisher methods are untyped in Jazzy.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
import json
import math
import os
from pathlib import Path
import sys
import tempfile
import threading
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
import numpy as np
from numpy.typing import NDArray
import rclpy
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.utilities import try_shutdown

from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.demo import processes
from lf_predictor_ros.nodes.conversions import pose_to_msg, stamp_to_ns, wrench_to_msg
from lf_predictor_ros.nodes.qos import publisher_qos, sensor_qos

NS_PER_S = 1_000_000_000  # [ns/s]
SCENARIO = 'supply_closed_loop'  # 3-DOF supply vessel under DP (sim_ros scenario)
SIM_SEED = 11  # seed of the simulated sea and sensors (the same as benchmark/latency.py)
PREDICTOR_MODULE = 'lf_predictor_ros.nodes.predictor_node'
PREDICTOR_ARGS = ('--ros-args', '-p', 'ndof:=3')  # shipped defaults otherwise
STARTUP_TIMEOUT = 60.0  # [s wall] node start (torch import) and DDS matching on a loaded machine
SETTLE_TIMEOUT = 15.0  # [s wall] after the last pose, for the node's backlog and diagnostics
MATCH_SETTLE = 0.5  # [s wall] after discovery, for the reader side of the match
MEMORY_PERIOD = 60.0  # [s simulated] resident set / CPU sampling period
CLOCK_TICKS = os.sysconf('SC_CLK_TCK')  # [ticks/s] unit of utime / stime in /proc/PID/stat
PROBE_STARTUP = 0.2  # [s wall] poll period while waiting for the probe's subscription
MAX_GAPS_LISTED = 20  # probe: gaps reported individually (index, length)
DIAG_NAME_PREFIX = 'predictor:'  # status name the predictor node publishes on /diagnostics

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SoakConfig:
    """One soak run: simulated length, feed speed and rate, canaries, optional probe."""

    minutes: float = 30.0  # [min simulated]
    speed: float = 20.0  # [× real time]
    rate: float = 100.0  # [Hz] pose and thrust rate, in simulated time
    canary_every: int = 10  # [poses] one canary after every N-th pose; 0 = none
    probe: bool = False  # run the independent probe subscriber process
    log_dir: Path | None = None  # node logs; None = a temporary folder

    def __post_init__(self) -> None:
        """Check every rule; the message says what to change."""
        for name in ('minutes', 'speed', 'rate'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'{name} must be a positive finite number, got {value}')
        if self.canary_every < 0:
            raise ValueError(f'canary_every must be >= 0 (0 disables canaries), got '
                             f'{self.canary_every}')
        if self.minutes * 60.0 * self.rate < 2:
            raise ValueError('minutes × 60 × rate must give at least 2 poses; run longer')


@dataclass(frozen=True)
class SoakInputs:
    """Pose and thrust series at the soak rate (simulated time)."""

    times: FloatArray  # (n,) [s]
    poses: FloatArray  # (n, 3) [m, m, rad]
    forces: FloatArray  # (n, 3) [N, N, N·m]


@dataclass(frozen=True)
class SoakResult:
    """What one soak measured (see the module docstring for each figure's meaning)."""

    minutes: float
    speed: float
    rate: float
    wall_s: float  # publishing wall time [s]
    achieved_speed: float  # simulated span / publishing wall time
    max_lag_s: float  # [s wall] largest delay of a publish behind its schedule
    poses_sent: int
    thrusts_sent: int
    canaries_sent: int
    canaries_received: int  # by the node: its `invalid` counter
    node_pose_loss: float  # 1 − canaries_received / canaries_sent (nan without canaries)
    node_dropped: int  # out_of_order + outliers reported by the node (canaries excluded)
    node_samples: int  # grid samples the node predicted (diagnostics `samples`)
    node_gaps: int  # diagnostics `gaps` (pose gaps > max_gap)
    node_stale_thrust: int  # diagnostics `stale_thrust`
    node_callback_errors: int
    trainings: int
    expected_outputs: int  # grid samples spanned by the poses sent
    outputs: int  # /lf_pose messages received
    output_gaps: int  # missing /lf_pose stamps between the first and the last
    outputs_finite: bool
    probe_received: int  # -1 without --probe
    probe_missing: int  # sequence gaps seen by the probe [poses]; -1 without --probe
    rss_start_mb: float  # after the first training (or the first sample if none)
    rss_end_mb: float
    rss_peak_mb: float
    rss_growth_pct: float
    rss_start_after_training: bool
    cpu_s_per_sim_hour: float  # node process
    cpu_share: float  # node CPU seconds / publishing wall seconds
    node_exit_code: int
    load_start: float  # 1-minute load average when the run started
    load_end: float
    rss_samples_mb: list[float] = field(default_factory=list)
    probe_first_gaps: list[list[int]] = field(default_factory=list)  # [pose index, missing]
    pose_loss_before_training: float = math.nan  # canary loss while no training had finished
    pose_loss_after_training: float = math.nan  # from the first finished training to the end
    poses_accepted: int = -1  # diagnostics `poses_accepted` (valid poses the aligner took)
    pose_loss_exact: float = math.nan  # 1 − poses_accepted / poses_sent


def soak_inputs(minutes: float, rate: float, seed: int = SIM_SEED) -> SoakInputs:
    """Simulate the supply vessel and resample pose and thrust to ``rate`` (linear interp.)."""
    from sim_ros.simulation import load_scenario, simulate  # physics only when a soak runs

    record = simulate(load_scenario(SCENARIO), seed=seed, duration=minutes * 60.0)
    times = np.arange(record.t[0], record.t[-1], 1.0 / rate)
    poses = np.column_stack([np.interp(times, record.t, record.measured_pose[:, i])
                             for i in range(3)])
    forces = np.column_stack([np.interp(times, record.t, record.thrust[:, i])
                              for i in range(3)])
    return SoakInputs(times, poses, forces)


def expected_grid_samples(first_t: float, last_t: float, sample_time: float) -> int:
    """Grid instants k·h in [first_t, last_t]: the node's predictions for that pose span."""
    first = math.ceil(first_t / sample_time - 1e-9)
    last = math.floor(last_t / sample_time + 1e-9)
    return max(0, last - first + 1)


def missing_in_sequence(stamps_ns: Sequence[int], period_ns: int) -> int:
    """Stamps missing between consecutive ones of a series that should step by ``period_ns``."""
    missing = 0
    for previous, current in zip(stamps_ns, stamps_ns[1:], strict=False):
        steps = round((current - previous) / period_ns)
        missing += max(0, steps - 1)
    return missing


def rss_bytes(pid: int) -> int:
    """Resident set size of a process [bytes]: ``Rss`` of ``/proc/PID/smaps_rollup``.

    Exact (the kernel walks the mappings); ``VmRSS`` of ``/proc/PID/status`` is kept from
    per-CPU counters that may lag (proc(5)), and is read only where ``smaps_rollup`` is
    missing (Linux before 4.14).
    """
    try:
        return _proc_kb(f'/proc/{pid}/smaps_rollup', 'Rss:') * 1024
    except FileNotFoundError:
        if not os.path.exists(f'/proc/{pid}'):
            raise
        return _proc_kb(f'/proc/{pid}/status', 'VmRSS:') * 1024


def _proc_kb(path: str, key: str) -> int:
    """The kB value of the first line of ``path`` that starts with ``key``."""
    with open(path, encoding='ascii') as lines:
        for line in lines:
            if line.startswith(key):
                return int(line.split()[1])  # the files give kB
    raise ValueError(f'{path} has no {key} line; is the process a zombie?')


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process [s] (fields 14 and 15 of ``/proc/PID/stat``)."""
    with open(f'/proc/{pid}/stat', encoding='ascii') as stat:
        text = stat.read()
    fields = text[text.rindex(')') + 2:].split()  # after "pid (comm) ": field 3 is index 0
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS


def canary_message(stamp: Any) -> PoseStamped:
    """A pose the node must drop and count as ``invalid``: NaN position, valid quaternion."""
    msg = PoseStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = 'map_ned'
    msg.pose.position.x = math.nan
    msg.pose.orientation.w = 1.0
    return msg


class SoakListener(Node):
    """Publishes the inputs; records ``/lf_pose`` stamps and the node's diagnostics values."""

    def __init__(self, context: Context) -> None:
        super().__init__('dds_soak', context=context)
        self.pose_pub = self.create_publisher(PoseStamped, '/measured_pose', publisher_qos())
        self.thrust_pub = self.create_publisher(WrenchStamped, '/thrust', publisher_qos())
        self.output_stamps_ns: list[int] = []
        self.outputs_finite = True
        self.diagnostics: dict[str, str] = {}
        self.diagnostics_received = 0
        self.canaries_sent = 0  # updated by the publishing loop
        # (canaries sent, node `invalid`, node `trainings`) at each diagnostics message
        self.timeline: list[tuple[int, int, int]] = []
        self._lock = threading.Lock()
        self.create_subscription(PoseStamped, '/lf_pose', self._on_lf_pose, publisher_qos())
        self.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics,
                                 publisher_qos())

    def _on_lf_pose(self, msg: PoseStamped) -> None:
        p, q = msg.pose.position, msg.pose.orientation
        finite = all(math.isfinite(v) for v in (p.x, p.y, p.z, q.w, q.x, q.y, q.z))
        with self._lock:
            self.output_stamps_ns.append(stamp_to_ns(msg.header.stamp))
            self.outputs_finite = self.outputs_finite and finite

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.startswith(DIAG_NAME_PREFIX):
                values = {kv.key: kv.value for kv in status.values}
                with self._lock:
                    self.diagnostics = values
                    self.diagnostics_received += 1
                    self.timeline.append((self.canaries_sent, _diag_int(values, 'invalid'),
                                          _diag_int(values, 'trainings')))

    def snapshot(self) -> tuple[int, int, dict[str, str]]:
        """(outputs received, diagnostics received, latest diagnostics values)."""
        with self._lock:
            return (len(self.output_stamps_ns), self.diagnostics_received,
                    dict(self.diagnostics))


def _diag_int(values: Mapping[str, str], key: str) -> int:
    try:
        return int(values[key])
    except (KeyError, ValueError):
        return -1


def _wait(condition: Any, timeout: float, what: str, node_process: processes.NodeProcess,
          poll: float = 0.05) -> None:
    """Poll ``condition()`` until true; RuntimeError naming ``what`` on timeout or node exit."""
    deadline = time.monotonic() + timeout
    while not condition():
        if not node_process.running():
            raise RuntimeError(processes.describe_failure(node_process))
        if time.monotonic() > deadline:
            raise RuntimeError(f'{what} not seen within {timeout:.0f} s (node log '
                               f'{node_process.log_path})')
        time.sleep(poll)


def _probe_result(log_path: Path) -> dict[str, Any]:
    """The probe's JSON line (the last line of its log starting with '{')."""
    for line in reversed(processes.log_tail(log_path, 50).splitlines()):
        if line.startswith('{'):
            parsed: dict[str, Any] = json.loads(line)
            return parsed
    return {'received': -1, 'missing': -1, 'canaries': -1, 'first_gaps': []}


@dataclass
class _MemoryLog:
    """Resident-set samples of the node and whether the first training was seen before each."""

    pid: int
    samples_mb: list[float] = field(default_factory=list)
    start_index: int | None = None  # first sample taken after the first training

    def sample(self, trained: bool) -> None:
        self.samples_mb.append(rss_bytes(self.pid) / 2**20)
        if trained and self.start_index is None:
            self.start_index = len(self.samples_mb) - 1


def _publish(listener: SoakListener, inputs: SoakInputs, config: SoakConfig,
             memory: _MemoryLog) -> tuple[int, float, float]:
    """Feed the inputs on schedule; (canaries sent, max lag [s wall], publishing wall [s])."""
    times, speed = inputs.times, config.speed
    canaries = 0
    max_lag = 0.0
    next_memory = times[0]
    wall0 = time.monotonic()
    for k in range(len(times)):
        lag = time.monotonic() - (wall0 + (times[k] - times[0]) / speed)
        if lag < 0.0:
            time.sleep(-lag)
        max_lag = max(max_lag, lag)
        t = float(times[k])
        listener.thrust_pub.publish(wrench_to_msg(inputs.forces[k], t))
        msg = pose_to_msg(inputs.poses[k], t)
        listener.pose_pub.publish(msg)
        if config.canary_every and k % config.canary_every == config.canary_every - 1:
            listener.pose_pub.publish(canary_message(msg.header.stamp))
            canaries += 1
            listener.canaries_sent = canaries
        if t >= next_memory:
            memory.sample(_diag_int(listener.snapshot()[2], 'trainings') >= 1)
            next_memory += MEMORY_PERIOD
    return canaries, max_lag, time.monotonic() - wall0


def _settle(listener: SoakListener, node_process: processes.NodeProcess) -> dict[str, str]:
    """Wait until the node's diagnostics account for every output; return their values."""
    deadline = time.monotonic() + SETTLE_TIMEOUT
    _, seen, _ = listener.snapshot()
    values: dict[str, str] = {}
    while time.monotonic() < deadline and node_process.running():
        outputs, received, values = listener.snapshot()
        if received >= seen + 2 and _diag_int(values, 'samples') == outputs:
            break
        time.sleep(0.1)
    return values


def _start_probe(env: Mapping[str, str], log_dir: Path, rate: float) -> processes.NodeProcess:
    return processes.start('dds_soak_probe', 'lf_predictor_ros.benchmark.dds_soak',
                           ['--run-probe', '--rate', repr(rate)], env, log_dir)


@dataclass
class _Ros:
    """The feeding process's ROS side: private context, listener node, spinning thread."""

    context: Context
    listener: SoakListener
    executor: SingleThreadedExecutor
    spinner: threading.Thread

    @classmethod
    def start(cls) -> _Ros:
        context = Context()
        rclpy.init(context=context)
        listener = SoakListener(context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(listener)
        spinner = threading.Thread(target=_spin_quietly, args=(executor,), daemon=True)
        spinner.start()
        return cls(context, listener, executor, spinner)

    def stop(self) -> None:
        self.executor.shutdown()
        self.listener.destroy_node()
        try_shutdown(context=self.context)
        self.spinner.join(timeout=5.0)


def _feed(ros: _Ros, node_process: processes.NodeProcess, inputs: SoakInputs,
          config: SoakConfig, memory: _MemoryLog) -> tuple[int, float, float, float,
                                                           dict[str, str]]:
    """Wait for the active node, feed it, let it settle.

    Returns (canaries sent, max lag [s], publishing wall [s], node CPU [s], final diagnostics).
    """
    listener = ros.listener
    readers = 2 if config.probe else 1  # the probe subscribes to /measured_pose too
    _wait(lambda: (listener.pose_pub.get_subscription_count() >= readers
                   and listener.thrust_pub.get_subscription_count() >= 1
                   and listener.snapshot()[2].get('active') == 'true'),
          STARTUP_TIMEOUT, 'the active predictor (subscriptions + diagnostics)', node_process)
    time.sleep(MATCH_SETTLE)
    cpu0 = cpu_seconds(node_process.process.pid)
    canaries, max_lag, wall = _publish(listener, inputs, config, memory)
    values = _settle(listener, node_process)
    memory.sample(_diag_int(values, 'trainings') >= 1)
    cpu = cpu_seconds(node_process.process.pid) - cpu0
    return canaries, max_lag, wall, cpu, values


def run_soak(config: SoakConfig) -> SoakResult:
    """Run one soak (the node in its own process, this process feeding it); see the module."""
    inputs = soak_inputs(config.minutes, config.rate)
    sample_time = PredictorParams().sample_time  # [s] shipped default of the node
    env = processes.isolated_environment(os.environ, os.getpid())
    probe_counts: dict[str, Any] = {'received': -1, 'missing': -1, 'first_gaps': []}
    with tempfile.TemporaryDirectory(prefix='dds_soak-') as scratch:
        log_dir = config.log_dir or Path(scratch)
        load_start = os.getloadavg()[0]
        node_process = processes.start('predictor', PREDICTOR_MODULE, list(PREDICTOR_ARGS), env,
                                       log_dir)
        probe = _start_probe(env, log_dir, config.rate) if config.probe else None
        ros: _Ros | None = None
        try:
            ros = _Ros.start()
            memory = _MemoryLog(node_process.process.pid)
            canaries, max_lag, wall, cpu, values = _feed(ros, node_process, inputs, config,
                                                         memory)
        finally:
            exit_code = processes.stop(node_process)
            if probe is not None:
                processes.stop(probe)
                probe_counts = _probe_result(probe.log_path)
            if ros is not None:
                ros.stop()
    listener = ros.listener
    result = _result(config, inputs, sample_time, sorted(listener.output_stamps_ns),
                     listener.outputs_finite, values, memory, canaries, max_lag, wall, cpu,
                     exit_code, probe_counts, (load_start, os.getloadavg()[0]))
    return _with_loss_split(result, listener.timeline)


def _spin_quietly(executor: SingleThreadedExecutor) -> None:
    try:
        executor.spin()
    except ExternalShutdownException:
        pass


def split_loss(timeline: Sequence[tuple[int, int, int]]) -> tuple[float, float]:
    """Canary loss before the first finished training and after it (nan when no data).

    ``timeline`` holds (canaries sent, canaries the node counted, trainings) per diagnostics
    message, in arrival order.
    """
    def loss(sent: int, seen: int) -> float:
        return 1.0 - seen / sent if sent > 0 and seen >= 0 else math.nan

    first = next((i for i, (_, _, trainings) in enumerate(timeline) if trainings >= 1), None)
    if not timeline:
        return math.nan, math.nan
    if first is None:
        return loss(timeline[-1][0], timeline[-1][1]), math.nan
    before = timeline[first - 1] if first > 0 else (0, 0, 0)
    end = timeline[-1]
    return loss(before[0], before[1]), loss(end[0] - before[0], end[1] - before[1])


def _result(config: SoakConfig, inputs: SoakInputs, sample_time: float, stamps: list[int],
            finite: bool, values: Mapping[str, str], memory: _MemoryLog, canaries: int,
            max_lag: float, wall: float, cpu: float, exit_code: int,
            probe_counts: Mapping[str, Any], loads: tuple[float, float]) -> SoakResult:
    span = float(inputs.times[-1] - inputs.times[0])  # [s simulated]
    invalid = _diag_int(values, 'invalid')
    dropped = _diag_int(values, 'dropped')
    accepted = _diag_int(values, 'poses_accepted')
    samples = memory.samples_mb
    start_index = memory.start_index if memory.start_index is not None else 0
    rss_start, rss_end = samples[start_index], samples[-1]
    return SoakResult(
        minutes=config.minutes, speed=config.speed, rate=config.rate, wall_s=wall,
        achieved_speed=span / wall, max_lag_s=max_lag, poses_sent=len(inputs.times),
        thrusts_sent=len(inputs.times), canaries_sent=canaries, canaries_received=invalid,
        node_pose_loss=1.0 - invalid / canaries if canaries else math.nan,
        node_dropped=dropped - invalid if dropped >= 0 and invalid >= 0 else -1,
        node_samples=_diag_int(values, 'samples'), node_gaps=_diag_int(values, 'gaps'),
        node_stale_thrust=_diag_int(values, 'stale_thrust'),
        node_callback_errors=_diag_int(values, 'callback_errors'),
        trainings=_diag_int(values, 'trainings'),
        expected_outputs=expected_grid_samples(float(inputs.times[0]),
                                               float(inputs.times[-1]), sample_time),
        outputs=len(stamps),
        output_gaps=missing_in_sequence(stamps, round(sample_time * NS_PER_S)),
        outputs_finite=finite, probe_received=int(probe_counts.get('received', -1)),
        probe_missing=int(probe_counts.get('missing', -1)),
        probe_first_gaps=[list(gap) for gap in probe_counts.get('first_gaps', [])],
        rss_start_mb=rss_start, rss_end_mb=rss_end, rss_peak_mb=max(samples),
        rss_growth_pct=100.0 * (rss_end - rss_start) / rss_start,
        rss_start_after_training=memory.start_index is not None,
        cpu_s_per_sim_hour=cpu / (span / 3600.0), cpu_share=cpu / wall,
        node_exit_code=exit_code, load_start=loads[0], load_end=loads[1],
        rss_samples_mb=[round(value, 1) for value in samples], poses_accepted=accepted,
        pose_loss_exact=1.0 - accepted / len(inputs.times) if accepted >= 0 else math.nan)


def _with_loss_split(result: SoakResult, timeline: Sequence[tuple[int, int, int]]) -> SoakResult:
    before, after = split_loss(timeline)
    return replace(result, pose_loss_before_training=before, pose_loss_after_training=after)


# ---- probe process ------------------------------------------------------------------------

class _Probe(Node):
    """Counts ``/measured_pose`` messages with the node's QoS: received, canaries, gaps."""

    def __init__(self, rate: float) -> None:
        super().__init__('dds_soak_probe')
        self.period_ns = round(NS_PER_S / rate)
        self.received = 0
        self.canaries = 0
        self.missing = 0
        self.first_gaps: list[tuple[int, int]] = []  # (pose index, poses missing before it)
        self._first_ns: int | None = None
        self._last_ns: int | None = None
        self.create_subscription(PoseStamped, '/measured_pose', self._on_pose, sensor_qos())

    def _on_pose(self, msg: PoseStamped) -> None:
        if math.isnan(msg.pose.position.x):
            self.canaries += 1
            return
        stamp = stamp_to_ns(msg.header.stamp)
        if self._first_ns is None:
            self._first_ns = stamp
        if self._last_ns is not None:
            missing = max(0, round((stamp - self._last_ns) / self.period_ns) - 1)
            self.missing += missing
            if missing and len(self.first_gaps) < MAX_GAPS_LISTED:
                self.first_gaps.append((round((stamp - self._first_ns) / self.period_ns),
                                        missing))
        self._last_ns = stamp
        self.received += 1


def run_probe(rate: float) -> int:
    """Probe process main: spin until SIGINT, then print one JSON line of counts."""
    rclpy.init()
    probe = _Probe(rate)
    try:
        rclpy.spin(probe)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        print(json.dumps({'received': probe.received, 'canaries': probe.canaries,
                          'missing': probe.missing, 'first_gaps': probe.first_gaps}),
              flush=True)
        probe.destroy_node()
        try_shutdown()
    return 0


# ---- command line -------------------------------------------------------------------------

def _percent(fraction: float) -> str:
    return f'{100 * fraction:.2f} %' if math.isfinite(fraction) else 'n/a'


def json_line(result: SoakResult) -> str:
    """The result as one line of strict JSON (nan → null)."""
    fields = {key: None if isinstance(value, float) and not math.isfinite(value) else value
              for key, value in asdict(result).items()}
    return json.dumps(fields, allow_nan=False)


def format_table(result: SoakResult) -> str:
    """A compact, human-readable summary of one soak."""
    r = result
    rows = [
        ('run', f'{r.minutes:g} min simulated at {r.rate:g} Hz, {r.speed:g}× real time '
                f'(achieved {r.achieved_speed:.1f}×, {r.wall_s:.1f} s wall, max publish lag '
                f'{r.max_lag_s * 1e3:.0f} ms), load {r.load_start:.2f} → {r.load_end:.2f}'),
        ('poses / thrusts sent', f'{r.poses_sent} / {r.thrusts_sent}'),
        ('node: poses accepted', f'{r.poses_accepted} of {r.poses_sent} (pose loss '
                                 f'{_percent(r.pose_loss_exact)})'),
        ('node: canaries seen', f'{r.canaries_received} of {r.canaries_sent} (pose loss ≈ '
                                f'{_percent(r.node_pose_loss)}: '
                                f'{_percent(r.pose_loss_before_training)} before the first '
                                f'training, {_percent(r.pose_loss_after_training)} after)'),
        ('node: dropped / gaps / stale thrust / errors',
         f'{r.node_dropped} / {r.node_gaps} / {r.node_stale_thrust} / {r.node_callback_errors}'),
        ('probe: received / missing', f'{r.probe_received} / {r.probe_missing} (first gaps '
         f'[pose index, length]: {r.probe_first_gaps[:5]})' if r.probe_received >= 0
         else 'not run'),
        ('outputs (lf_pose)', f'{r.outputs} of {r.expected_outputs} grid samples, node '
                              f'samples {r.node_samples}, gaps {r.output_gaps}, finite '
                              f'{r.outputs_finite}'),
        ('trainings', str(r.trainings)),
        ('node RSS [MB]', f'{r.rss_start_mb:.0f} → {r.rss_end_mb:.0f} (peak '
                          f'{r.rss_peak_mb:.0f}, {r.rss_growth_pct:+.1f} %'
                          f'{"" if r.rss_start_after_training else ", no training seen"})'),
        ('node CPU', f'{r.cpu_s_per_sim_hour:.0f} s per simulated hour '
                     f'({100 * r.cpu_share:.0f} % of a core while fed)'),
        ('node exit code', str(r.node_exit_code)),
    ]
    width = max(len(name) for name, _ in rows)
    return '\n'.join(f'{name:<{width}}  {value}' for name, value in rows)


def _parse(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog='dds_soak', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--minutes', type=float, default=30.0, help='simulated minutes')
    parser.add_argument('--speed', type=float, default=20.0, help='× real time feed')
    parser.add_argument('--rate', type=float, default=100.0, help='pose and thrust rate [Hz]')
    parser.add_argument('--canary-every', type=int, default=10,
                        help='one NaN canary pose after every N-th pose (0: none)')
    parser.add_argument('--probe', action='store_true',
                        help='also count poses in an independent subscriber process')
    parser.add_argument('--log-dir', type=Path, default=None, help='keep the node logs here')
    parser.add_argument('--run-probe', action='store_true', help=argparse.SUPPRESS)
    return parser.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point (``python -m lf_predictor_ros.benchmark.dds_soak``); exit code."""
    args = _parse(argv)
    env = processes.isolated_environment(os.environ, os.getpid())
    for name in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID'):
        os.environ[name] = env[name]  # before rclpy.init: this process joins the private domain
    if args.run_probe:
        return run_probe(args.rate)
    try:
        config = SoakConfig(minutes=args.minutes, speed=args.speed, rate=args.rate,
                            canary_every=args.canary_every, probe=args.probe,
                            log_dir=args.log_dir)
        result = run_soak(config)
    except (ValueError, RuntimeError) as error:
        print(f'dds_soak: {error}', file=sys.stderr)
        return 1
    print(format_table(result))
    print(json_line(result), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
