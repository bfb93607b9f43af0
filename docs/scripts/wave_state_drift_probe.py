"""How much of the force-superposition 'LF truth' can no filter of the measurement see?

    python docs/scripts/wave_state_drift_probe.py SCENARIO SEED [SEED ...]   # not 11-20

Under force superposition (`sim_ros.physics.vessels`, `wave_rates_fn`) the wave-frequency state
x_WF is a mass-damper driven by the first-order wave force, with no restoring force, and the
true LF pose is the twin's (`truth_lf_pose`). Any slow part of the WF position is in the measured
pose but not in the truth. (Until the eighteenth session the WF damping followed the LF velocity
above u0 = 0.1 m/s and the RK4 stages missed part of each step's force impulse, so the WF mean
moved; both are fixed, and this probe measures what is left.) A filter of the measurement (notch
+ low-pass, the learned filter, a smoother) passes it as LF motion; only a filter that knows the
model, the thrust and the initial state (the oracle) can split it off.

Per seed: the fair recording (`suite.make_recording`, the loop on the scenario's recording
estimator), the WF motion η_w = truth_pose - truth_lf_pose, its part below the wave band
(`benchmark.seen_truth.seen_lf_truth`: zero-phase Butterworth below 0.25 x the run's lowest ω0),
and the RMSE after the benchmark's scored start of some estimators against the twin (the truth
the benchmark scores) and against twin + that slow part of η_w (what a filter of the
measurement can at best see); with ``--nees``, also the lf_odom pose NEES (shipped
`OdometryParams`, `odometry_bench`'s consistency test) against both. Tuning seeds 1-2 and
development seeds 3-10 only.
"""
from __future__ import annotations

import sys

import numpy as np
from numpy.typing import NDArray

from lf_predictor_ros.benchmark.estimators import predictor_params
from lf_predictor_ros.benchmark.odometry_bench import _tracking_run
from lf_predictor_ros.benchmark.seen_truth import recording_seen_truth
from lf_predictor_ros.benchmark.suite import (
    make_recording,
    make_setup,
    run_open_loop,
    scored_start,
)
from lf_predictor_ros.core.heading import wrap_angle
from lf_predictor_ros.core.odometry_params import OdometryParams
from lf_predictor_ros.core.params import PredictorParams
from sim_ros.simulation import load_scenario

FloatArray = NDArray[np.float64]
ESTIMATORS = ('adaptive', 'cascade', 'observer', 'oracle_kf', 'smoother_tuned')
HELD_OUT = range(11, 21)
DURATION = 1800.0  # s, the benchmark's (`benchmark.SUITE`)


def rmse(estimate: FloatArray, truth: FloatArray) -> FloatArray:
    """Per-DOF RMSE; a third column (heading) is wrapped to (-π, π]."""
    error = estimate - truth
    if error.shape[1] == 3:
        error[:, 2] = wrap_angle(error[:, 2])
    return np.asarray(np.sqrt(np.mean(error ** 2, axis=0)), dtype=np.float64)


def pose_nees(params: PredictorParams, data: dict[str, FloatArray], truth: FloatArray,
              begin: int) -> str:
    """Per-DOF and joint mean pose NEES of lf_odom against ``truth`` (inside its bounds?)."""
    run = _tracking_run(params, OdometryParams(), {**data, 'truth': truth}, begin)
    dofs = ' / '.join(f"{d['mean_nees']:.2f}{'' if d['inside'] else '*'}"
                      for d in run['pose']['dof'])
    return f"{dofs}; joint {run['pose']['joint']['mean_nees']:.2f} (* outside its bounds)"


def probe(name: str, seed: int, nees: bool) -> None:
    scenario = load_scenario(name)
    params = predictor_params(scenario, None)
    setup = make_setup(scenario, seed, params)
    recording = make_recording(scenario, seed, DURATION, setup)
    n = params.ndof
    full_seen = recording_seen_truth(recording, params.sample_time)
    assert full_seen is not None
    data = recording.data()
    slow = full_seen - data['truth']
    slow[:, 2] = wrap_angle(slow[:, 2])
    slow = slow[:, :n]
    begin = scored_start(params, len(recording.t))
    outputs = run_open_loop(data, setup, ESTIMATORS, {}, begin)
    truth, seen = data['truth'][begin:, :n], full_seen[begin:, :n]
    print(f'{name} seed {seed}: slow wave motion RMS {np.sqrt(np.mean(slow[begin:] ** 2, 0))} '
          f'mean {slow[begin:].mean(0)}')
    for est in ESTIMATORS:
        out = outputs[est][begin:, :n]
        print(f'  {est:15s} RMSE vs twin {rmse(out, truth)}  vs twin + slow η_w {rmse(out, seen)}')
    if nees:
        print(f'  lf_odom pose NEES vs twin {pose_nees(params, data, data["truth"], begin)}')
        seen_nees = pose_nees(params, data, full_seen, begin)
        print(f'  lf_odom pose NEES vs twin + slow η_w {seen_nees}')

def main(argv: list[str]) -> None:
    nees = '--nees' in argv
    argv = [a for a in argv if a != '--nees']
    name, seeds = argv[0], [int(s) for s in argv[1:]]
    if any(s in HELD_OUT for s in seeds):
        raise SystemExit('seeds 11-20 are held out: reporting only, not for probes')
    for seed in seeds:
        probe(name, seed, nees)


if __name__ == '__main__':
    main(sys.argv[1:])
