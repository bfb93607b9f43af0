"""Benchmark helper (not a test): speed of the core simulation in × real time.

Times `Simulator.step` for the supply vessel with waves (scenario `supply_closed_loop`: motion
superposition, current, wind, drift, thrusters, 10 Hz output) over 3 h simulated time with a
constant command, then the same with the scenario's PID in the loop (`simulate`).
Run: `python -m sim_ros.bench [--hours H]`.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from sim_ros.simulation import Simulator, load_scenario, simulate


def main(argv: list[str] | None = None) -> int:
    """Print simulated/wall-clock ratios for open-loop stepping and the closed loop."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--hours', type=float, default=3.0, help='simulated hours (default 3)')
    parser.add_argument('--scenario', default='supply_closed_loop')
    args = parser.parse_args(argv)
    scenario = load_scenario(args.scenario)
    duration = args.hours * 3600.0
    steps = int(round(duration / scenario.sample_time))
    sim = Simulator(scenario, seed=1)
    command = np.array([1e5, 5e4, 1e6])  # N, N, N·m
    start = time.perf_counter()
    for _ in range(steps):
        sim.step(command)
    wall = time.perf_counter() - start
    print(f'{scenario.name}: {steps} steps of {scenario.sample_time} s, {args.hours} h simulated, '
          f'Simulator.step {wall:.2f} s wall = {duration / wall:.0f}× real time')
    start = time.perf_counter()
    simulate(scenario, seed=1, duration=duration, controller=True)
    wall = time.perf_counter() - start
    print(f'closed loop with PID (simulate): {wall:.2f} s wall = {duration / wall:.0f}× real time')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
