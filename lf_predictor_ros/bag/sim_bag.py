"""Write a simulated run to an MCAP bag, as a sensor + actuator log with ground truth.

    python -m lf_predictor_ros.bag.sim_bag supply_closed_loop --duration 10800 -o sim.mcap

Topics: `/thrust` (WrenchStamped), `/truth/lf_pose`, `/truth/pose` and `/measured_pose`
(PoseStamped), one message each per simulator sample, log time = stamp. For replay benchmarks and
tests, and to try `replay` without a vessel. With ``--thrust-command`` (a scenario with a DP
controller) also `/thrust_command` (WrenchStamped), as a DP stack's log has it: at every
controller instant t (each multiple of the predictor's sample time h) the command held during
the period ending at t, stamped t (the commands `odometry_bench`'s loops hand to the vessel
memory; `replay` feeds them to the controller read).

A scenario with a DP controller is recorded with its loop closed on ``--loop-estimator``
(default `observer`: the passive observer with the scenario's tuned gains, fed once per h, as the
benchmark records; `benchmark.recordings.record`), so the thrust does not encode the truth and
`replay`'s metrics against the truth are fair. ``--loop-estimator truth`` is the scenario file's
own loop (its PID on the true LF pose at every sensor sample; the bags of the sessions before
the thirty-first): its thrust leaks the truth, so use it for cost measurements only. The bag's
rosbag2 custom data say which loop it was (`bag.provenance`), and `replay` warns on a leaking one.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
import sys

from lf_predictor_ros.bag.mcap_writer import BagWriter, qos_profile_dict, qos_profiles_yaml
from lf_predictor_ros.bag.provenance import recording_custom_data
from lf_predictor_ros.bag.ros_codec import serialize
from lf_predictor_ros.benchmark.estimators import CAUSAL, make_estimator, predictor_params
from lf_predictor_ros.benchmark.recordings import Provenance, grid_rows, grid_stride, record
from lf_predictor_ros.benchmark.suite import make_setup
from lf_predictor_ros.nodes.conversions import pose_to_msg, wrench_to_msg
from sim_ros.simulation import Scenario, SimRecord, load_scenario

POSE = 'geometry_msgs/msg/PoseStamped'
WRENCH = 'geometry_msgs/msg/WrenchStamped'
SENSOR_QOS = qos_profiles_yaml([qos_profile_dict(reliability='best_effort', depth=5)])
TRUTH_LOOP = 'truth'  # --loop-estimator: the scenario's PID on the true LF pose (leaks)
LOOP_CHOICES = (*CAUSAL, TRUTH_LOOP)
DEFAULT_LOOP = 'observer'


def simulate_recording(scenario: Scenario, seed: int, duration: float | None,
                       loop_estimator: str = DEFAULT_LOOP) -> tuple[SimRecord, Provenance]:
    """The full-rate run of ``scenario`` and where it came from (module docstring).

    `recordings.record` on the predictor's grid: open loop when the scenario has no DP
    controller (``loop_estimator`` unused); otherwise the loop closed on ``loop_estimator`` (a
    causal estimator of `benchmark.estimators`, fed once per h) or, for ``'truth'``, the PID on
    the true LF pose at every sensor sample. Raises ValueError for an unknown estimator or a
    recording loop that diverges.
    """
    if loop_estimator not in LOOP_CHOICES:
        raise ValueError(f'unknown loop estimator {loop_estimator!r}; choose one of '
                         f'{LOOP_CHOICES}')
    setup = make_setup(scenario, seed, predictor_params(scenario))
    truth_fed = loop_estimator == TRUTH_LOOP
    recording = record(scenario, seed, duration, setup.sample_time,
                       None if truth_fed else loop_estimator,
                       lambda name: make_estimator(name, setup).step, truth_fed=truth_fed)
    if recording.full_rate is None:  # record() keeps the run it decimated
        raise RuntimeError('the recording came without its full-rate run')
    return recording.full_rate, recording.provenance


def write_record(path: Path, record: SimRecord, *, duration: float | None = None,
                 truth: bool = True, total_truth: bool = False,
                 provenance: Provenance | None = None,
                 command_stride: int | None = None) -> Path:
    """Thrust, truth and measured pose of each sample (in that order, log time = stamp).

    ``provenance`` goes into the bag's rosbag2 custom data (`bag.provenance`).
    ``command_stride`` (None: no command topic): `/thrust_command` at the grid instants of
    that many sensor samples (`recordings.grid_rows`), after the sample's other messages
    (module docstring).
    """
    commands = set() if command_stride is None else \
        set(range(len(record.t))[grid_rows(command_stride)])
    custom = (None if provenance is None else
              recording_custom_data(provenance.scenario, provenance.seed, provenance.loop,
                                    provenance.estimator))
    with BagWriter(path, custom_data=custom) as writer:
        pose_ch = writer.add_topic('/measured_pose', POSE, SENSOR_QOS)
        thrust_ch = writer.add_topic('/thrust', WRENCH)
        truth_ch = writer.add_topic('/truth/lf_pose', POSE) if truth else -1
        total_ch = writer.add_topic('/truth/pose', POSE) if total_truth else -1
        command_ch = writer.add_topic('/thrust_command', WRENCH) if commands else -1
        for k, t in enumerate(record.t):
            if duration is not None and t > duration:
                break
            ns = int(round(t * 1e9))
            writer.write(thrust_ch, ns, serialize(wrench_to_msg(record.thrust[k], t)))
            if truth:
                writer.write(truth_ch, ns, serialize(pose_to_msg(record.truth_lf_pose[k], t)))
            if total_truth:
                writer.write(total_ch, ns, serialize(pose_to_msg(record.truth_pose[k], t)))
            writer.write(pose_ch, ns, serialize(pose_to_msg(record.measured_pose[k], t)))
            if k in commands:
                writer.write(command_ch, ns,
                             serialize(wrench_to_msg(record.thrust_command[k], t)))
    return path


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point (`python -m lf_predictor_ros.bag.sim_bag`)."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('scenario')
    parser.add_argument('-o', '--output', required=True)
    parser.add_argument('--duration', type=float)
    parser.add_argument('--seed', type=int, help="default: the scenario file's seed")
    parser.add_argument('--loop-estimator', choices=LOOP_CHOICES, default=DEFAULT_LOOP,
                        help='estimator the DP loop is closed on (default observer); truth: '
                        'the PID on the true LF pose, whose thrust leaks it (cost only)')
    parser.add_argument('--thrust-command', action='store_true',
                        help="also write the DP controller's commands on /thrust_command "
                        '(module docstring; a scenario with a DP controller only)')
    args = parser.parse_args(argv)
    scenario = load_scenario(args.scenario)
    seed = scenario.seed if args.seed is None else args.seed
    if args.thrust_command and not scenario.controller.enabled:
        parser.exit(2, f'sim_bag: error: {args.scenario} has no DP controller, so no '
                    'thrust_command: drop --thrust-command\n')
    try:
        record, provenance = simulate_recording(scenario, seed, args.duration,
                                                args.loop_estimator)
    except ValueError as err:
        parser.exit(2, f'sim_bag: error: {err}\n')
    command_stride = grid_stride(scenario, provenance.sample_time) if args.thrust_command \
        else None
    write_record(Path(args.output), record, truth=True, total_truth=True, provenance=provenance,
                 command_stride=command_stride)
    print(f'wrote {len(record.t)} samples ({provenance.label()}) to {args.output}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
