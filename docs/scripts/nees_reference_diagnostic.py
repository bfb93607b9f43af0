"""Where does the pose covariance miss? Errors against the truth and against the reference.

    python docs/scripts/nees_reference_diagnostic.py SCENARIO SEED DURATION   # tuning seeds only

Runs `LfStateEstimator` inline with the shipped defaults, keeps every target window with its
calibration reference (the narrow reference when the targets' notch was widened, else the
targets) and prints, per DOF, averaged over the later two thirds of the windows (samples after
the benchmark's warm-up): var(estimate − truth), var(estimate − reference), var(reference −
truth), cov(estimate − reference, reference − truth), var_r_hat (the removed wave motion and
noise, y − reference, filtered once more with the targets' zero-phase filter: the part of it the
reference lets through; by linearity also the reference's own distortion of the LF motion,
reference minus reference filtered once more), the published pose variance, and the mean errors.
"The truth" is the LF truth the measurement carries (`benchmark.seen_truth`: the twin plus the
wave motion below the wave band, which the thesis vessels have; seventeenth session on).
"""
from __future__ import annotations

import math
import sys
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lf_predictor_ros.benchmark.estimators import predictor_params
from lf_predictor_ros.benchmark.odometry_bench import _wrap_error
from lf_predictor_ros.benchmark.seen_truth import recording_seen_truth
from lf_predictor_ros.benchmark.suite import make_recording, make_setup, scored_start
from lf_predictor_ros.core.filters import zero_phase
from lf_predictor_ros.core.lf_state import LfStateEstimator
from lf_predictor_ros.core.odometry_params import OdometryParams
from lf_predictor_ros.core.retraining import target_filter
from sim_ros.simulation import load_scenario

FloatArray = NDArray[np.float64]
KEYS = ('var_true', 'var_ref', 'var_r', 'cov_eref_r', 'var_r_hat', 'published_var',
        'mean_true', 'mean_r')


def collect(name: str, seed: int, duration: float) -> tuple[Any, dict[str, FloatArray],
                                                             FloatArray, FloatArray, list[Any]]:
    """(params, data, published poses, published variances, target windows) of one run."""
    scenario = load_scenario(name)
    params = predictor_params(scenario, None)
    recording = make_recording(scenario, seed, duration, make_setup(scenario, seed, params))
    data = recording.data()
    seen_truth = recording_seen_truth(recording, params.sample_time)
    if seen_truth is not None:  # score against the LF truth the measurement carries
        data['truth'] = seen_truth
    n, t = params.ndof, data['t']
    pub = np.full((len(t), n), np.nan)
    pvar = np.full((len(t), n), np.nan)
    windows: list[Any] = []
    est = LfStateEstimator(params, OdometryParams(), background=False)
    seen = None
    try:
        for k in range(len(t)):
            out = est.update(float(t[k]), data['y'][k], data['u'][k])[1]
            if out is not None and k + 1 < len(t):  # the estimate of update k is for t[k + 1]
                pub[k + 1] = out.pose[:n]
                pvar[k + 1] = np.diagonal(out.pose_cov)[:n]
            targets = est.predictor.targets
            if targets is None or targets is seen:
                continue
            seen = targets
            values = np.array(targets.values, dtype=np.float64).reshape(len(targets), -1)
            narrow = est.predictor.narrow_reference
            ref = values if narrow is None else np.array(narrow).reshape(len(targets), -1)
            usable = max(3, values.shape[0] - params.transient_samples)
            omega = est.predictor.wave_peak_freq
            windows.append((targets.indices()[:usable].copy(), ref[:usable].copy(),
                            math.nan if omega is None else float(omega)))
    finally:
        est.close()
    return params, data, pub, pvar, windows


def window_stats(params: Any, data: dict[str, FloatArray], pub: FloatArray, pvar: FloatArray,
                 window: Any, begin: int) -> dict[str, FloatArray] | None:
    """The KEYS of one target window (None: fewer than 50 scored samples)."""
    idx, ref, wave_peak_freq = window
    n = params.ndof
    inside = (idx >= 0) & (idx < len(data['t']))
    removed = _wrap_error(data['y'][idx[inside]], ref[inside], n)
    leak = zero_phase(removed, target_filter(params, wave_peak_freq))
    edge = len(leak) // 10
    scored = inside & (idx >= begin)
    i, r = idx[scored], ref[scored]
    ok = np.all(np.isfinite(pub[i]), axis=1)
    i, r = i[ok], r[ok]
    if len(i) < 50:
        return None
    e_true = _wrap_error(pub[i], data['truth'][i], n)
    e_ref = _wrap_error(pub[i], r, n)
    r_err = _wrap_error(r, data['truth'][i], n)
    cov = np.mean((e_ref - e_ref.mean(0)) * (r_err - r_err.mean(0)), axis=0)
    return {'var_true': np.var(e_true, 0), 'var_ref': np.var(e_ref, 0),
            'var_r': np.var(r_err, 0), 'cov_eref_r': cov,
            'var_r_hat': np.var(leak[edge:len(leak) - edge], 0),
            'published_var': np.mean(pvar[i], 0), 'mean_true': np.mean(e_true, 0),
            'mean_r': np.mean(r_err, 0)}


def main(argv: list[str]) -> None:
    name, seed, duration = argv[0], int(argv[1]), float(argv[2])
    params, data, pub, pvar, windows = collect(name, seed, duration)
    begin = scored_start(params, len(data['t']))
    stats = [s for w in windows[len(windows) // 3:]
             if (s := window_stats(params, data, pub, pvar, w, begin)) is not None]
    print(f'{name} seed {seed}: {len(stats)} windows')
    mean = {key: np.mean([s[key] for s in stats], axis=0) for key in KEYS}
    for key in KEYS:
        print(f'  {key:14s} {np.array2string(mean[key], precision=8)}')
    print('  var_true / published', (mean['var_true'] / mean['published_var']).round(2),
          ' var_ref / published', (mean['var_ref'] / mean['published_var']).round(2),
          ' var_true / var_ref', (mean['var_true'] / mean['var_ref']).round(2))


if __name__ == '__main__':
    main(sys.argv[1:])
