"""Exploratory: how well lf_odom reads the DP controller's implied inertia in a loop, two ways.

    OMP_NUM_THREADS=1 python docs/scripts/controller_read_probe.py rao_supply 771 772 \
        [--duration 1800] [--block-time 300]

Per seed, `odometry_bench`'s lf_odom loop (the predictor's pose to the PID, the D term from
lf_odom's twist, the commands fed as ``thrust_command``) runs once with the shipped defaults.
Every time the vessel memory reads the controller (`lf_state.implied_input_gain`), the same
inputs are also read the other way: as shipped (one read pooled over the history, body-frame
high-pass) and as the forty-seventh session's candidate (``controller_read_block_time`` blocks,
median over the believed ones, earth-frame high-pass). Without dropouts the read does not
change the loop (it only feeds the dead-reckoning model), so one loop serves both.

Each read is compared with what it estimates: Kd² / (4 Kp) of the scenario's own PID
(`sim_ros.simulation.controller_gains`), with the PID's earth-frame Kp turned into the body
frame at the heading of the read's newest estimate (surge cos²ψ Kp_N + sin²ψ Kp_E, sway
sin²ψ Kp_N + cos²ψ Kp_E). Printed per seed: the reads' log10 error per DOF over time; at the
end per way and DOF: the share of reads made ('read'), the median |log10(read / target)| and
the share within ±25 %. Development seeds only, as `method_probe.py`.

Stale since the sixtieth session (the pooled read calls `implied_input_gain` only before the
pool's first full block): it stops with a message instead of printing empty summaries; the
per-block read of today's loop is `controller_read_blocks_probe.py`.
"""
from __future__ import annotations

import argparse
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
from lf_predictor_ros.core.odometry_params import OdometryParams  # noqa: E402
from sim_ros.simulation import controller_gains, load_scenario  # noqa: E402

WAYS = ('pooled', 'blocks')


def target_inertia(kp: np.ndarray, kd: np.ndarray, heading: float, ndof: int) -> np.ndarray:
    """Kd² / (4 Kp) per DOF with the earth-frame Kp seen in the body frame at ``heading``."""
    if ndof == 1:
        return np.array([kd[0] ** 2 / (4.0 * kp[0])])
    c2, s2 = np.cos(heading) ** 2, np.sin(heading) ** 2
    body_kp = np.array([c2 * kp[0] + s2 * kp[1], s2 * kp[0] + c2 * kp[1], kp[2]])
    return kd[:3] ** 2 / (4.0 * body_kp)


def run_seed(scenario_name: str, seed: int, duration: float, block_time: float
             ) -> dict[str, list[np.ndarray | None]]:
    """One loop; per way the log10 read / target per read (None: not read)."""
    scenario = load_scenario(scenario_name)
    params = predictor_params(scenario)
    setup = make_setup(scenario, seed, params)
    gains = controller_gains(scenario, setup.model)
    n = params.ndof
    original = lf_state.implied_input_gain
    errors: dict[str, list[np.ndarray | None]] = {way: [] for way in WAYS}

    def spy(published: Any, times: Any, forces: Any, sample_time: float, *args: Any,
            **kwargs: Any) -> lf_state.ControllerRead:
        read = original(published, times, forces, sample_time, *args, **kwargs)
        if not published:
            return read
        heading = float(published[-1].pose[2]) if n == 3 else 0.0
        target = target_inertia(np.asarray(gains.kp), np.asarray(gains.kd), heading, n)
        line = f'  t {published[-1].stamp:6.0f}'
        for way, settings in zip(WAYS, ((0.0, False), (block_time, True)), strict=True):
            other = original(published, times, forces, sample_time, *settings)
            if other.gain is None:
                errors[way].append(None)
                line += f'  {way} {other.outcome:8s}'
                continue
            error = np.log10(1.0 / np.asarray(other.gain) / target)
            errors[way].append(error)
            line += f'  {way} ' + ' '.join(f'{v:+.2f}' for v in error)
        print(line, flush=True)
        return read

    lf_state.implied_input_gain = spy
    try:
        ob._odometry_loop(scenario, seed, duration, params, OdometryParams())
    finally:
        lf_state.implied_input_gain = original
    if not any(errors.values()):
        raise SystemExit('the spy saw no read: since the sixtieth session the loop reads the '
                         'controller from its pool of blocks (`lf_state.pooled_input_gain`), '
                         'which calls implied_input_gain only before its first full block. Run '
                         'this probe at the commit of its section (docs/BENCHMARKS.md, '
                         'forty-seventh session) or use controller_read_blocks_probe.py')
    return errors


def summary(errors: dict[str, list[np.ndarray | None]]) -> None:
    """Per way and DOF: reads made, median |log10 error|, share within ±25 %."""
    for way in WAYS:
        reads = errors[way]
        made = [e for e in reads if e is not None]
        if not made:
            print(f'{way:7s} no read in {len(reads)} attempts')
            continue
        err = np.abs(np.array(made))
        within = np.mean(err <= np.log10(1.25), axis=0)
        gross = np.mean(err > np.log10(2.0), axis=0)
        print(f'{way:7s} read {len(made)}/{len(reads)}; median |log10| '
              + ' / '.join(f'{v:.3f}' for v in np.median(err, axis=0)) + '; within ±25 % '
              + ' / '.join(f'{v:.2f}' for v in within) + '; off by > 2× '
              + ' / '.join(f'{v:.2f}' for v in gross))


def main(argv: list[str] | None = None) -> int:
    """CLI (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('scenario')
    parser.add_argument('seeds', nargs='+', type=int)
    parser.add_argument('--duration', type=float, default=1800.0)
    parser.add_argument('--block-time', type=float, default=300.0)
    args = parser.parse_args(argv)
    if set(args.seeds) - set(mp.DEVELOPMENT_SEEDS):
        parser.error('development seeds only (held-out seeds: `benchmark`)')
    torch.set_num_threads(1)
    pooled: dict[str, list[np.ndarray | None]] = {way: [] for way in WAYS}
    for seed in args.seeds:
        print(f'{args.scenario} {seed}', flush=True)
        errors = run_seed(args.scenario, seed, args.duration, args.block_time)
        summary(errors)
        for way in WAYS:
            pooled[way].extend(errors[way])
    print(f'{args.scenario} all seeds {args.seeds}')
    summary(pooled)
    return 0


if __name__ == '__main__':
    sys.exit(main())
