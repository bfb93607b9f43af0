"""`demo`: one closed-loop run of a scenario over DDS with the predictor in the loop, plus report.

    demo [SCENARIO] [--duration S] [--seed N] [--output-dir runs] [--speed-factor X]
         [--predictor-params FILE] [--no-report]

The real topic graph runs as four processes, each with its log in ``RUN/logs/NAME.log`` and an
isolated DDS environment (`processes.isolated_environment`):

1. ``recorder`` (``use_sim_time``) records every interface topic to ``RUN/run.mcap``;
2. ``predictor`` (``use_sim_time``): measured_pose + thrust → lf_pose, wave_peak_frequency;
   parameters from ``config/predictor.yaml``, then ``config/demo.yaml``, then
   ``--predictor-params`` (later files override earlier ones), ``ndof`` from the scenario;
3. ``dp_controller`` on ``lf_pose`` (the predictor's estimate closes the loop);
4. ``simulator`` last, in lockstep through the predictor: it steps freely between multiples of
   the predictor's sample time h and waits there for the command answering that sample (stamped
   t + h: ``lockstep_period`` = ``lockstep_lead`` = h; see `sim_ros.nodes.simulator_node`).

The simulator is started once the graph shows the other nodes' subscriptions (so the recorder
and the predictor miss no sample); the demo waits for it to exit at ``--duration``, then stops the
controller, the predictor and the recorder (SIGINT, then SIGTERM, then SIGKILL, with timeouts). A
process that dies early stops the run with a non-zero exit and the tail of its log.

Comparison: the same scenario and seed run offline with `sim_ros.simulation.simulate` with the
controller fed the raw ``measured_pose`` and, as the ideal reference, the true LF pose (ROS-free,
fast). The report (`report.write_report`) goes to ``RUN/report.png``, ``metrics.json`` and
``report.md``; RUN = ``OUTPUT_DIR/<scenario>-<YYYYmmdd-HHMMSS>``.
"""
from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime
import math
import os
from pathlib import Path
import signal
import sys
import time
from typing import Any

import numpy as np
import yaml

from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.demo import processes
from lf_predictor_ros.demo.processes import NodeProcess
from lf_predictor_ros.demo.report import (
    LoopRun,
    RunData,
    Trace,
    retrain_times_from_diagnostics,
    write_report,
)
from sim_ros.simulation import REPO_ROOT, Scenario, SimRecord, load_scenario, simulate

DEFAULT_SCENARIO = 'supply_closed_loop'
CONFIG_DIR = REPO_ROOT / 'config'
PREDICTOR_CONFIG = CONFIG_DIR / 'predictor.yaml'
DEMO_CONFIG = CONFIG_DIR / 'demo.yaml'
STARTUP_TIMEOUT = 60.0  # [s wall] for recorder, predictor and controller to appear in the graph
STOP_TIMEOUT = 10.0  # [s wall] per signal when stopping a node
SETTLE_TIME = 0.5  # [s wall] after the simulator exits, so the recorder gets the last messages
MIN_REAL_TIME_FACTOR = 1.0  # the run is aborted if slower than real time (plus start-up)
START_UP_ALLOWANCE = 120.0  # [s wall] added to the run-time limit
# Subscriptions that must exist before the simulator starts: predictor + recorder on the
# measurements, controller + recorder on lf_pose, predictor + recorder on the commands (the
# predictor reads the controller's gains from them; a command it missed shortens that fit).
REQUIRED_SUBSCRIBERS = {'/measured_pose': 2, '/thrust': 2, '/lf_pose': 2, '/thrust_command': 2}
# the simulator offers its first sample only once its publishers have matched these (predictor +
# recorder; recorder): the graph showing a subscription does not mean it has matched a publisher
# that starts after it, and the bag would miss the start of the run
START_SUBSCRIPTIONS = ('measured_pose=2', 'thrust=2', 'truth/pose=1', 'truth/lf_pose=1')
NO_TRAINING_WARMUP = 0.1  # fraction of the run excluded from the metrics without a training


@dataclass(frozen=True)
class DemoOptions:
    """Command-line options of `demo`."""

    scenario: str = DEFAULT_SCENARIO
    duration: float | None = None
    seed: int | None = None
    output_dir: Path = Path('runs')
    speed_factor: float = 0.0
    predictor_params: Path | None = None
    report: bool = True


@dataclass(frozen=True)
class RunPlan:
    """Everything resolved before any process starts."""

    scenario: Scenario
    scenario_arg: str
    duration: float
    seed: int
    predictor_sample_time: float
    param_files: tuple[Path, ...]
    run_dir: Path
    speed_factor: float

    @property
    def bag_path(self) -> Path:
        """The recorded bag."""
        return self.run_dir / 'run.mcap'

    @property
    def log_dir(self) -> Path:
        """Where every process's output goes."""
        return self.run_dir / 'logs'


# ------------------------------------------------------------------------------ planning
def parse_args(argv: Sequence[str]) -> DemoOptions:
    """Parse the command line (``--help`` exits 0, bad options exit 2)."""
    parser = argparse.ArgumentParser(
        prog='demo', description='One closed-loop run over DDS (simulator, predictor, '
        'dp_controller, recorder) with a plotted report.')
    parser.add_argument('scenario', nargs='?', default=DEFAULT_SCENARIO,
                        help='scenario name in config/scenarios/ or a YAML path '
                             f'(default {DEFAULT_SCENARIO})')
    parser.add_argument('--duration', type=float, default=None,
                        help="simulated seconds (default: the scenario's duration)")
    parser.add_argument('--seed', type=int, default=None,
                        help="seed of every noise source (default: the scenario's seed)")
    parser.add_argument('--output-dir', type=Path, default=Path('runs'),
                        help='parent of the run directory (default runs)')
    parser.add_argument('--speed-factor', type=float, default=0.0,
                        help='simulated s per wall s; 0 = as fast as the loop allows (default)')
    parser.add_argument('--predictor-params', type=Path, default=None,
                        help='ROS params file overriding config/predictor.yaml and '
                             'config/demo.yaml')
    parser.add_argument('--no-report', action='store_true', help='skip the report')
    ns = parser.parse_args(list(argv))
    return DemoOptions(ns.scenario, ns.duration, ns.seed, ns.output_dir, ns.speed_factor,
                       ns.predictor_params, not ns.no_report)


def ros_parameters(path: Path) -> dict[str, Any]:
    """The ``ros__parameters`` of a params file (``/**`` or any node key, merged)."""
    data = yaml.safe_load(path.read_text(encoding='utf-8')) or {}
    if not isinstance(data, Mapping):
        raise ValueError(f'{path} is not a ROS params file (a mapping of node names to '
                         f'ros__parameters)')
    merged: dict[str, Any] = {}
    for section in data.values():
        if isinstance(section, Mapping) and isinstance(section.get('ros__parameters'), Mapping):
            merged.update(section['ros__parameters'])
    return merged


def predictor_sample_time(param_files: Sequence[Path], scenario_sample_time: float) -> float:
    """The predictor's h from the params files (last wins), checked against the scenario.

    The lockstep period is h, so h must be a whole multiple of the simulator's sample time.
    """
    sample_time = PredictorParams().sample_time
    for path in param_files:
        sample_time = float(ros_parameters(path).get('sample_time', sample_time))
    ratio = sample_time / scenario_sample_time
    if round(ratio) < 1 or abs(ratio - round(ratio)) > 1e-9 * max(ratio, 1.0):
        raise ValueError(f"the predictor's sample_time ({sample_time} s) must be a whole "
                         f"multiple of the scenario's sample time ({scenario_sample_time} s): "
                         f'set sample_time in a --predictor-params file')
    return sample_time


def plan_run(options: DemoOptions, now: datetime | None = None) -> RunPlan:
    """Resolve scenario, seed, duration, parameter files and the run directory."""
    scenario = load_scenario(options.scenario)
    duration = scenario.duration if options.duration is None else float(options.duration)
    if not (math.isfinite(duration) and duration > 0.0):
        raise ValueError(f'--duration must be > 0 s, got {duration}')
    if not (math.isfinite(options.speed_factor) and options.speed_factor >= 0.0):
        raise ValueError(f'--speed-factor must be >= 0 (0 = as fast as possible), got '
                         f'{options.speed_factor}')
    files = [path for path in (PREDICTOR_CONFIG, DEMO_CONFIG) if path.is_file()]
    if options.predictor_params is not None:
        if not options.predictor_params.is_file():
            raise ValueError(f'--predictor-params {options.predictor_params}: no such file')
        files.append(options.predictor_params.resolve())
    sample_time = predictor_sample_time(files, scenario.sample_time)
    scenario_arg = options.scenario
    if scenario_arg.endswith(('.yaml', '.yml')) or os.sep in scenario_arg:
        scenario_arg = str(Path(scenario_arg).resolve())
    stamp = (now or datetime.now()).strftime('%Y%m%d-%H%M%S')
    run_dir = options.output_dir / f'{scenario.name}-{stamp}'
    return RunPlan(scenario, scenario_arg, duration,
                   scenario.seed if options.seed is None else int(options.seed), sample_time,
                   tuple(files), run_dir, options.speed_factor)


def node_commands(plan: RunPlan) -> dict[str, tuple[str, list[str]]]:
    """(module, arguments) of every node, in start order."""
    h = f'{plan.predictor_sample_time!r}'
    predictor_args = ['--ros-args', '-p', 'use_sim_time:=true']
    for path in plan.param_files:
        predictor_args += ['--params-file', str(path)]
    predictor_args += ['-p', f'ndof:={plan.scenario.ndof}']
    return {
        'recorder': ('lf_predictor_ros.bag.recorder_node', [
            '--ros-args', '-p', 'use_sim_time:=true', '-p', f'output:={plan.bag_path}',
            '-p', 'reliability:=reliable']),  # every node here publishes reliably
        'predictor': ('lf_predictor_ros.nodes.predictor_node', predictor_args),
        'dp_controller': ('sim_ros.nodes.dp_controller_node', [
            '--ros-args', '--params-file', str(CONFIG_DIR / 'dp_controller.yaml'),
            '-p', f'scenario:={plan.scenario_arg}']),
        'simulator': ('sim_ros.nodes.simulator_node', [
            '--ros-args', '--params-file', str(CONFIG_DIR / 'simulator.yaml'),
            '-p', f'scenario:={plan.scenario_arg}', '-p', f'seed:={plan.seed}',
            '-p', f'duration:={plan.duration!r}', '-p', f'speed_factor:={plan.speed_factor!r}',
            '-p', 'lockstep:=true', '-p', f'lockstep_period:={h}', '-p', f'lockstep_lead:={h}',
            '-p', f'command_timeout:={max(1.0, 2.0 * plan.predictor_sample_time)!r}',
            '-p', f'start_subscriptions:={list(START_SUBSCRIPTIONS)!r}']),
    }


# ------------------------------------------------------------------------------ running
def wait_for_subscribers(required: Mapping[str, int], nodes: Sequence[NodeProcess],
                         timeout: float) -> NodeProcess | None:
    """Wait until the graph shows the required subscriptions; returns a node that died first.

    Raises TimeoutError naming the missing subscriptions after ``timeout`` wall seconds.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.utilities import try_shutdown

    context = Context()
    rclpy.init(args=[], context=context)
    probe = rclpy.create_node('demo_graph_probe', context=context)
    try:
        deadline = time.monotonic() + timeout
        while True:
            missing = {topic: probe.count_subscribers(topic) for topic in required
                       if probe.count_subscribers(topic) < required[topic]}
            if not missing:
                return None
            dead = processes.first_dead(nodes)
            if dead is not None:
                return dead
            if time.monotonic() > deadline:
                raise TimeoutError(f'after {timeout:.0f} s the graph still lacks subscriptions '
                                   f'(topic: subscribers seen) {missing}')
            time.sleep(0.1)
    finally:
        probe.destroy_node()
        try_shutdown(context=context)


@dataclass(frozen=True)
class RunOutcome:
    """Wall time [s] of the simulated run (simulator start to exit) and the failure, if any."""

    wall_time: float
    failure: str = ''


def run_graph(plan: RunPlan, env: Mapping[str, str]) -> RunOutcome:
    """Start the four nodes, wait for the simulator, stop the rest; never leaves a process."""
    commands = node_commands(plan)
    started: list[NodeProcess] = []
    failure = ''
    wall_time = math.nan
    try:
        for name in ('recorder', 'predictor', 'dp_controller'):
            module, args = commands[name]
            started.append(processes.start(name, module, args, env, plan.log_dir, REPO_ROOT))
        dead = wait_for_subscribers(REQUIRED_SUBSCRIBERS, started, STARTUP_TIMEOUT)
        if dead is not None:
            return RunOutcome(wall_time, processes.describe_failure(dead))
        module, args = commands['simulator']
        start = time.monotonic()
        simulator = processes.start('simulator', module, args, env, plan.log_dir, REPO_ROOT)
        started.append(simulator)
        limit = START_UP_ALLOWANCE + plan.duration / max(plan.speed_factor * 0.5,
                                                          MIN_REAL_TIME_FACTOR)
        dead = processes.wait_exit(simulator, started[:-1], limit)
        wall_time = time.monotonic() - start
        if dead is not None:
            failure = processes.describe_failure(dead)
        elif simulator.returncode() != 0:
            failure = processes.describe_failure(simulator)
        time.sleep(SETTLE_TIME)
    except TimeoutError as error:
        failure = f'{error}; logs in {plan.log_dir}'
    finally:
        for node in reversed(started):
            code = processes.stop(node, STOP_TIMEOUT)
            if not failure and code not in (0, -2, 130) and node.name != 'simulator':
                print(f'note: {node.name} exited with code {code} on shutdown '
                      f'(log {node.log_path})', file=sys.stderr)
    return RunOutcome(wall_time, failure)


# ------------------------------------------------------------------------------ report
def offline_loops(plan: RunPlan) -> dict[str, SimRecord]:
    """The comparison runs: controller fed the raw measurement, and the true LF pose (ideal)."""
    return {name: simulate(plan.scenario, seed=plan.seed, duration=plan.duration,
                           controller=True, feedback=feedback)
            for name, feedback in (('raw_measurement', 'measured'), ('ideal', 'truth_lf'))}


def _last_value(diagnostics: Sequence[tuple[float, str, Mapping[str, str]]], key: str,
                name_part: str = '') -> int:
    value = 0
    for _, name, values in diagnostics:
        if key in values and name_part in name:
            try:
                value = int(float(values[key]))
            except ValueError:
                continue
    return value


def load_run(plan: RunPlan, wall_time: float,
             offline: Mapping[str, SimRecord]) -> tuple[RunData, float]:
    """RunData from the bag and the offline runs, and the warm-up [s] for the metrics.

    The warm-up ends at the first accepted training (the network is in service from then on),
    but at most at half the run so that half of it is always scored; without a training it is
    ``NO_TRAINING_WARMUP`` of the run (filter and controller start-up).
    """
    from lf_predictor_ros.bag.series import read_diagnostics, read_series

    topics = ['/measured_pose', '/truth/lf_pose', '/lf_pose', '/thrust']
    series = read_series(plan.bag_path, topics)
    try:
        omega = read_series(plan.bag_path, ['/wave_peak_frequency'])['/wave_peak_frequency']
        omega_trace = Trace(omega.stamp, omega.values)
    except ValueError:  # no estimate published (short run): plot the truth only
        omega_trace = Trace(np.empty(0), np.empty((0, 1)))
    diagnostics = read_diagnostics(plan.bag_path)
    retrains = retrain_times_from_diagnostics(diagnostics)
    truth = series['/truth/lf_pose']
    thrust = series['/thrust']
    grid = np.round(truth.stamp * 1e9).astype(np.int64)
    thrust_ns = np.round(thrust.stamp * 1e9).astype(np.int64)
    _, truth_index, thrust_index = np.intersect1d(grid, thrust_ns, return_indices=True)
    loops = {'predictor': LoopRun(truth.stamp[truth_index], truth.values[truth_index],
                                  thrust.values[thrust_index])}
    for name, record in offline.items():
        loops[name] = LoopRun(record.t, record.truth_lf_pose, record.thrust)
    schedule_t = np.arange(0.0, plan.duration + 1e-9, plan.scenario.sample_time)
    omega_truth = plan.scenario.waves.peak_freq.sample(schedule_t)
    trainings = _last_value(diagnostics, 'trainings')
    info = {
        'scenario': plan.scenario.name,
        'scenario_arg': plan.scenario_arg,
        'seed': plan.seed,
        'duration': plan.duration,
        'wall_time': wall_time,
        'real_time_factor': plan.duration / wall_time if wall_time > 0.0 else math.nan,
        'trainings': trainings,
        'lockstep_timeouts': _last_value(diagnostics, 'lockstep_timeouts', 'simulator'),
        'predictor_sample_time': plan.predictor_sample_time,
        'simulator_sample_time': plan.scenario.sample_time,
        'predictor_param_files': [str(p) for p in plan.param_files],
        'bag': str(plan.bag_path),
        'offline_comparison': 'raw_measurement and ideal loops: sim_ros.simulation.simulate '
                              "(ROS-free) with feedback='measured' and 'truth_lf'",
    }
    setpoint = plan.scenario.controller.setpoint
    run = RunData(ndof=plan.scenario.ndof,
                  measured_pose=Trace(series['/measured_pose'].stamp,
                                      series['/measured_pose'].values),
                  truth_lf_pose=Trace(truth.stamp, truth.values),
                  lf_pose=Trace(series['/lf_pose'].stamp, series['/lf_pose'].values),
                  wave_peak_freq=omega_trace,
                  wave_peak_freq_truth=Trace(schedule_t, omega_truth[:, None]),
                  loops=loops, retrain_times=tuple(retrains), setpoint=tuple(setpoint),
                  run_info=info)
    warmup = (min(retrains[0], 0.5 * plan.duration) if retrains
              else NO_TRAINING_WARMUP * plan.duration)
    return run, warmup


# ------------------------------------------------------------------------------ main
def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt(f'signal {signum}')


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``demo``; returns the exit code."""
    options = parse_args(sys.argv[1:] if argv is None else argv)
    try:
        plan = plan_run(options)
    except (ValueError, FileNotFoundError) as error:
        print(f'demo: {error}', file=sys.stderr)
        return 2
    plan.log_dir.mkdir(parents=True, exist_ok=True)
    env = processes.isolated_environment(os.environ, os.getpid())
    # this process joins the same domain for its graph probe
    for key in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID'):
        os.environ[key] = env[key]
    print(f"demo: {plan.scenario.name} seed {plan.seed}, {plan.duration:g} s simulated, "
          f"predictor h = {plan.predictor_sample_time:g} s, ROS_DOMAIN_ID {env['ROS_DOMAIN_ID']}"
          f', run directory {plan.run_dir}', flush=True)
    signal.signal(signal.SIGTERM, _interrupt)  # stop the children on SIGTERM too
    try:
        outcome = run_graph(plan, env)
    except KeyboardInterrupt:
        print(f'demo: interrupted; the nodes were stopped, logs in {plan.log_dir}',
              file=sys.stderr)
        return 130
    if outcome.failure:
        print(f'demo: FAILED: {outcome.failure}', file=sys.stderr)
        return 1
    print(f'demo: {plan.duration:g} s simulated in {outcome.wall_time:.1f} s wall '
          f'({plan.duration / outcome.wall_time:.1f}x real time)', flush=True)
    print(f'run directory: {plan.run_dir}')
    if not options.report:
        print(f'bag: {plan.bag_path}')
        return 0
    offline = offline_loops(plan)
    try:
        run, warmup = load_run(plan, outcome.wall_time, offline)
    except ValueError as error:
        print(f'demo: cannot read the recording {plan.bag_path}: {error}', file=sys.stderr)
        return 1
    paths = write_report(run, plan.run_dir, warmup)
    print(f'report: {paths.markdown} ({paths.png.name}, {paths.metrics.name})')
    return 0


if __name__ == '__main__':
    sys.exit(main())
