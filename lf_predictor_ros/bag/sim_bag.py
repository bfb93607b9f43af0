"""Write a simulated run to an MCAP bag, as a sensor + actuator log with ground truth.

    python -m lf_predictor_ros.bag.sim_bag supply_closed_loop --duration 10800 -o sim.mcap

Topics: `/thrust` (WrenchStamped), `/truth/lf_pose`, `/truth/pose` and `/measured_pose`
(PoseStamped), one message each per simulator sample, log time = stamp. For replay benchmarks and
tests, and to try `replay` without a vessel.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
import sys

from lf_predictor_ros.bag.mcap_writer import BagWriter, qos_profile_dict, qos_profiles_yaml
from lf_predictor_ros.bag.ros_codec import serialize
from lf_predictor_ros.nodes.conversions import pose_to_msg, wrench_to_msg
from sim_ros.simulation import SimRecord, load_scenario, simulate

POSE = 'geometry_msgs/msg/PoseStamped'
WRENCH = 'geometry_msgs/msg/WrenchStamped'
SENSOR_QOS = qos_profiles_yaml([qos_profile_dict(reliability='best_effort', depth=5)])


def write_record(path: Path, record: SimRecord, *, duration: float | None = None,
                 truth: bool = True, total_truth: bool = False) -> Path:
    """Thrust, truth and measured pose of each sample (in that order, log time = stamp)."""
    with BagWriter(path) as writer:
        pose_ch = writer.add_topic('/measured_pose', POSE, SENSOR_QOS)
        thrust_ch = writer.add_topic('/thrust', WRENCH)
        truth_ch = writer.add_topic('/truth/lf_pose', POSE) if truth else -1
        total_ch = writer.add_topic('/truth/pose', POSE) if total_truth else -1
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
    return path


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point (`python -m lf_predictor_ros.bag.sim_bag`)."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('scenario')
    parser.add_argument('-o', '--output', required=True)
    parser.add_argument('--duration', type=float)
    parser.add_argument('--seed', type=int)
    args = parser.parse_args(argv)
    record = simulate(load_scenario(args.scenario), seed=args.seed, duration=args.duration)
    write_record(Path(args.output), record, truth=True, total_truth=True)
    print(f'wrote {len(record.t)} samples to {args.output}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
