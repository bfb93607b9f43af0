"""Outputs of the predict path saved for a before/after comparison of a refactoring.

    python docs/scripts/bit_identity_check.py before.npz          # at the old commit
    python docs/scripts/bit_identity_check.py after.npz           # at the new one
    python docs/scripts/bit_identity_check.py --compare before.npz after.npz

Runs `LfStateEstimator` inline with the shipped defaults (predictor, the motion gate's
ramp-invariant twin, LM trainings, the odometry) on fair recordings of rao_supply and
supply_closed_loop (seed 3, a development seed since the fifteenth session: 1500 s, h = 1 s),
and the position-reference checks and the averaging aligner on 600 s of 10 Hz poses; saves every
output (lf_pose, odometry pose, twist and covariances; aligned samples). ``--compare`` prints, per
array, whether the two files are equal bit for bit (NaN equal to NaN). Bit-identity holds on one
machine only: another CPU rounds differently (`docs/BENCHMARKS.md`, fourteenth session).
"""
from __future__ import annotations

import argparse

import numpy as np
from numpy.typing import NDArray
import torch

from lf_predictor_ros.benchmark.estimators import predictor_params
from lf_predictor_ros.benchmark.suite import make_recording, make_setup
from lf_predictor_ros.core.alignment import AlignerSettings, InputAligner
from lf_predictor_ros.core.lf_state import LfStateEstimator
from lf_predictor_ros.core.odometry_params import OdometryParams
from lf_predictor_ros.core.reference_checks import ReferenceChecker, ReferenceCheckSettings
from sim_ros.simulation import load_scenario, simulate

FloatArray = NDArray[np.float64]
SEED = 3
WIDTH = 3 + 3 + 9 + 3 + 9  # lf_pose, odometry pose, pose covariance, twist, twist covariance


def estimator_outputs(name: str) -> FloatArray:
    """Every update's lf_pose and odometry estimate (NaN where there is none), (n, WIDTH)."""
    scenario = load_scenario(name)
    params = predictor_params(scenario, None)
    data = make_recording(scenario, SEED, 1500, make_setup(scenario, SEED, params)).data()
    estimator = LfStateEstimator(params, OdometryParams(), background=False)
    rows = np.full((len(data['t']), WIDTH), np.nan)
    try:
        for k in range(len(data['t'])):
            lf_pose, odom = estimator.update(float(data['t'][k]), data['y'][k], data['u'][k])
            if lf_pose is not None:
                rows[k, :3] = lf_pose
            if odom is not None:
                rows[k, 3:] = np.concatenate([odom.pose, odom.pose_cov.ravel(), odom.twist,
                                              odom.twist_cov.ravel()])
    finally:
        estimator.close()
    return rows


def aligner_outputs() -> FloatArray:
    """Aligned samples (t, pose) of checked 10 Hz poses at h = 1 s, (n, 4)."""
    record = simulate(load_scenario('supply_closed_loop'), 4, 600.0)
    aligner = InputAligner(AlignerSettings(sample_time=1.0, average_poses=True))
    checker = ReferenceChecker(ReferenceCheckSettings(), 3)
    samples = []
    for k in range(len(record.t)):
        t, pose = float(record.t[k]), record.measured_pose[k]
        if record.measured_valid[k] and checker.check_pose(t, pose, 0.8).accepted:
            samples += [np.concatenate([[s.t], s.pose]) for s in aligner.add_pose(t, pose)]
    return np.array(samples)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('output', nargs='?', help='.npz file to write')
    parser.add_argument('--compare', nargs=2, metavar=('BEFORE', 'AFTER'))
    args = parser.parse_args()
    if args.compare:
        before, after = (np.load(path) for path in args.compare)
        for key in before:
            print(key, np.array_equal(before[key], after[key], equal_nan=True))
        return
    torch.set_num_threads(1)
    arrays = {name: estimator_outputs(name) for name in ('rao_supply', 'supply_closed_loop')}
    arrays['aligner'] = aligner_outputs()
    np.savez(args.output, **arrays)  # type: ignore[arg-type]  # numpy's stub: allow_pickle
    print({key: value.shape for key, value in arrays.items()})


if __name__ == '__main__':
    main()
