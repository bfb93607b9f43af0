"""Exploratory: the controller read per block in a DP loop, and what a manoeuvre does to it.

    OMP_NUM_THREADS=1 python docs/scripts/controller_read_blocks_probe.py rao_supply:1602 \
        rao_swell:1602

Per case, `odometry_bench`'s lf_odom loop (the predictor's pose to the PID, the D term from
lf_odom's twist, the PID's commands fed as ``thrust_command``; 1800 s, no dropout) runs once with
the shipped defaults. Every block the vessel memory reads (`controller_gains.
read_controller_gains`, called from `lf_state`) is recorded once with the estimates it was read
on. Printed per block: whether its estimates manoeuvred (`lf_state.block_manoeuvred`), Kp and Kd
against the scenario's PID (`sim_ros.simulation.controller_gains`; the earth-frame Kp seen in
the body frame at the block's headings, cos²ψ Kp_N + sin²ψ Kp_E in surge), the implied inertia
Kd² / (4 Kp) against the PID's own (the read's target: the PID takes the damping off its Kd, so
the target is not the vessel's inertia), R² and T_v. Then per DOF the median of that inertia
ratio over the believed blocks (`ControllerGains.believed` at `MAX_NATURAL_FREQ_RATIO` × the
scenario's ω0), all blocks and the holding blocks only: what `controller_read_holding_only`
would read from the same blocks (without dropouts the read does not change the loop: it only
feeds the dead reckoning). Development seeds only, as `method_probe.py`.
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
import method_probe as mp  # noqa: E402 - the sibling script

from lf_predictor_ros.benchmark import odometry_bench as ob  # noqa: E402
from lf_predictor_ros.benchmark.suite import make_setup, predictor_params  # noqa: E402
from lf_predictor_ros.core import lf_state  # noqa: E402
from lf_predictor_ros.core.controller_gains import (  # noqa: E402
    MAX_NATURAL_FREQ_RATIO,
    ControllerGains,
    read_controller_gains,
)
from lf_predictor_ros.core.odometry_params import OdometryParams  # noqa: E402
from sim_ros.simulation import controller_gains, load_scenario  # noqa: E402

DURATION = 1800.0  # [s] simulated per loop


def blocks_of_loop(scenario_name: str, seed: int) -> tuple[list[tuple[np.ndarray,
                                                                       ControllerGains]], Any,
                                                             float, float]:
    """(every block read once: (its estimates, its gains), the PID's gains, h, ω0)."""
    scenario = load_scenario(scenario_name)
    params = predictor_params(scenario)
    setup = make_setup(scenario, seed, params)
    original = read_controller_gains
    seen: dict[tuple[int, bytes], tuple[np.ndarray, ControllerGains]] = {}

    def spy(poses: Any, twists: Any, forces: Any, sample_time: float,
            **kwargs: Any) -> ControllerGains:
        gains = original(poses, twists, forces, sample_time, **kwargs)
        block = np.asarray(poses, dtype=np.float64)[kwargs.get('lead', 0):]
        seen.setdefault((block.shape[0], block[0].tobytes()), (block.copy(), gains))
        return gains

    setattr(lf_state, 'read_controller_gains', spy)  # noqa: B010 - the name lf_state calls
    try:
        ob._odometry_loop(scenario, seed, DURATION, params, OdometryParams())
    finally:
        setattr(lf_state, 'read_controller_gains', original)  # noqa: B010
    return list(seen.values()), controller_gains(scenario, setup.model), params.sample_time, \
        float(setup.wave_peak_freq)


def ratios(block: np.ndarray, gains: ControllerGains, pid: Any
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Kp, Kd, Kd² / (4 Kp)) of the read against the PID's, per DOF."""
    kp, kd = np.asarray(pid.kp, dtype=np.float64), np.asarray(pid.kd, dtype=np.float64)
    n = block.shape[1]
    if n == 3:
        c2, s2 = np.mean(np.cos(block[:, 2]) ** 2), np.mean(np.sin(block[:, 2]) ** 2)
        kp = np.array([c2 * kp[0] + s2 * kp[1], s2 * kp[0] + c2 * kp[1], kp[2]])
    kp, kd = kp[:n], kd[:n]
    inertia = (gains.damping ** 2 / (4.0 * gains.stiffness)) / (kd ** 2 / (4.0 * kp))
    return gains.stiffness / kp, gains.damping / kd, inertia


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('cases', nargs='+', help='scenario:seed')
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    for case in args.cases:
        name, seed_text = case.split(':')
        seed = int(seed_text)
        if seed not in mp.DEVELOPMENT_SEEDS:
            parser.error(f'development seeds only, got {seed}')
        blocks, pid, sample_time, omega = blocks_of_loop(name, seed)
        print(f'{name} {seed}: {len(blocks)} blocks', flush=True)
        believed_all, believed_holding = [], []
        for block, gains in blocks:
            moved = lf_state.block_manoeuvred(block, sample_time)
            kp, kd, inertia = ratios(block, gains, pid)
            believed = gains.believed(MAX_NATURAL_FREQ_RATIO * omega)
            ratio = np.where(believed, inertia, np.nan)
            believed_all.append(ratio)
            if not moved:
                believed_holding.append(ratio)
            print(f'  n {block.shape[0]:4d} manoeuvred {moved!s:5s} Kp {np.round(kp, 3)} '
                  f'Kd {np.round(kd, 3)} M {np.round(inertia, 3)} '
                  f'R2 {np.round(gains.r_squared, 3)} T_v {gains.difference_time:.2f} '
                  f'believed {believed.astype(int)}', flush=True)
        for label, rows in (('all blocks', believed_all), ('holding only', believed_holding)):
            median = np.nanmedian(np.array(rows), axis=0) if rows else None
            text = 'none' if median is None else ' '.join(f'{v:.3f}' for v in median)
            print(f'  {name} {seed} median M / target, {label}: {text}', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
