"""Does regularizing the sliding linear fit help? Ridge, a prior on the last fit, validation.

    OMP_NUM_THREADS=1 python docs/scripts/ridge_probe.py --scenarios supply_closed_loop \
        onedof_feedback rao_supply threedof_open_loop --seeds 1 2

A diagnostic for issue 13, hypothesis 1 ("regularization chosen by validation"), tuning seeds
only. The shipped predictor is, in effect, a linear ARX refitted every Δ on its window's targets
and predicting one step ahead (`target_fit_probe.py`, "lin sliding wide +h"); this probe refits
that ARX with a penalty α·m·‖c − c₀‖² on the unit-std coefficients c (m rows, the constant
free) and prints the RMSE per DOF against the true LF pose from the benchmark's first scored
sample, and its ratio to plain least squares:

- ``ridge α``: c₀ = 0, α = 1e-4, 1e-3, 1e-2;
- ``prior α``: c₀ = the previous window's coefficients (a memory of the last fit), α = 1e-3,
  1e-2, 0.1;
- ``cv``: ridge with α chosen every Δ from {0, 1e-5, …, 0.1} by the error on the newest 20 %
  of the window when fitted on the older 80 % (then refitted on all).

Nothing is tuned here; the printed numbers are in docs/BENCHMARKS.md (twentieth session).
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
import sys

import numpy as np
from numpy.typing import NDArray

sys.path.insert(0, str(Path(__file__).resolve().parent))

from target_fit_probe import Fit, rmse, sliding, tuning_seed_cli  # noqa: E402 - sibling

from lf_predictor_ros.benchmark.baseline_tuning import (  # noqa: E402
    smoother_settings,
)
from lf_predictor_ros.benchmark.estimators import predictor_params  # noqa: E402
from lf_predictor_ros.benchmark.suite import (  # noqa: E402
    make_recording,
    make_setup,
    scored_start,
)
from sim_ros.simulation import load_scenario  # noqa: E402

FloatArray = NDArray[np.float64]
CV_GRID = (0.0, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1)
VARIANTS = [('ls', 0.0)] + [('ridge', a) for a in (1e-4, 1e-3, 1e-2)] + \
    [('prior', a) for a in (1e-3, 1e-2, 1e-1)] + [('cv', 0.0)]


def penalized_fit(design: FloatArray, goal: FloatArray, alpha: float,
                  prior: FloatArray | None = None) -> FloatArray:
    """Coefficients (unscaled) minimizing ‖X c − y‖² + α m ‖s ∘ c − s ∘ c₀‖² (s: column stds)."""
    rows, columns = design.shape
    scale = np.std(design, axis=0)
    scale[scale == 0.0] = 1.0
    scaled = design / scale
    if alpha <= 0.0:
        coef, *_ = np.linalg.lstsq(scaled, goal, rcond=None)
        return np.asarray(coef / scale[:, None], dtype=np.float64)
    penalty = np.full(columns, alpha * rows)
    penalty[-1] = 0.0  # the constant is not penalized
    rhs = scaled.T @ goal
    if prior is not None:
        rhs = rhs + penalty[:, None] * (prior * scale[:, None])
    coef = np.linalg.lstsq(scaled.T @ scaled + np.diag(penalty), rhs, rcond=None)[0]
    return np.asarray(coef / scale[:, None], dtype=np.float64)


def window_fit(mode: str, alpha: float) -> Fit:
    """The per-window fit of one variant (module docstring), for `target_fit_probe.sliding`."""
    previous: list[FloatArray] = []  # the last window's coefficients (mode 'prior')

    def fit(design: FloatArray, goal: FloatArray) -> FloatArray:
        penalty = alpha
        if mode == 'cv':
            split = int(0.8 * design.shape[0])
            errors = [float(np.mean((design[split:] @ penalized_fit(design[:split], goal[:split],
                                                                    a) - goal[split:]) ** 2))
                      for a in CV_GRID]
            penalty = CV_GRID[int(np.argmin(errors))]
        prior = previous[-1] if mode == 'prior' and previous else None
        coef = penalized_fit(design, goal, penalty if mode != 'prior' or prior is not None
                             else 0.0, prior)
        previous[:] = [coef]
        return coef

    return fit


def run(scenario_name: str, seed: int) -> None:
    """Print one line per variant (module docstring)."""
    scenario = load_scenario(scenario_name)
    params = predictor_params(scenario)
    setup = make_setup(scenario, seed, params)
    data = make_recording(scenario, seed, 1800.0, setup).data()
    y, u, truth = data['y'], data['u'], data['truth']
    y_c, truth_c = np.array(y, dtype=np.float64), np.array(truth, dtype=np.float64)
    y_c[:, 2], truth_c[:, 2] = np.unwrap(y[:, 2]), np.unwrap(truth[:, 2])
    start = scored_start(params, len(y))
    settings = dict(smoother_settings({}, 'smoother_targets', params),
                    notch_zeta=params.notch_zeta_broadband)
    base: list[float] | None = None
    for mode, alpha in VARIANTS:
        estimate = sliding(y_c, u, params, setup.wave_peak_freq, settings, ahead=1,
                           fit=window_fit(mode, alpha))
        values = rmse(estimate[:-1], truth_c[1:], params.ndof, start)
        base = values if base is None else base
        print(f'{scenario_name:20s} {seed} {mode:6s} {alpha:<7g} '
              + ' '.join(f'{v:.4f}' for v in values) + '  ratio '
              + ' '.join(f'{v / b:.3f}' for v, b in zip(values, base, strict=True)), flush=True)


def main(argv: Sequence[str] | None = None) -> int:
    return tuning_seed_cli(__doc__, run, argv)


if __name__ == '__main__':
    sys.exit(main())
