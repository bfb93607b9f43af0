"""Predictor node callback latency and CPU use at 10 Hz and 100 Hz input (issue 5 benchmark).

    python -m lf_predictor_ros.benchmark.latency [--minutes 30] [--speed 20]

Builds the `predictor` node in-process (shipped defaults, ndof 3), feeds it simulated
supply-vessel pose + thrust messages by calling its subscription callbacks at `--speed` × real
time, and times every pose callback (wall clock, `time.perf_counter`). Callbacks are split into
"idle" and "while training" (the core's worker thread busy); ``learning_p99_ms`` is the p99
of the callbacks that ran while the vessel memory's job ran on its own thread (either kind).
Prints p50 / p99 / max, the number of trainings, and the CPU time of the process and its
children (the ω0 fit's) per simulated hour, and the garbage collector's full collections and its
longest run (a collection in any thread stalls the callback: the GIL).

With input faster than the sample time h (1 s), most callbacks only store the pose; the one that
completes a grid sample runs the whole step (checks, predictor, odometry, publishing). At 100 Hz
that is one callback in a hundred, so the p99 sits at the fast end of the steps and moves with
the machine's noise. ``step_p50_ms`` / ``step_p90_ms`` (idle and busy) are the percentiles of
the step callbacks alone (those after which the node has processed one more sample): the
statistic to compare two versions of the step with. While training nearly every step is over
the cost target's 1 ms and the steps are 0.8–0.9 % of the callbacks, so the p99 while training
is under 1 ms exactly when the steps and the other callbacks over 1 ms (``busy_slow_steps``,
``busy_slow_others``: a pose-only callback that waited for the GIL or the CPU) stay under 1 %
of ``callbacks_while_training`` (docs/BENCHMARKS.md, sixty-seventh and sixty-eighth sessions).

``--commands pid`` also closes a DP controller on the node's output, as a DP stack does: the
`dp_controller` node in the same process (its defaults: the scenario's gains, the D term on the
filtered pose difference) answers ``lf_pose`` over DDS (spun between callbacks, not timed), and
each of its commands, stamped with the estimate's stamp, goes to the node's ``thrust_command``
callback. The vessel memory then reads the controller's gains in its
learning thread (``controller_inertia``, ``core.controller_gains``), which the default feed
(``--commands none``: no ``thrust_command``) never runs. The commands do not move the simulated
vessel (the poses are simulated beforehand); the read only needs them to be a PD law of the
published estimates. ``controller_read`` reports the last read's outcome.

The math libraries run on one thread after the node is built, as in the node executables
(`core.math_threads`; before the sixty-eighth session the bench relied on ``OMP_NUM_THREADS=1``
in its command line, which a plain ``ros2 run`` does not set).

The default feed (20×) sends the callbacks 0.5 ms apart, which keeps the caches warm; at real
time (``--speed 1``) the step took 1.28–1.31 ms (median) against 1.0–1.15 ms at 20× on the
2-core machine of docs/BENCHMARKS.md's twenty-ninth session, and a training overlaps hardly any
step. Both feeds are worth reading.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
import gc
import os
from pathlib import Path
import resource
import sys
import time

from geometry_msgs.msg import WrenchStamped
import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.utilities import try_shutdown

from lf_predictor_ros.core.math_threads import use_one_math_thread
from lf_predictor_ros.nodes.conversions import (
    pose_to_msg,
    stamp_to_sec,
    wrench_to_msg,
)
from lf_predictor_ros.nodes.predictor_node import PredictorNode
from lf_predictor_ros.nodes.qos import command_qos
from lf_predictor_ros.nodes.runner import freeze_startup_heap
from sim_ros.nodes.dp_controller_node import DpControllerNode
from sim_ros.simulation import load_scenario, simulate

COMMAND_FEEDS = ('none', 'pid')  # --commands
SLOW_CALLBACK = 1e-3  # [s] the cost target's bound (module docstring: the slow counts)


def _cpu_seconds() -> float:
    """CPU time [s] of this process and its live descendants (the ω0 fit's child process)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime + _descendants_cpu_seconds()


def _descendants_cpu_seconds() -> float:
    """CPU time [s] of this process's live descendants, from Linux's /proc (0 elsewhere).

    The node's ω0 fits run in a child of a forkserver child (`core.fit_process`), so
    ``RUSAGE_CHILDREN`` (children that have ended) does not see them.
    """
    parents: dict[int, int] = {}
    ticks: dict[int, int] = {}
    for stat in Path('/proc').glob('[0-9]*/stat'):
        try:
            text = stat.read_text()
        except OSError:  # the process ended meanwhile
            continue
        fields = text[text.rindex(')') + 2:].split()  # after "pid (comm) "
        pid = int(stat.parent.name)
        parents[pid] = int(fields[1])
        ticks[pid] = int(fields[11]) + int(fields[12])  # utime + stime [clock ticks]
    total, me = 0, os.getpid()
    for pid in ticks:
        ancestor = parents.get(pid)
        while ancestor is not None and ancestor > 1 and ancestor != me:
            ancestor = parents.get(ancestor)
        if ancestor == me:
            total += ticks[pid]
    return total / os.sysconf('SC_CLK_TCK')


class CollectionTimer:
    """Times the garbage collector's runs (any thread; each stalls every thread: the GIL)."""

    def __init__(self) -> None:
        """Not yet recording: `start` registers the callback."""
        self.seconds: list[float] = []  # duration of each collection [s]
        self.generations: list[int] = []
        self._start = 0.0

    def __call__(self, phase: str, info: dict[str, int]) -> None:
        """`gc.callbacks` hook."""
        if phase == 'start':
            self._start = time.perf_counter()
        else:
            self.seconds.append(time.perf_counter() - self._start)
            self.generations.append(info['generation'])

    def start(self) -> None:
        """Record from now on."""
        gc.callbacks.append(self)

    def stop(self) -> None:
        """Stop recording."""
        if self in gc.callbacks:
            gc.callbacks.remove(self)

    def summary(self) -> dict[str, float]:
        """Number of full (generation 2) collections and the longest collection [ms]."""
        return {'gc_full': float(sum(1 for g in self.generations if g == 2)),
                'gc_max_ms': max(self.seconds, default=0.0) * 1e3}


class DpControllerFeed:
    """``--commands pid``: the `dp_controller` node answering the node's ``lf_pose``.

    The product's controller with its defaults (scenario supply_closed_loop, the D term on the
    filtered pose difference), in `context`, and a probe on its ``thrust_command``, both spun
    by `answer` between the pose callbacks.
    """

    def __init__(self, context: Context) -> None:
        """Build the controller and the probe in `context` (the predictor node's)."""
        self.controller = DpControllerNode(context=context)
        self._probe = Node('latency_command_probe', context=context)
        self._heard: list[WrenchStamped] = []
        self._probe.create_subscription(WrenchStamped, 'thrust_command', self._heard.append,
                                        command_qos())
        self._executor = SingleThreadedExecutor(context=context)
        self._executor.add_node(self.controller)
        self._executor.add_node(self._probe)
        self._last_stamp: float | None = None
        self.commands = 0

    def answer(self, timeout: float) -> list[WrenchStamped]:
        """Spin until a command is heard (at most `timeout` [s]); the commands with new stamps.

        The controller answers a re-offered estimate again with the same stamp (a lockstep
        simulator's first sample); the predictor would count the repeat out of order, so it is
        passed on once.
        """
        deadline = time.monotonic() + timeout
        while not self._heard and time.monotonic() < deadline:
            self._executor.spin_once(timeout_sec=max(deadline - time.monotonic(), 0.0))
        self._executor.spin_once(timeout_sec=0.0)  # any other command already delivered
        answers = []
        for msg in self._heard:
            stamp = stamp_to_sec(msg.header.stamp)
            if self._last_stamp is None or stamp > self._last_stamp:
                self._last_stamp = stamp
                answers.append(msg)
        self._heard.clear()
        self.commands += len(answers)
        return answers

    def close(self) -> None:
        """Destroy the controller and the probe."""
        self._executor.shutdown()
        self._probe.destroy_node()
        self.controller.destroy_node()


def slow_counts(callbacks: Sequence[float], steps: Sequence[float],
                limit: float = SLOW_CALLBACK) -> tuple[int, int]:
    """(steps, other callbacks) that took over ``limit`` [s]; ``steps`` are among ``callbacks``."""
    slow_steps = sum(1 for elapsed in steps if elapsed > limit)
    return slow_steps, sum(1 for elapsed in callbacks if elapsed > limit) - slow_steps


def measure(rate_hz: float, minutes: float, speed: float,
            freeze: bool = True, commands: str = 'none') -> dict[str, float | str]:
    """Run one input rate; return latency percentiles [ms] and CPU use.

    ``freeze``: freeze the heap after building the node, as the node executables do
    (`nodes.runner.freeze_startup_heap`); False measures the node without it. ``commands``
    (`COMMAND_FEEDS`): 'pid' closes `DpControllerFeed` on the node's output (module docstring).
    """
    if commands not in COMMAND_FEEDS:
        raise ValueError(f'commands must be one of {COMMAND_FEEDS}, got {commands!r}')
    scenario = load_scenario('supply_closed_loop')
    record = simulate(scenario, seed=11, duration=minutes * 60.0)
    times = np.arange(record.t[0], record.t[-1], 1.0 / rate_hz)  # resample to the input rate
    poses = np.column_stack([np.interp(times, record.t, record.measured_pose[:, i])
                             for i in range(3)])
    forces = np.column_stack([np.interp(times, record.t, record.thrust[:, i]) for i in range(3)])
    context = Context()
    rclpy.init(context=context)
    node = PredictorNode(context=context, parameter_overrides=[Parameter('ndof', value=3)])
    controller = DpControllerFeed(context) if commands == 'pid' else None
    use_one_math_thread()  # as the node executables (`nodes.runner`), for good
    if freeze:
        freeze_startup_heap()
    collections = CollectionTimer()
    collections.start()
    idle: list[float] = []
    busy: list[float] = []
    idle_steps: list[float] = []
    busy_steps: list[float] = []
    learning: list[float] = []  # callbacks while the vessel memory's job ran (either kind)
    cpu0, wall0 = _cpu_seconds(), time.monotonic()
    waited = 0.0  # wall time spent hearing estimates (--commands pid): not the node's
    try:
        for k in range(len(times)):
            target = wall0 + waited + (times[k] - times[0]) / speed
            pause = target - time.monotonic()
            if pause > 0:
                time.sleep(pause)
            t = float(times[k])
            node.on_thrust(wrench_to_msg(forces[k], t))
            msg = pose_to_msg(poses[k], t)
            predictor = node.predictor
            training = predictor is not None and not predictor.wait_for_training(0.0)
            samples = node.samples
            state = node.state
            memory_learning = state is not None and state.memory_learning
            start = time.perf_counter()
            node.on_pose(msg)
            elapsed = time.perf_counter() - start
            (busy if training else idle).append(elapsed)
            if memory_learning:
                learning.append(elapsed)
            if node.samples > samples:  # this callback completed a sample: the whole step
                (busy_steps if training else idle_steps).append(elapsed)
                if controller is not None:
                    heard = time.monotonic()
                    answers = controller.answer(timeout=0.05)
                    waited += time.monotonic() - heard
                    for answer in answers:
                        node.on_command(answer)
        predictor = node.predictor
        counters = predictor.counters if predictor is not None else {}
        state = node.state
        read = state.controller_read if state is not None else None
    finally:
        collections.stop()
        if controller is not None:
            controller.close()
        node.destroy_node()
        try_shutdown(context=context)
        if freeze:
            gc.unfreeze()  # the next rate starts from the same heap
    cpu, wall = _cpu_seconds() - cpu0, time.monotonic() - wall0 - waited
    simulated_hours = (times[-1] - times[0]) / 3600.0

    def pct(values: list[float], q: float) -> float:
        return float(np.percentile(values, q) * 1e3) if values else float('nan')
    slow_steps, slow_others = slow_counts(busy, busy_steps)
    return {'rate_hz': rate_hz, 'callbacks': len(times), 'idle_p50_ms': pct(idle, 50),
            'idle_p99_ms': pct(idle, 99), 'busy_p50_ms': pct(busy, 50),
            'busy_p99_ms': pct(busy, 99), 'max_ms': pct(idle + busy, 100),
            'idle_step_p50_ms': pct(idle_steps, 50), 'idle_step_p90_ms': pct(idle_steps, 90),
            'busy_step_p50_ms': pct(busy_steps, 50), 'busy_step_p90_ms': pct(busy_steps, 90),
            'steps_while_training': len(busy_steps), 'busy_slow_steps': slow_steps,
            'busy_slow_others': slow_others,
            'callbacks_while_training': len(busy), 'trainings': counters.get('trainings', 0),
            'learning_p99_ms': pct(learning, 99), 'callbacks_while_learning': len(learning),
            'cpu_s_per_sim_hour': cpu / simulated_hours, 'cpu_share': cpu / wall,
            **collections.summary(), 'commands': commands,
            'commands_sent': controller.commands if controller is not None else 0,
            'controller_read': read.outcome if read is not None else 'none'}


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point (`python -m lf_predictor_ros.benchmark.latency`)."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--minutes', type=float, default=30.0, help='simulated minutes per rate')
    parser.add_argument('--speed', type=float, default=20.0, help='× real time feed')
    parser.add_argument('--rates', type=float, nargs='*', default=[10.0, 100.0])
    parser.add_argument('--no-gc-freeze', dest='freeze', action='store_false',
                        help='do not freeze the heap after building the node (as before 2026-12)')
    parser.add_argument('--commands', choices=COMMAND_FEEDS, default='none',
                        help="'pid': a DP controller answers each lf_pose on thrust_command, so "
                             'the vessel memory reads its gains (module docstring)')
    args = parser.parse_args(argv)
    for rate in args.rates:
        result = measure(rate, args.minutes, args.speed, args.freeze, args.commands)
        print(' '.join(f'{k}={v:.4g}' if isinstance(v, float) else f'{k}={v}'
                       for k, v in result.items()), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
