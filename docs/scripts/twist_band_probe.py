"""Where lf_odom's twist error lies in frequency, and what a notch at ω0 would take (issue 14).

    OMP_NUM_THREADS=1 python docs/scripts/twist_band_probe.py supply_closed_loop 3
    OMP_NUM_THREADS=1 python docs/scripts/twist_band_probe.py rao_supply 3

A diagnostic on one fair recording (development or tuning seed, 1500 s): `LfStateEstimator`
with the shipped defaults replays it open loop; the published twist of each update (valid at
the next sample) is compared with the body velocity of the true LF pose from 481 s on. Printed:
the error's variance per band (Welch, 256 samples; 0–0.2, 0.2–0.35, 0.35–1.4, 1.4–π rad/s)
beside the true velocity's; the RMSE of the twist, of zero, and of the twist after a causal
notch at the scenario's true ω0 (depth `notch_depth`; ζ 0.2 / 0.5 / 1.0, with and without the
targets' low-pass at ω0 + 0.2 rad/s). Nothing is tuned here (docs/BENCHMARKS.md, twentieth
session).
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
import sys

import numpy as np
from scipy import signal
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from method_probe import fair_case  # noqa: E402 - the sibling script

from lf_predictor_ros.core.filters import design_wave_filter  # noqa: E402
from lf_predictor_ros.core.lf_dynamics import body_velocity  # noqa: E402
from lf_predictor_ros.core.lf_state import LfStateEstimator  # noqa: E402
from lf_predictor_ros.core.odometry_params import OdometryParams  # noqa: E402

BANDS = ((0.0, 0.2), (0.2, 0.35), (0.35, 1.4), (1.4, np.pi))  # [rad/s]
SCORED_FROM = 481  # [samples] the benchmark's first scored sample at h = 1 s


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('scenario')
    parser.add_argument('seed', type=int, choices=range(1, 11))
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    scenario, params, setup, recording = fair_case(args.scenario, args.seed, 1500.0)
    data = recording.data()
    t, y, u, truth = data['t'], data['y'], data['u'], data['truth']
    estimator = LfStateEstimator(params, OdometryParams(), background=False)
    try:
        outs = [estimator.update(float(t[k]), y[k], u[k])[1] for k in range(len(t))]
    finally:
        estimator.close()
    eta = np.array(truth, dtype=np.float64)
    eta[:, 2] = np.unwrap(eta[:, 2])
    true_twist = body_velocity(eta, params.sample_time)
    keep = [k for k in range(SCORED_FROM, len(outs) - 1) if outs[k] is not None]
    twist = np.array([outs[k].twist for k in keep])  # type: ignore[union-attr]
    true = true_twist[np.array(keep) + 1]
    error = twist - true
    n = params.ndof
    fs = 1.0 / params.sample_time
    freq, err_psd = signal.welch(error, fs=fs, nperseg=256, axis=0)
    _, true_psd = signal.welch(true, fs=fs, nperseg=256, axis=0)
    omega = 2.0 * np.pi * freq
    for low, high in BANDS:
        band = (omega >= low) & (omega < high)
        err_var = [np.trapezoid(err_psd[band, j], freq[band]) for j in range(n)]
        true_var = [np.trapezoid(true_psd[band, j], freq[band]) for j in range(n)]
        print(f'{args.scenario} {args.seed} {low:.2f}-{high:.2f} rad/s: error variance '
              + ' '.join(f'{v:.2e}' for v in err_var) + '; true velocity '
              + ' '.join(f'{v:.2e}' for v in true_var))
    print('twist RMSE', np.round(np.sqrt(np.mean(error[:, :n] ** 2, axis=0)), 5),
          'zero', np.round(np.sqrt(np.mean(true[:, :n] ** 2, axis=0)), 5),
          f'(ω0 {setup.wave_peak_freq:.3f} rad/s)')
    for zeta in (0.2, 0.5, 1.0):
        for offset in (None, 0.2):
            sos = design_wave_filter(setup.wave_peak_freq, params.sample_time, notch_zeta=zeta,
                                     notch_depth=params.notch_depth, lowpass_offset=offset)
            notched = signal.sosfilt(sos, twist, axis=0)[100:] - true[100:]
            print(f'notch ζ {zeta} low-pass {offset}: RMSE',
                  np.round(np.sqrt(np.mean(notched[:, :n] ** 2, axis=0)), 5))
    return 0


if __name__ == '__main__':
    sys.exit(main())
