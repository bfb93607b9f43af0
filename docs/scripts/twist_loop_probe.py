"""Exploratory: lf_odom's twist-fed loop (``adaptive_odom_d``) over time, with the memory's model.

    OMP_NUM_THREADS=1 python docs/scripts/twist_loop_probe.py rao_swell:1009 \
        --odometry controller_read_stiffness_frame=auto controller_read_fitted_damping=true

The loop is `odometry_bench`'s item 4 loop with the D term from lf_odom's twist (no dropouts).
Printed at every new vessel memory: its dead reckoner, where the thrust gain came from
(``known_gain``; '' = fitted), and the diagonals of G (≈ M⁻¹) and F (≈ −M⁻¹D) as ratios to the
simulator's; then per block of ``--block`` s: the true LF pose's distance from the setpoint (RMS
and largest, m), its heading error (RMS, rad), and the published twist's error against the true
LF body velocity (central differences of the true LF pose; RMS per DOF). Development seeds only.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
import sys
from typing import Any

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
import move_dropout_probe as mdp  # noqa: E402 - the sibling scripts
import vessel_memory_loop_probe as vml  # noqa: E402

from lf_predictor_ros.benchmark import odometry_bench as ob  # noqa: E402
from lf_predictor_ros.benchmark.suite import make_setup, predictor_params  # noqa: E402
from lf_predictor_ros.core.heading import wrap_angle  # noqa: E402
from lf_predictor_ros.core.lf_state import LfStateEstimator  # noqa: E402
from lf_predictor_ros.core.odometry_params import OdometryParams  # noqa: E402
from sim_ros.simulation import load_scenario  # noqa: E402


def true_body_velocity(t: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Body-frame [u, v, r] of an earth-frame pose series (central differences)."""
    heading = np.unwrap(pose[:, 2])
    d_north = np.gradient(pose[:, 0], t)
    d_east = np.gradient(pose[:, 1], t)
    c, s = np.cos(heading), np.sin(heading)
    return np.column_stack((c * d_north + s * d_east, -s * d_north + c * d_east,
                            np.gradient(heading, t)))


def probe(sc: str, seed: int, overrides: dict[str, Any], duration: float, block: float) -> None:
    """Run one development loop and print the memories and the blocks (module docstring)."""
    np.set_printoptions(precision=3, linewidth=160)
    scenario = load_scenario(sc)
    params = predictor_params(scenario)
    n = params.ndof
    true_g, true_f = vml.true_rates(make_setup(scenario, seed, params), n)
    print(f'{sc} {seed} {overrides}', flush=True)
    seen: list[Any] = [None]
    twists: list[tuple[float, np.ndarray]] = []

    class Probe(LfStateEstimator):
        def update(self, t: float, *args: Any, **kwargs: Any) -> Any:
            out = super().update(t, *args, **kwargs)
            if out[1] is not None:
                twists.append((t, np.asarray(out[1].twist, dtype=float)))
            mem = self.memory
            if mem is not None and mem is not seen[0]:
                seen[0] = mem
                print(vml.memory_line(t, mem, true_g, true_f), flush=True)
            return out

    ob.LfStateEstimator = Probe  # type: ignore[attr-defined]
    run = ob._odometry_loop(scenario, seed, duration, params, OdometryParams(**overrides))
    rec = run.record
    offset = rec.truth_lf_pose - scenario.controller.setpoint_series(rec.t)
    offset[:, 2] = wrap_angle(offset[:, 2])
    velocity = true_body_velocity(rec.t, rec.truth_lf_pose)
    tw_t = np.array([t for t, _ in twists])
    tw = np.array([v for _, v in twists])
    true_at = np.column_stack([np.interp(tw_t, rec.t, velocity[:, j]) for j in range(3)])
    est_t = run.estimate_t
    truth_at = np.column_stack([np.interp(est_t, rec.t, rec.truth_lf_pose[:, j])
                                for j in range(3)])
    pose_err = run.estimates - truth_at
    pose_err[:, 2] = wrap_angle(pose_err[:, 2])
    print(f'aborted_at {run.aborted_at}')
    print(' block   dist rms  max   head rms  twist err rms u v r       |twist| max u v r'
          '        pose err rms n e psi')
    for start in np.arange(0.0, rec.t[-1], block):
        k = (rec.t >= start) & (rec.t < start + block)
        j = (tw_t >= start) & (tw_t < start + block)
        dist = np.hypot(offset[k, 0], offset[k, 1])
        err = np.sqrt(np.mean((tw[j, :n] - true_at[j, :n]) ** 2, axis=0)) if j.any() else []
        big = np.max(np.abs(tw[j, :n]), axis=0) if j.any() else []
        i = (est_t >= start) & (est_t < start + block)
        perr = np.sqrt(np.nanmean(pose_err[i, :n] ** 2, axis=0)) if i.any() else []
        print(f'{start:6.0f} {np.sqrt(np.mean(dist ** 2)):8.3f} {dist.max():6.2f} '
              f'{np.sqrt(np.mean(offset[k, 2] ** 2)):8.4f}  {err}  {big}  {perr}')


def main(argv: Sequence[str] | None = None) -> int:
    """CLI: SCENARIO:SEED … [--odometry FIELD=VALUE …] (development seeds only)."""
    parser = argparse.ArgumentParser(description=(__doc__ or '').splitlines()[0])
    parser.add_argument('cases', nargs='+', help='SCENARIO:SEED (development seeds)')
    parser.add_argument('--odometry', nargs='*', default=[], help='OdometryParams FIELD=VALUE')
    parser.add_argument('--duration', type=float, default=3600.0, help='simulated s')
    parser.add_argument('--block', type=float, default=300.0, help='block length [s]')
    args, cases, overrides = mdp.parse_dropout_args(parser, argv)
    torch.set_num_threads(1)
    for scenario, seed in cases:
        probe(scenario, seed, overrides, args.duration, args.block)
    return 0


if __name__ == '__main__':
    sys.exit(main())
