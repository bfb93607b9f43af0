"""Earth- vs body-frame regressors on the tuning seeds (docs/BENCHMARKS.md, issue 13 hyp. 3).

    python docs/scripts/body_frame_probe.py --scenarios rao_supply rao_swell supply_closed_loop \
        --seeds 1 2 --closed-loop --json runs/body_frame_probe.json

Per (scenario, seed): one fair recording (`suite.make_recording`, DP loop closed on the tuned
observer), then the adaptive predictor with ``regressor_frame`` earth and body over the same grid
arrays (`suite.run_open_loop`), scored like `suite.run_case` from the same first sample
(`suite.scored_start`): RMSE per DOF against the true LF pose, over all scored samples and split
into turning (|true LF yaw rate| > ``--turn-rate``, or within ``--turn-margin`` s of such a
sample) and steady. `raw`, `observer` and `linear_limit` on the same recording for reference.
``--closed-loop``: each frame's predictor in its own DP loop (`suite.run_closed_loops`, same
seed). Only the tuning seeds 1 and 2 are accepted; held-out seeds are for `benchmark` only.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import replace
import json
import math
import sys
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lf_predictor_ros.benchmark.baseline_tuning import TUNING_SEEDS
from lf_predictor_ros.benchmark.estimators import EstimatorSetup
from lf_predictor_ros.benchmark.recordings import check_scorable
from lf_predictor_ros.benchmark.suite import (
    make_recording,
    make_setup,
    predictor_params,
    run_closed_loops,
    run_open_loop,
    scored_start,
)
from sim_ros.simulation import load_scenario, simulate

FloatArray = NDArray[np.float64]
FRAMES = ('earth', 'body')
REFERENCES = ('raw', 'observer', 'linear_limit')


def turning_mask(t: FloatArray, truth_yaw: FloatArray, rate: float,
                 margin: float) -> NDArray[np.bool_]:
    """Samples where the true LF heading turns faster than ``rate`` [rad/s], ± ``margin`` s."""
    yaw = np.unwrap(truth_yaw)
    turning = np.abs(np.gradient(yaw, t)) > rate
    out = turning.copy()
    for k in np.flatnonzero(turning):
        out |= np.abs(t - t[k]) <= margin
    return out


def rmse(estimate: FloatArray, truth: FloatArray, keep: NDArray[np.bool_]) -> list[float]:
    """RMSE per DOF over ``keep`` (heading error wrapped); NaN when nothing is kept."""
    if not np.any(keep):
        return [math.nan] * 3
    err = estimate[keep] - truth[keep]
    err[:, 2] = np.angle(np.exp(1j * err[:, 2]))
    return [float(v) for v in np.sqrt(np.mean(err ** 2, axis=0))]


def probe(name: str, seed: int, duration: float, closed_loop: bool, turn_rate: float,
          turn_margin: float) -> dict[str, Any]:
    """Open-loop (and closed-loop) scores of both frames on one (scenario, seed)."""
    scenario = load_scenario(name)
    params = {frame: predictor_params(scenario, {'regressor_frame': frame}) for frame in FRAMES}
    setup = make_setup(scenario, seed, params['earth'])
    recording = make_recording(scenario, seed, duration, setup)
    check_scorable(recording, scenario.name, seed)
    data = recording.data()
    setup = replace(setup, wave_peak_freq=float(np.median(data['omega'])))
    begin = scored_start(params['earth'], len(data['t']))
    t, truth = data['t'][begin:], data['truth'][begin:]
    turning = turning_mask(t, truth[:, 2], turn_rate, turn_margin)
    result: dict[str, Any] = {'scenario': name, 'seed': seed, 'scored_from': float(t[0]),
                              'samples': int(t.size), 'turning_samples': int(turning.sum()),
                              'open_loop': {}, 'closed_loop': {}}
    runs: list[tuple[str, EstimatorSetup, tuple[str, ...]]] = [
        (frame, replace(setup, params=params[frame]), ('adaptive',)) for frame in FRAMES]
    runs.append(('reference', setup, REFERENCES))
    for label, frame_setup, names in runs:
        info: dict[str, Any] = {}
        outputs = run_open_loop(data, frame_setup, names, info, begin)
        for estimator, out in outputs.items():
            key = estimator if label == 'reference' else f'adaptive_{label}'
            result['open_loop'][key] = {
                'all': rmse(out[begin:], truth, np.ones(t.size, dtype=bool)),
                'turning': rmse(out[begin:], truth, turning),
                'steady': rmse(out[begin:], truth, ~turning),
                'counters': info.get(f'{estimator}_counters'),
                'seconds': info.get(f'{estimator}_seconds')}
    if closed_loop and scenario.controller.enabled:
        ideal = simulate(scenario, seed=seed, duration=duration, controller=True,
                         feedback='truth_lf')
        warmup = float(t[0])
        for frame in FRAMES:
            loops, _ = run_closed_loops(scenario, seed, duration,
                                        replace(setup, params=params[frame]), ('adaptive',),
                                        ideal, warmup)
            result['closed_loop'][f'adaptive_{frame}'] = loops['adaptive']
        loops, _ = run_closed_loops(scenario, seed, duration, setup, ('observer', 'raw'), ideal,
                                    warmup, {'observer': recording.loop_run}
                                    if recording.loop_run is not None else None)
        result['closed_loop'].update(loops)
    return result


def _line(result: dict[str, Any]) -> str:
    cells = []
    for key, entry in result['open_loop'].items():
        cells.append(f"{key}: all {np.round(entry['all'], 4).tolist()} turning "
                     f"{np.round(entry['turning'], 4).tolist()} steady "
                     f"{np.round(entry['steady'], 4).tolist()}")
    for key, entry in result['closed_loop'].items():
        power = entry['thrust_wave_band_power']
        cells.append(f"loop {key}: position {entry['position_rmse']:.4f} m, heading "
                     f"{entry.get('heading_rmse', math.nan):.5f} rad, thrust WF power "
                     f"{[f'{v:.3g}' for v in power.values()]}, stable "
                     f"{entry['stability']['stable']}")
    return f"{result['scenario']} seed {result['seed']} (turning {result['turning_samples']}/" \
        f"{result['samples']}):\n  " + '\n  '.join(cells)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: one block per (scenario, seed); optional JSON of everything."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--scenarios', nargs='+',
                        default=['rao_supply', 'rao_swell', 'supply_closed_loop'])
    parser.add_argument('--seeds', nargs='+', type=int, default=list(TUNING_SEEDS))
    parser.add_argument('--duration', type=float, default=1800.0, help='simulated s')
    parser.add_argument('--closed-loop', action='store_true', help='also run the DP loops')
    parser.add_argument('--turn-rate', type=float, default=0.002, help='rad/s (0.11°/s)')
    parser.add_argument('--turn-margin', type=float, default=30.0, help='s')
    parser.add_argument('--json', help='write every number here')
    args = parser.parse_args(argv)
    if any(seed not in TUNING_SEEDS for seed in args.seeds):
        parser.error(f'only the tuning seeds {TUNING_SEEDS}: held-out seeds are for benchmark')
    results = []
    for name in args.scenarios:
        for seed in args.seeds:
            start = time.monotonic()
            results.append(probe(name, seed, args.duration, args.closed_loop, args.turn_rate,
                                 args.turn_margin))
            print(_line(results[-1]), f'({time.monotonic() - start:.0f} s)', flush=True)
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as stream:
            json.dump(results, stream, indent=1)
    return 0


if __name__ == '__main__':
    sys.exit(main())
