"""Is lf_odom's twist error its own wave-band content? Band split and a wave-envelope variance.

    OMP_NUM_THREADS=1 python docs/scripts/twist_wave_probe.py rao_supply:231 \
        supply_closed_loop:231 threedof_open_loop:231 onedof_feedback:231

Tuning and lf_odom calibration seeds only (1, 2, 231–236; issue 14, thirty-fourth session). Per
SCENARIO:SEED, the odometry benchmark's fair recording (`suite.make_recording`, 1500 s, no
schedule spread) and `LfStateEstimator` inline with the shipped defaults (the environment
variables TWIST_REFERENCE_CUTOFF and TWIST_COV_SCALE override those two `OdometryParams`
fields); the published twist of each update (valid at the next sample) from the benchmark's
first scored sample on, against the body velocity of the true LF pose. Printed per DOF:

- the joint and per-DOF NEES (`odometry_bench.consistency`);
- the RMS twist error, its parts below and above 0.5 ω0 (zero-phase Butterworth of order 4, ω0
  the recording's median true wave peak frequency), the true velocity's and the published
  twist's content above 0.5 ω0, and the correlation of the error's wave-band part with minus
  the true velocity's (a shared part would show there);
- the wave envelope z = LP_T(HP(twist)²) (causal: order-2 Butterworth high-pass at 0.5 ω0,
  first-order low-pass over T = 5 and 20 s): mean e² / mean z, the correlation of e² with z, and
  the mean NEES with the variance z + the mean square of the error's part below 0.5 ω0 (that
  second part from the truth: an oracle, to see what z alone could carry);
- with ``--blocks``, the per-DOF twist NEES and RMS per 100 s block.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
import os
from pathlib import Path
import sys

import numpy as np
from numpy.typing import NDArray
from scipy import signal

sys.path.insert(0, str(Path(__file__).resolve().parent))
from method_probe import case_arguments  # noqa: E402 - the sibling script
from twin_gain_calibration import CALIBRATION_SEEDS  # noqa: E402 - the sibling script

from lf_predictor_ros.benchmark.estimators import predictor_params  # noqa: E402
from lf_predictor_ros.benchmark.odometry_bench import consistency, true_twist  # noqa: E402
from lf_predictor_ros.benchmark.suite import (  # noqa: E402
    make_recording,
    make_setup,
    scored_start,
)
from lf_predictor_ros.core.lf_state import LfStateEstimator  # noqa: E402
from lf_predictor_ros.core.odometry import OdometryEstimate  # noqa: E402
from lf_predictor_ros.core.odometry_params import OdometryParams  # noqa: E402
from sim_ros.simulation import load_scenario  # noqa: E402

FloatArray = NDArray[np.float64]
DURATION = 1500.0  # [s] as the odometry benchmark's development runs
CUTOFF = 0.5  # × ω0: the band edge between LF and wave motion
ENVELOPE_TIMES = (5.0, 20.0)  # [s]


def _zero_phase(x: FloatArray, h: float, cutoff: float, kind: str) -> FloatArray:
    b, a = signal.butter(4, cutoff / (np.pi / h), kind)
    return np.asarray(signal.filtfilt(b, a, x, axis=0), dtype=np.float64)


def _rms(x: FloatArray) -> str:
    return ' / '.join(f'{v:.4f}' for v in np.sqrt(np.mean(x ** 2, axis=0)))


def _odometry() -> OdometryParams:
    params = OdometryParams()
    cutoff, scale = os.environ.get('TWIST_REFERENCE_CUTOFF'), os.environ.get('TWIST_COV_SCALE')
    if cutoff is not None:
        params = replace(params, twist_reference_cutoff=float(cutoff))
    if scale is not None:
        params = replace(params, twist_cov_scale=float(scale))
    return params


def probe(scenario_name: str, seed: int, blocks: bool) -> None:
    """Print the report of one run."""
    scenario = load_scenario(scenario_name)
    params = predictor_params(scenario, None)
    data = make_recording(scenario, seed, DURATION, make_setup(scenario, seed, params)).data()
    n, h = params.ndof, params.sample_time
    omega = float(np.median(data['omega']))
    begin = scored_start(params, len(data['t']))
    estimator = LfStateEstimator(params, _odometry(), background=False)
    outs: list[OdometryEstimate | None] = []
    try:
        for k in range(len(data['t'])):
            outs.append(estimator.update(float(data['t'][k]), data['y'][k], data['u'][k])[1])
    finally:
        estimator.close()
    keep = [k for k in range(begin - 1, len(outs) - 1) if outs[k] is not None]
    odoms = [out for out in (outs[k] for k in keep) if out is not None]
    idx = np.array(keep) + 1
    twist = np.array([o.twist[:n] for o in odoms])
    cov = np.array([o.twist_cov[:n, :n] for o in odoms])
    true = true_twist(data['truth'], h, n)[idx]
    err = twist - true
    nees = consistency(err, cov)
    edge = CUTOFF * omega
    err_wave = _zero_phase(err, h, edge, 'high')
    true_wave = _zero_phase(true, h, edge, 'high')
    shared = [round(float(np.corrcoef(err_wave[:, i], -true_wave[:, i])[0, 1]), 2)
              for i in range(n)]
    print(f'{scenario_name} {seed} w0 {omega:.3f} twist NEES joint '
          f'{nees["joint"]["mean_nees"]:.2f} per DOF '
          f'{[round(d["mean_nees"], 2) for d in nees["dof"]]}')
    print(f'  error {_rms(err)}; below {CUTOFF} w0 {_rms(_zero_phase(err, h, edge, "low"))}; '
          f'above {_rms(err_wave)}')
    print(f'  above {CUTOFF} w0: true velocity {_rms(true_wave)}, published twist '
          f'{_rms(_zero_phase(twist, h, edge, "high"))}; corr(error, -true) {shared}')
    high = signal.sosfilt(signal.butter(2, edge / (np.pi / h), 'high', output='sos'), twist,
                          axis=0)
    low_part = np.mean(_zero_phase(err, h, edge, 'low') ** 2, axis=0)
    e2 = err ** 2
    for time in ENVELOPE_TIMES:
        z = signal.lfilter([h / time], [1.0, h / time - 1.0], high ** 2, axis=0)
        corr = [round(float(np.corrcoef(e2[:, i], z[:, i])[0, 1]), 2) for i in range(n)]
        with_z = [round(float(np.mean(e2[:, i] / (z[:, i] + low_part[i]))), 2)
                  for i in range(n)]
        ratio = (e2.mean(axis=0) / z.mean(axis=0)).round(2)
        print(f'  envelope T {time:g} s: mean e2 / mean z {ratio} corr(e2, z) {corr} NEES with '
              f'z + low part {with_z}')
    if not blocks:
        return
    stamps = data['t'][idx]
    for start in range(int(stamps[0]) // 100 * 100, int(stamps[-1]), 100):
        inside = (stamps >= start) & (stamps < start + 100)
        if np.count_nonzero(inside) >= 10:
            block = [round(float(np.mean(err[inside, i] ** 2 / cov[inside, i, i])), 2)
                     for i in range(n)]
            print(f'    block {start:5d} NEES {block} error {_rms(err[inside])}')


def main(argv: Sequence[str] | None = None) -> int:
    args = list(argv if argv is not None else sys.argv[1:])
    blocks = '--blocks' in args
    cases = case_arguments([a for a in args if a != '--blocks'],
                           (__doc__ or '').splitlines()[0], CALIBRATION_SEEDS,
                           f'calibration seeds: {CALIBRATION_SEEDS}')
    for scenario, seed in cases:
        probe(scenario, seed, blocks)
    return 0


if __name__ == '__main__':
    sys.exit(main())
