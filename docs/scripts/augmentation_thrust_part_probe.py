"""Diagnostic: how much of each DOF's one-step estimate comes from the thrust, with an LF copy.

    OMP_NUM_THREADS=1 python docs/scripts/augmentation_thrust_part_probe.py \
        threedof_open_loop 579 --lf-augmentation 0 0 0.00025

Simulates the scenario for 3600 s (open loop: the scenario's own thrust, turned to the earth
frame with the measured heading as the predictor does), retrains the default predictor's
network from cold on the data up to three instants (1800, 2700 and 3599 s) with
``lf_augmentation`` off and with the given speeds, and prints per DOF the RMS over the
last 1000 s (every 5th sample) of the estimate's thrust part: the one-step estimate with the
measured thrust history minus the estimate with zero thrust. Nothing in the package changes;
development seeds only.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np
import torch

from lf_predictor_ros.core import regressors
from lf_predictor_ros.core.network import predict_step
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.retraining import Snapshot, run_retraining
from sim_ros.simulation import load_scenario, simulate

INSTANTS = (1800, 2700, 3599)  # [samples] ends of the retraining windows (1 s sample time)
SPAN = 1000  # [samples] the thrust part's RMS is taken over these last samples of the window


def thrust_part(params: PredictorParams, u: np.ndarray, y: np.ndarray, end: int) -> np.ndarray:
    """RMS per DOF of (estimate − estimate without thrust) over the window's last SPAN samples."""
    result = run_retraining(params, Snapshot(u=u[:end + 1], y=y[:end + 1], end_index=end,
                                             segment=1), None, None, None)
    if result.model is None:
        return np.full(y.shape[1], np.nan)
    feedback = np.zeros((params.nfb, y.shape[1]))
    parts = []
    for k in range(end - SPAN, end, 5):
        u_hist, y_hist = u[k - params.nu + 1:k + 1], y[k - params.ny + 1:k + 1]  # oldest first
        parts.append(np.ravel(predict_step(result.model, u_hist, y_hist, feedback))
                     - np.ravel(predict_step(result.model, np.zeros_like(u_hist), y_hist,
                                             feedback)))
    rms: np.ndarray = np.sqrt(np.mean(np.square(parts), axis=0))
    return rms


def main(argv: list[str]) -> int:
    """Print the thrust part per instant, without and with the LF copy."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('scenario')
    parser.add_argument('seed', type=int)
    parser.add_argument('--lf-augmentation', type=float, nargs=3, default=(0.0, 0.0, 0.00025))
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    record = simulate(load_scenario(args.scenario), args.seed, 3600.0)
    u, y = np.array(record.thrust), np.array(record.measured_pose)
    y[:, 2] = np.unwrap(y[:, 2])
    # the forces in the earth frame with each sample's measured heading, u = R(ψ)τ, as the
    # predictor feeds them to its network for 3 DOF (`AdaptivePredictor._force_channels`)
    u = regressors.rotate_blocks(u[:, :3], np.cos(y[:, 2]), np.sin(y[:, 2]))
    for end in INSTANTS:
        for name, speeds in (('off', (0.0, 0.0, 0.0)), ('copy', tuple(args.lf_augmentation))):
            part = thrust_part(PredictorParams(lf_augmentation=speeds), u, y, end)
            print(f'{args.scenario} {args.seed} end {end} s {name:5s} thrust part RMS '
                  + ' / '.join(f'{v:.4g}' for v in part), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
