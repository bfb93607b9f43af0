"""Diagnostic: in a turn, which regressors move the network's north/east estimate (issue 13).

    OMP_NUM_THREADS=1 python docs/scripts/turn_part_probe.py rao_supply 638 1140 \
        [--without heading | --without heading-moment]

The seed's fair recording (its DP loop closed on the tuned observer, events delayed as
`method_probe.py` delays them; 1800 s, h = 1 s), the default network retrained from cold on the
data up to ``turn_start`` (its window ends just before the turn), then run one step ahead over
the 10 s blocks from ``turn_start`` − 60 s to ``turn_start`` + 120 s on the recorded data. Per
block, for north and east: the RMS error of the network's one-step estimate against the true LF
pose, and the RMS of three parts of the estimate:
- *heading*: the estimate minus the estimate with every heading lag set to the newest heading
  (what the relative heading regressors add);
- *thrust*: the estimate minus the estimate with every thrust lag set to the window's mean
  thrust (earth frame; what the thrust's change from its mean adds);
- *positions*: the estimate minus the newest measured position, minus the two parts above
  (the north/east lags and the bias; the network is linear, so the parts add up).
Also the heading estimate's error. ``--without`` fits the network with
`heading_column_probe.py`'s patch (the north/east rows without the heading lags, and with
``heading-moment`` without the yaw-moment lags too). Nothing in the package changes;
development seeds only. The recorded turn is the observer loop's, so the heading follows the
setpoint as a well-filtered loop turns; what the parts show is how the network extrapolates
into it.
"""
from __future__ import annotations

import argparse
from pathlib import Path
import sys

import numpy as np
import torch

from lf_predictor_ros.core import regressors
from lf_predictor_ros.core.network import predict_step
from lf_predictor_ros.core.retraining import Snapshot, run_retraining

sys.path.insert(0, str(Path(__file__).resolve().parent))
from own_loop_band_probe import loop_case  # noqa: E402 - the sibling script

BEFORE, AFTER, BLOCK = 60, 120, 10  # [s] blocks around the turn start (h = 1 s)


def main(argv: list[str]) -> int:
    """Print the parts per block (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('scenario')
    parser.add_argument('seed', type=int)
    parser.add_argument('turn_start', type=float, help='[s] the training window ends here')
    parser.add_argument('--without', choices=('heading', 'heading-moment'), default=None,
                        help='north/east rows fitted without these columns (heading_column_probe)')
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    if args.without is not None:
        import heading_column_probe

        from lf_predictor_ros.core import network

        heading_column_probe.DROP_MOMENT = args.without == 'heading-moment'
        setattr(network.NnarmaxNet, 'fit_linear_bypass',  # noqa: B010 - the probe's patch
                heading_column_probe.no_heading_fit)
    case = loop_case(args.scenario, args.seed, 'default')
    params = case.setup.params
    if params.sample_time != 1.0 or params.ndof != 3:
        raise SystemExit('the probe expects a 3-DOF scenario at h = 1 s')
    from lf_predictor_ros.benchmark.suite import make_recording

    data = make_recording(case.scenario, args.seed, 1800.0, case.setup).data()
    t, y, truth = data['t'], np.array(data['y']), np.array(data['truth'])
    y[:, 2] = np.unwrap(y[:, 2])
    truth[:, 2] = np.unwrap(truth[:, 2])
    # earth-frame forces with each sample's measured heading, as the predictor feeds them
    u = regressors.rotate_blocks(np.array(data['u'])[:, :3], np.cos(y[:, 2]), np.sin(y[:, 2]))
    end = int(np.searchsorted(t, args.turn_start))
    result = run_retraining(params, Snapshot(u=u[:end + 1], y=y[:end + 1], end_index=end,
                                             segment=1), None, None, None)
    if result.model is None:
        raise SystemExit(f'no network from the window ending at {t[end]:.0f} s')
    model = result.model
    window = slice(max(0, end - int(params.training_window)), end + 1)
    mean_force = u[window].mean(axis=0)
    feedback = np.zeros((params.nfb, 3))
    print(f'{args.scenario} seed {args.seed}: network trained on the data up to {t[end]:.0f} s '
          f'(north/east rows without: {args.without or "nothing"}); RMS per 10 s block, '
          'north / east [m]')
    print('  block  error N / E    heading err [rad]  heading part N / E  thrust part N / E  '
          'positions part N / E')
    for start in range(end - BEFORE, end + AFTER, BLOCK):
        rows = []
        for k in range(start, start + BLOCK):
            u_hist, y_hist = u[k - params.nu + 1:k + 1], y[k - params.ny + 1:k + 1]
            full = np.ravel(predict_step(model, u_hist, y_hist, feedback))
            level = y_hist.copy()
            level[:, 2] = y_hist[-1, 2]
            no_heading = np.ravel(predict_step(model, u_hist, level, feedback))
            flat = np.broadcast_to(mean_force, u_hist.shape)
            no_thrust = np.ravel(predict_step(model, flat, y_hist, feedback))
            heading_part, thrust_part = full - no_heading, full - no_thrust
            rest = full - y_hist[-1] - heading_part - thrust_part
            rows.append(np.concatenate((full - truth[k + 1], heading_part, thrust_part, rest)))
        rms = np.sqrt(np.mean(np.square(rows), axis=0))
        print(f'{t[start]:7.0f}  {rms[0]:5.3f} / {rms[1]:5.3f}  {rms[2]:9.4f}          '
              f'{rms[3]:5.3f} / {rms[4]:5.3f}      {rms[6]:5.3f} / {rms[7]:5.3f}     '
              f'{rms[9]:5.3f} / {rms[10]:5.3f}', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
