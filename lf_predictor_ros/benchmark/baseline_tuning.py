"""Tuning search for the classical baselines, per scenario, on the tuning seeds only.

    OMP_NUM_THREADS=1 python -m lf_predictor_ros.benchmark.baseline_tuning
        [--scenarios NAME ...] [--seeds 1 2] [--duration S] [--out config/baselines]

Why: a baseline tuned worse than the method makes any comparison meaningless. Every baseline of
the benchmark (`benchmark.estimators`) is tuned here for each scenario, on the **tuning seeds 1
and 2 only** (seeds >= 3 are refused: the held-out seeds 11–20 are for reporting), and the
result is written to ``config/baselines/<scenario>.yaml`` with the command that produced it.

**Data (no leaks).** Open-loop scenarios are simulated as they are (`sim_ros.simulation.simulate`
via `recordings.record`). Scenarios with ``controller.enabled`` are recorded with the DP loop
closed on a realistic causal estimator, never on the true LF pose: the passive observer with the
true M, D and ω0 and the fixed gains `RECORDING_OBSERVER` (the review's retuning of the old
defaults: K3, K4 ×10, ωc = 1.01 ω0, ζn = 2, T = 10⁴ s; fixed, so the recording does not depend
on the search), fed one interval-mean pose per h (`recordings.record`, `recordings.GridInput`).
Every estimator runs on the grid arrays h (the predictor's sample time) as the benchmark runs it.

**Score (open loop).** Per seed and DOF the RMSE against ``truth_lf_pose`` after the suite's
warm-up (first training plus two retraining periods, at most half the record), divided by the raw
measurement's RMSE on that DOF; the score is the mean over DOFs (so yaw counts as much as north)
and over the seeds. Lower is better; 1 is the raw measurement.

**Searches.**

1. ``cascade`` (RMSE-optimal): grid `CASCADE_GRID` over notch ζ, notch depth and the low-pass
   (none, or order 1|2 at ω0 + offset), then a coordinate refinement of the continuous values
   (multiplicative steps, halved when a pass gains nothing). Scenarios whose ω0 changes inside the
   tuning record are run through the streaming filter (every retune as in the benchmark) on the
   coarse `COARSE_CASCADE_GRID` without refinement (a retune per sample costs ~0.4 ms); with a
   constant ω0 the filter is run vectorized (`cascade_outputs`, identical to the streaming
   `CascadeFilter`: tested).
2. ``cascade_loop_safe``: the same family chosen in closed loop (scenarios with a controller):
   `simulate_in_loop` with the scenario's PID run once per h on the cascade's output (fed as the
   benchmark feeds it), for ~16 candidates (the RMSE-optimal point, the default, the best two
   open-loop points of every low-pass option). Among the candidates that are stable on every seed
   (`stability.assess`: bounded, no limit cycle; bounds and forced-response reference from the
   recording loop on the observer, not from a loop on the truth) and whose position RMSE (and
   3 DOF heading RMSE) is ≤ `LOOP_RMSE_FACTOR` × the best candidate's, the one with the least
   thrust wave-band power (`evaluation.loop_metrics`, per DOF divided by the raw-measurement
   loop's, mean over DOFs and seeds). Scenarios without a controller: = ``cascade`` (noted).
3. ``observer``: coordinate descent over the discrete grids `OBSERVER_GRID` (K3 scale, K4 scale,
   ωc/ω0, ζn, bias time T) from `RECORDING_OBSERVER`, with the true model. ``observer_mistuned``
   is not tuned: the benchmark builds it from the same entry (`make_observer(..., mistuned=True)`).
4. ``smoother_targets``: the predictor's own target settings (`PredictorParams` notch_zeta,
   notch_depth, lowpass_offset), recorded, nothing tuned; ``smoother_tuned``: grid + refinement
   as the cascade (the zero-phase smoother at the median ω0 of the record, as the benchmark).

**Schema** of ``config/baselines/<scenario>.yaml`` (a header comment holds the command, date,
seeds, grids and scores; every entry is the keyword dict its builder takes):

```yaml
cascade:            {notch_zeta: float, notch_depth: float, lowpass_offset: float | null,
                     lowpass_order: 1 | 2}          # CascadeFilter(ndof, h, w0, **cascade)
cascade_loop_safe:  {same keys as cascade}
observer:           {k3_scale: float, k4_scale: float, cutoff_ratio: float,
                     relative_damping: float, bias_time: float}   # make_observer
                    # optional explicit gains instead of the scales: k3: [..], k4: [..] (per DOF)
smoother_targets:   {notch_zeta, notch_depth, lowpass_offset}   # smooth_poses(..., **entry)
smoother_tuned:     {notch_zeta, notch_depth, lowpass_offset, lowpass_order}
tuning:             {command, date, seeds, duration, scores ...}  # provenance, not read back
```

The observer scales multiply the suite's bias-gain rule (`observer_base_gains`): K4 = 0.1 ·
diag(M) · g/L and K3 = 0.1 · √(g/L) · K4 with the supply vessel's L = 76.2 m for every vessel
(M the mass matrix the observer assumes, so the mistuned observer's gains follow its M ×1.3 as
before). A missing file gives `default_config()`: the untuned classical settings the benchmark
used before this search (cascade ζ 0.5, depth 0.05, low-pass ω0 + 0.2; observer scales 1,
ωc = 1.2 ω0, ζn = 1, T = 1000 s; smoother_targets from `PredictorParams`; smoother_tuned at the
filter defaults), flagged by ``tuning: {source: defaults}``.

Builders for the estimator factory: `make_cascade`, `make_observer`, `smoother_settings`;
`load_baseline_config` reads a scenario's file.
"""
from __future__ import annotations

import argparse
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
import datetime
import itertools
import math
import os
from pathlib import Path
import sys
import textwrap
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from lf_predictor_ros.benchmark import recordings, stability
from lf_predictor_ros.benchmark.recordings import check_scorable, grid_stride, record
from lf_predictor_ros.core.baselines.cascade import CascadeFilter
from lf_predictor_ros.core.baselines.observer import PassiveObserver
from lf_predictor_ros.core.baselines.smoother import smooth_poses
from lf_predictor_ros.core.evaluation import DEFAULT_WAVE_BAND, DOF_NAMES, LoopRun, loop_metrics
from lf_predictor_ros.core.filters import (
    DEFAULT_LOWPASS_OFFSET,
    DEFAULT_LOWPASS_ORDER,
    DEFAULT_NOTCH_DEPTH,
    DEFAULT_NOTCH_ZETA,
    design_wave_filter,
)
from lf_predictor_ros.core.heading import wrap_angle
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.retraining import first_training_samples
from sim_ros.physics.vessels import GRAVITY, SUPPLY_LENGTH, LinearModel
from sim_ros.simulation import (
    Scenario,
    Simulator,
    available_scenarios,
    load_scenario,
)

FloatArray = NDArray[np.float64]
Point = dict[str, Any]

REPO_ROOT = Path(__file__).resolve().parents[2]
CONFIG_DIR = REPO_ROOT / 'config' / 'baselines'
MODULE = 'lf_predictor_ros.benchmark.baseline_tuning'
TUNING_SEEDS = (1, 2)
OBSERVER_HEADING_RESOLUTION = 1e-3  # [rad] cached R(ψ) transitions (PassiveObserver), gyro σ
ENTRIES = ('cascade', 'cascade_loop_safe', 'observer', 'smoother_targets', 'smoother_tuned')
CASCADE_KEYS = ('notch_zeta', 'notch_depth', 'lowpass_offset', 'lowpass_order')
OBSERVER_KEYS = ('k3_scale', 'k4_scale', 'cutoff_ratio', 'relative_damping', 'bias_time', 'k3',
                 'k4', 'wave_damping')
CONSTANT_OMEGA_DURATION = 1800.0  # [s] default tuning record, constant ω0 (the loop length)
VARYING_OMEGA_DURATION = 7200.0  # [s] default when ω0 changes: covers the first change
LOOP_RMSE_FACTOR = 1.1  # loop-safe: station keeping within this × the best candidate's
LOOP_CANDIDATES_PER_LOWPASS = 2

CASCADE_DEFAULT: Point = {'notch_zeta': DEFAULT_NOTCH_ZETA, 'notch_depth': DEFAULT_NOTCH_DEPTH,
                          'lowpass_offset': DEFAULT_LOWPASS_OFFSET,
                          'lowpass_order': DEFAULT_LOWPASS_ORDER}
OBSERVER_DEFAULT: Point = {'k3_scale': 1.0, 'k4_scale': 1.0, 'cutoff_ratio': 1.2,
                           'relative_damping': 1.0, 'bias_time': 1000.0}
RECORDING_OBSERVER: Point = {'k3_scale': 10.0, 'k4_scale': 10.0, 'cutoff_ratio': 1.01,
                             'relative_damping': 2.0, 'bias_time': 1.0e4}
# low-pass options: (offset [rad/s] or None for none, order)
LOWPASS_OPTIONS: tuple[tuple[float | None, int], ...] = (
    (None, 2), (0.1, 1), (0.3, 1), (1.0, 1), (0.1, 2), (0.3, 2), (1.0, 2))
CASCADE_GRID: dict[str, Sequence[Any]] = {
    'notch_zeta': (0.05, 0.1, 0.2, 0.35, 0.5, 0.8, 1.2),
    'notch_depth': (0.0, 0.02, 0.05, 0.1, 0.2, 0.4),
    'lowpass': LOWPASS_OPTIONS,
}
COARSE_CASCADE_GRID: dict[str, Sequence[Any]] = {
    'notch_zeta': (0.1, 0.2, 0.5),
    'notch_depth': (0.05, 0.2),
    'lowpass': ((None, 2), (0.3, 1), (0.3, 2)),
}
OBSERVER_GRID: dict[str, Sequence[float]] = {
    'k4_scale': (1.0, 3.0, 10.0, 30.0, 100.0),
    'k3_scale': (1.0, 3.0, 10.0, 30.0, 100.0),
    'cutoff_ratio': (1.01, 1.05, 1.1, 1.2),
    'relative_damping': (0.5, 1.0, 2.0, 4.0),
    'bias_time': (1.0e3, 1.0e4, 1.0e5),
}
OBSERVER_PASSES = 2
# refinement: multiplicative first step per key (halved in log when a pass gains nothing)
REFINE_STEPS = {'notch_zeta': 1.3, 'notch_depth': 1.5, 'lowpass_offset': 1.4}
REFINE_SHRINKS = 2
REFINE_BOUNDS = {'notch_zeta': (0.02, 2.0), 'notch_depth': (0.0, 0.9),
                 'lowpass_offset': (0.03, 3.0)}


# ------------------------------------------------------------------------------ config & builders
def default_config(params: PredictorParams | None = None) -> dict[str, Any]:
    """The untuned classical settings (module docstring), ``tuning: {source: defaults}``."""
    p = PredictorParams() if params is None else params
    return {
        'cascade': dict(CASCADE_DEFAULT),
        'cascade_loop_safe': dict(CASCADE_DEFAULT),
        'observer': dict(OBSERVER_DEFAULT),
        'smoother_targets': {'notch_zeta': p.notch_zeta, 'notch_depth': p.notch_depth,
                             'lowpass_offset': p.lowpass_offset},
        'smoother_tuned': dict(CASCADE_DEFAULT),
        'tuning': {'source': 'defaults'},
    }


def config_path(scenario: str, directory: str | os.PathLike[str] | None = None) -> Path:
    """``<directory>/<scenario>.yaml``, by default found like the scenarios.

    Without a directory: config/baselines of the source tree, else of the installed package
    (share/lf_predictor_ros/config/baselines).
    """
    if directory is not None:
        return Path(directory) / f'{scenario}.yaml'
    from sim_ros.simulation import scenario_search_dirs

    candidates = [CONFIG_DIR / f'{scenario}.yaml'] + [
        d.parent / 'baselines' / f'{scenario}.yaml' for d in scenario_search_dirs()]
    return next((c for c in candidates if c.is_file()), candidates[0])


def load_baseline_config(scenario: str,
                         directory: str | os.PathLike[str] | None = None) -> dict[str, Any]:
    """The tuned baseline settings of ``scenario`` (schema: module docstring).

    Entries missing from the file (or the whole file) fall back to `default_config()`; a
    missing file is not an error (the result says ``tuning: {source: defaults}``).
    """
    import yaml

    config = default_config()
    path = config_path(scenario, directory)
    if not path.is_file():
        return config
    with open(path, encoding='utf-8') as stream:
        data = yaml.safe_load(stream) or {}
    if not isinstance(data, Mapping):
        raise ValueError(f'{path} must hold a mapping of baseline entries {ENTRIES}')
    for key, value in data.items():
        if key in ENTRIES and not isinstance(value, Mapping):
            raise ValueError(f'{path}: {key} must be a mapping of keyword arguments, got '
                             f'{value!r}')
        config[key] = dict(value) if isinstance(value, Mapping) else value
    return config


def _plain(value: Any) -> Any:
    """YAML-safe plain Python (floats rounded to 6 significant digits)."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [_plain(v) for v in value]
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        number = float(value)
        return number if not math.isfinite(number) or number == 0.0 else \
            float(f'{number:.6g}')
    return value


def write_baseline_config(path: str | os.PathLike[str], config: Mapping[str, Any],
                          header: Iterable[str] = ()) -> Path:
    """Write ``config`` as YAML, ``header`` lines (wrapped at 99) as a leading comment."""
    import yaml

    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    lines = [f'# {part}'.rstrip() for line in header
             for part in textwrap.wrap(line, 97, subsequent_indent='    ', break_on_hyphens=False,
                                       drop_whitespace=True) or ['']]
    body = yaml.safe_dump(_plain(dict(config)), sort_keys=False, width=99,
                          default_flow_style=None, allow_unicode=True)
    target.write_text('\n'.join([*lines, body]) if lines else body, encoding='utf-8')
    return target


def _cascade_kwargs(config: Mapping[str, Any]) -> dict[str, Any]:
    unknown = sorted(set(config) - set(CASCADE_KEYS))
    if unknown:
        raise ValueError(f'unknown cascade setting(s) {unknown}; allowed: {CASCADE_KEYS}')
    out = {**CASCADE_DEFAULT, **config}
    offset = out['lowpass_offset']
    return {'notch_zeta': float(out['notch_zeta']), 'notch_depth': float(out['notch_depth']),
            'lowpass_offset': None if offset is None else float(offset),
            'lowpass_order': int(out['lowpass_order'])}


def make_cascade(config: Mapping[str, Any], ndof: int, sample_time: float,
                 wave_peak_freq: float) -> CascadeFilter:
    """`CascadeFilter` from a ``cascade``/``cascade_loop_safe`` entry ({} → defaults)."""
    return CascadeFilter(ndof, sample_time, wave_peak_freq, **_cascade_kwargs(config))


def observer_base_gains(mass: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(K3, K4) diagonals (3,) of the suite's rule for mass matrix M (module docstring)."""
    k4 = 0.1 * np.diag(np.asarray(mass, dtype=np.float64)) * GRAVITY / SUPPLY_LENGTH
    k3 = 0.1 * math.sqrt(GRAVITY / SUPPLY_LENGTH) * k4
    return np.asarray(k3, dtype=np.float64), np.asarray(k4, dtype=np.float64)


def make_observer(config: Mapping[str, Any], model: LinearModel, ndof: int, sample_time: float,
                  wave_peak_freq: float, mistuned: bool = False) -> PassiveObserver:
    """`PassiveObserver` from an ``observer`` entry ({} → defaults) and the true model.

    ``mistuned``: the same entry with M ×1.3, D ×0.7 and ω0 ×1.2 (`estimators.MISTUNE_*`); the
    caller retuning ω0 later must scale it too (``StreamingEstimator(freq_factor=…)``).
    """
    from lf_predictor_ros.benchmark.estimators import MISTUNE_DAMPING, MISTUNE_FREQ, MISTUNE_MASS

    unknown = sorted(set(config) - set(OBSERVER_KEYS))
    if unknown:
        raise ValueError(f'unknown observer setting(s) {unknown}; allowed: {OBSERVER_KEYS}')
    tuning = {**OBSERVER_DEFAULT, **config}
    mass = np.asarray(model.mass, dtype=np.float64) * (MISTUNE_MASS if mistuned else 1.0)
    damping = np.asarray(model.damping, dtype=np.float64) * (MISTUNE_DAMPING if mistuned else 1.0)
    base_k3, base_k4 = observer_base_gains(mass)
    k3 = np.asarray(tuning['k3'], dtype=np.float64) if 'k3' in config else \
        float(tuning['k3_scale']) * base_k3
    k4 = np.asarray(tuning['k4'], dtype=np.float64) if 'k4' in config else \
        float(tuning['k4_scale']) * base_k4
    m = mass[:ndof, :ndof] if ndof == 3 else float(mass[0, 0])
    d = damping[:ndof, :ndof] if ndof == 3 else float(damping[0, 0])
    omega0 = wave_peak_freq * (MISTUNE_FREQ if mistuned else 1.0)
    return PassiveObserver(ndof, sample_time, omega0, m, d, k3=np.atleast_1d(k3)[:ndof],
                           k4=np.atleast_1d(k4)[:ndof],
                           wave_damping=float(tuning.get('wave_damping', 0.1)),
                           relative_damping=float(tuning['relative_damping']),
                           cutoff_ratio=float(tuning['cutoff_ratio']),
                           bias_time=float(tuning['bias_time']),
                           heading_resolution=OBSERVER_HEADING_RESOLUTION)


def smoother_settings(config: Mapping[str, Any], which: str,
                      params: PredictorParams | None = None) -> dict[str, Any]:
    """`smooth_poses` keyword arguments of ``which`` ('smoother_targets' | 'smoother_tuned').

    ``smoother_targets`` is the predictor's own target filter: taken from ``params`` when given
    (the settings actually in use), else from the config.
    """
    if which not in ('smoother_targets', 'smoother_tuned'):
        raise ValueError(f"which must be 'smoother_targets' or 'smoother_tuned', got {which!r}")
    if which == 'smoother_targets' and params is not None:
        return {'notch_zeta': params.notch_zeta, 'notch_depth': params.notch_depth,
                'lowpass_offset': params.lowpass_offset}
    entry = config.get(which) or default_config(params)[which]
    return _cascade_kwargs(entry)


# ------------------------------------------------------------------------------------- search
@dataclass(frozen=True)
class Evaluation:
    """One scored point: normalized score (lower better) and RMSE per DOF (mean over seeds)."""

    point: Point
    score: float
    rmse: tuple[float, ...] = ()


def point_key(point: Mapping[str, Any]) -> tuple[tuple[str, Any], ...]:
    """Hashable, order-independent key of a point (floats rounded to 9 significant digits)."""
    return tuple(sorted((k, float(f'{v:.9g}') if isinstance(v, float) else v)
                        for k, v in point.items()))


class CachedObjective:
    """An objective point → `Evaluation`, each distinct point evaluated once."""

    def __init__(self, evaluate: Callable[[Point], Evaluation]) -> None:
        """Wrap ``evaluate``."""
        self._evaluate = evaluate
        self.cache: dict[tuple[tuple[str, Any], ...], Evaluation] = {}

    def __call__(self, point: Point) -> Evaluation:
        """The (cached) evaluation of ``point``."""
        key = point_key(point)
        if key not in self.cache:
            self.cache[key] = self._evaluate(dict(point))
        return self.cache[key]

    def ranked(self) -> list[Evaluation]:
        """Every evaluation so far, best first (NaN scores last)."""
        return sorted(self.cache.values(),
                      key=lambda e: (not math.isfinite(e.score), e.score))


def grid_points(grid: Mapping[str, Sequence[Any]]) -> list[Point]:
    """Cartesian product of the grid; a ``lowpass`` axis of (offset, order) pairs is expanded."""
    keys = list(grid)
    points = []
    for values in itertools.product(*(grid[k] for k in keys)):
        point: Point = {}
        for key, value in zip(keys, values, strict=True):
            if key == 'lowpass':
                point['lowpass_offset'], point['lowpass_order'] = value
            else:
                point[key] = value
        points.append(point)
    return points


def grid_search(objective: Callable[[Point], Evaluation],
                points: Sequence[Point]) -> Evaluation:
    """The evaluation with the least score over ``points`` (first one on ties)."""
    if not points:
        raise ValueError('grid_search needs at least one point')
    best: Evaluation | None = None
    for point in points:
        result = objective(point)
        if best is None or (math.isfinite(result.score) and
                            (not math.isfinite(best.score) or result.score < best.score)):
            best = result
    assert best is not None
    return best


def _neighbours(point: Point, key: str, factor: float) -> list[Point]:
    value = point.get(key)
    if value is None:
        return []
    if key == 'notch_depth' and value == 0.0:
        candidates = [0.01]
    else:
        candidates = [value * factor, value / factor]
    low, high = REFINE_BOUNDS.get(key, (0.0, math.inf))
    return [{**point, key: float(f'{c:.4g}')} for c in candidates if low <= c <= high]


def refine(objective: Callable[[Point], Evaluation], start: Evaluation,
           steps: Mapping[str, float] = REFINE_STEPS, shrinks: int = REFINE_SHRINKS,
           ) -> Evaluation:
    """Coordinate descent from ``start`` with multiplicative steps (halved in log when stuck)."""
    best = start
    factors = dict(steps)
    for _ in range(shrinks + 1):
        improved = True
        while improved:
            improved = False
            for key, factor in factors.items():
                for point in _neighbours(best.point, key, factor):
                    result = objective(point)
                    if math.isfinite(result.score) and result.score < best.score:
                        best, improved = result, True
        factors = {k: math.sqrt(v) for k, v in factors.items()}
    return best


def coordinate_search(objective: Callable[[Point], Evaluation], start: Point,
                      grid: Mapping[str, Sequence[Any]], passes: int) -> Evaluation:
    """Coordinate descent over discrete grids: per key, the best grid value with the rest fixed."""
    best = objective(start)
    for _ in range(passes):
        before = point_key(best.point)
        for key, values in grid.items():
            best = grid_search(objective, [best.point] + [{**best.point, key: v} for v in values])
        if point_key(best.point) == before:
            break
    return best


# ------------------------------------------------------------------------------- tuning cases
@dataclass
class TuningCase:
    """A scenario's recordings on the tuning seeds, ready for the open-loop objectives."""

    scenario: Scenario
    ndof: int
    sample_time: float  # h [s]
    stride: int
    begin: int  # first scored grid sample
    duration: float
    model: LinearModel
    data: list[dict[str, FloatArray]]
    raw_rmse: list[FloatArray] = field(default_factory=list)
    provenance: list[str] = field(default_factory=list)

    @property
    def constant_omega(self) -> bool:
        """True when ω0 is the same on every grid sample of every seed."""
        return all(float(np.ptp(d['omega'])) == 0.0 for d in self.data)

    def median_omega(self, k: int) -> float:
        """The median ω0 of seed k's record (the smoother's and the initial tuning)."""
        return float(np.median(self.data[k]['omega']))


def tuning_duration(scenario: Scenario, duration: float | None) -> float:
    """``duration`` capped at the scenario's, or the default of the module docstring."""
    if duration is not None:
        return min(float(duration), scenario.duration)
    times = np.arange(0.0, scenario.duration, scenario.sample_time)
    omega = scenario.waves.peak_freq.sample(times) if hasattr(scenario.waves.peak_freq,
                                                                'sample') else None
    varying = omega is not None and float(np.ptp(omega)) > 0.0
    return min(scenario.duration, VARYING_OMEGA_DURATION if varying else CONSTANT_OMEGA_DURATION)


def _errors(estimate: FloatArray, truth: FloatArray, ndof: int) -> FloatArray:
    err = np.asarray(estimate[:, :ndof] - truth[:, :ndof], dtype=np.float64)
    if ndof == 3:
        err[:, 2] = wrap_angle(err[:, 2])
    return err


def rmse(estimate: FloatArray, truth: FloatArray, ndof: int, begin: int) -> FloatArray:
    """RMSE per DOF over samples k >= begin (heading error wrapped)."""
    err = _errors(estimate[begin:], truth[begin:], ndof)
    return np.asarray(np.sqrt(np.mean(err**2, axis=0)), dtype=np.float64)


def recording_step(model: LinearModel, ndof: int, sample_time: float,
                   wave_peak_freq: float) -> Callable[[float, FloatArray, FloatArray, float],
                                                      FloatArray]:
    """The recording loop's estimator: the observer with `RECORDING_OBSERVER`, retuned to ω0."""
    from lf_predictor_ros.benchmark.estimators import StreamingEstimator

    observer = make_observer(RECORDING_OBSERVER, model, ndof, sample_time, wave_peak_freq)
    return StreamingEstimator(observer, retune=True).step


def prepare_case(name: str, seeds: Sequence[int], duration: float | None = None,
                 log: Callable[[str], None] | None = None) -> TuningCase:
    """Record ``name`` on ``seeds`` (module docstring: closed loops on the observer)."""
    from lf_predictor_ros.benchmark.estimators import predictor_params

    check_seeds(seeds)
    scenario = load_scenario(name)
    params = predictor_params(scenario)
    h = params.sample_time
    total = tuning_duration(scenario, duration)
    model = Simulator(scenario, seeds[0]).true_model()
    omega0 = float(scenario.waves.peak_freq(0.0))
    case = TuningCase(scenario, params.ndof, h, grid_stride(scenario, h), 0, total, model, [])
    for seed in seeds:
        begin = time.monotonic()
        rec = record(scenario, seed, total, h, 'observer',
                     lambda _name: recording_step(model, params.ndof, h, omega0))
        check_scorable(rec, scenario.name, seed)
        case.data.append(rec.data())
        case.provenance.append(rec.provenance.label())
        if log is not None:
            log(f'  recorded {name} seed {seed} ({rec.provenance.label()}, {total:g} s) in '
                f'{time.monotonic() - begin:.1f} s')
    samples = min(len(d['t']) for d in case.data)
    case.begin = min(first_training_samples(params) + 2 * params.retrain_samples, samples // 2)
    case.raw_rmse = [rmse(d['y'], d['truth'], case.ndof, case.begin) for d in case.data]
    return case


def check_seeds(seeds: Sequence[int]) -> None:
    """Refuse anything but the tuning seeds (held-out seeds are for reporting only)."""
    bad = [s for s in seeds if s not in TUNING_SEEDS]
    if bad or not seeds:
        raise ValueError(f'tune on the tuning seeds {TUNING_SEEDS} only, got {list(seeds)}: '
                         'seeds >= 3 (held-out 11–20) are for reporting')


def cascade_outputs(y: FloatArray, ndof: int, sample_time: float, wave_peak_freq: float,
                    config: Mapping[str, Any]) -> FloatArray:
    """`CascadeFilter` over a whole series at a constant ω0, vectorized (same outputs).

    `CausalFilter` starts in steady state at the first sample (``sosfilt_zi · x0``) and runs
    DF2T second-order sections, as ``scipy.signal.sosfilt`` does; heading is unwrapped first
    and the output wrapped, as the streaming filter does.
    """
    sos = design_wave_filter(wave_peak_freq, sample_time, **_cascade_kwargs(config))
    channels = np.array(y[:, :ndof], dtype=np.float64)
    if ndof == 3:
        channels[:, 2] = np.unwrap(channels[:, 2])
    zi = signal.sosfilt_zi(sos)[:, :, None] * channels[0][None, None, :]
    filtered, _ = signal.sosfilt(sos, channels, axis=0, zi=zi)
    out = np.zeros_like(np.asarray(y, dtype=np.float64))
    out[:, :ndof] = filtered
    if ndof == 3:
        out[:, 2] = wrap_angle(out[:, 2])
    return out


def stream(step: Callable[[float, FloatArray, FloatArray, float], FloatArray],
           data: Mapping[str, FloatArray]) -> FloatArray:
    """Outputs (n, 3) of a streaming estimator step over grid arrays (as the benchmark)."""
    out = np.empty_like(data['y'])
    for k in range(len(data['t'])):
        out[k] = step(float(data['t'][k]), data['y'][k], data['u'][k], float(data['omega'][k]))
    return out


def _evaluate(case: TuningCase, point: Point,
              run: Callable[[int, Point], FloatArray]) -> Evaluation:
    ratios, errors = [], []
    for k, data in enumerate(case.data):
        try:
            out = run(k, point)
        except ValueError:  # an invalid design for this ω0
            return Evaluation(point, math.nan)
        value = rmse(out, data['truth'], case.ndof, case.begin)
        if not np.all(np.isfinite(value)):
            return Evaluation(point, math.nan)
        errors.append(value)
        ratios.append(float(np.mean(value / case.raw_rmse[k])))
    return Evaluation(point, float(np.mean(ratios)),
                      tuple(float(v) for v in np.mean(errors, axis=0)))


def cascade_objective(case: TuningCase) -> CachedObjective:
    """Open-loop score of a cascade point (vectorized when ω0 is constant, else streamed)."""
    from lf_predictor_ros.benchmark.estimators import StreamingEstimator

    def run(k: int, point: Point) -> FloatArray:
        data = case.data[k]
        if case.constant_omega:
            return cascade_outputs(data['y'], case.ndof, case.sample_time,
                                   float(data['omega'][0]), point)
        filt = make_cascade(point, case.ndof, case.sample_time, case.median_omega(k))
        return stream(StreamingEstimator(filt, retune=True).step, data)

    return CachedObjective(lambda point: _evaluate(case, point, run))


def smoother_objective(case: TuningCase) -> CachedObjective:
    """Open-loop score of the zero-phase smoother at a point (median ω0, as the benchmark)."""

    def run(k: int, point: Point) -> FloatArray:
        return smooth_poses(case.data[k]['y'], case.sample_time, case.median_omega(k), case.ndof,
                            **_cascade_kwargs(point))

    return CachedObjective(lambda point: _evaluate(case, point, run))


def observer_objective(case: TuningCase) -> CachedObjective:
    """Open-loop score of the observer (true model) at a point."""
    from lf_predictor_ros.benchmark.estimators import StreamingEstimator

    def run(k: int, point: Point) -> FloatArray:
        obs = make_observer(point, case.model, case.ndof, case.sample_time, case.median_omega(k))
        return stream(StreamingEstimator(obs, retune=True).step, case.data[k])

    return CachedObjective(lambda point: _evaluate(case, point, run))


# -------------------------------------------------------------------------------- closed loop
@dataclass(frozen=True)
class LoopScore:
    """A candidate's closed loops over the seeds."""

    point: Point
    stable: bool
    position_rmse: float  # [m] mean over seeds
    heading_rmse: float  # [rad] mean over seeds (NaN for 1 DOF)
    thrust_ratio: float  # thrust wave-band power / the raw loop's, mean over DOFs and seeds
    thrust_power: tuple[float, ...]  # per DOF, mean over seeds
    reasons: tuple[str, ...] = ()


@dataclass(frozen=True)
class _Loop:
    t: FloatArray
    offset: FloatArray  # (n, ndof) LF pose − setpoint(t), heading wrapped, all samples
    thrust: FloatArray
    aborted: bool


def run_loop(case: TuningCase, seed: int,
             step: Callable[[float, FloatArray, FloatArray, float], FloatArray]) -> _Loop:
    """The scenario's PID once per h on ``step``'s output (the benchmark's closed loop)."""
    scenario = case.scenario
    run = recordings.run_loop(scenario, seed, case.duration, case.sample_time, step)
    rec = run.record
    offset = rec.truth_lf_pose - scenario.controller.setpoint_series(rec.t)
    offset[:, 2] = np.angle(np.exp(1j * offset[:, 2]))
    return _Loop(rec.t, offset[:, :case.ndof], rec.thrust, run.aborted_at is not None)


def _loop_metrics(case: TuningCase, loop: _Loop, start: float) -> dict[str, Any]:
    pose = np.zeros((loop.t.size, 3))
    pose[:, :case.ndof] = loop.offset
    return loop_metrics(LoopRun(loop.t, pose, loop.thrust), case.ndof, (0.0, 0.0, 0.0),
                        DEFAULT_WAVE_BAND, start)


def loop_safe_search(case: TuningCase, seeds: Sequence[int], candidates: Sequence[Point],
                     log: Callable[[str], None] | None = None,
                     ) -> tuple[LoopScore, list[LoopScore]]:
    """The loop-safe cascade among ``candidates`` (module docstring) and all their scores."""
    from lf_predictor_ros.benchmark.estimators import MeasurementPassThrough, StreamingEstimator

    ndof, h = case.ndof, case.sample_time
    omega0 = float(case.scenario.waves.peak_freq(0.0))
    start = float(case.data[0]['t'][case.begin])
    references, raw_power = [], []
    for seed in seeds:
        ref = run_loop(case, seed, recording_step(case.model, ndof, h, omega0))
        keep = ref.t >= start
        references.append((ref.offset[keep],
                           stability.excursion_bounds(*stability.max_offsets(ref.offset[keep],
                                                                             ndof))))
        raw = run_loop(case, seed, StreamingEstimator(MeasurementPassThrough(ndof, h), False).step)
        power = _loop_metrics(case, raw, start)['thrust_wave_band_power']
        raw_power.append(np.array([power[d] for d in DOF_NAMES[:ndof]]))
    scores = []
    for point in candidates:
        begin = time.monotonic()
        stable, reasons = True, []
        pos, head, ratio, powers = [], [], [], []
        for k, seed in enumerate(seeds):
            filt = make_cascade(point, ndof, h, omega0)
            loop = run_loop(case, seed, StreamingEstimator(filt, retune=True).step)
            keep = loop.t >= start
            ref_offset, bounds = references[k]
            offset = loop.offset[keep]
            verdict = stability.assess(offset, case.scenario.sample_time, ndof, bounds,
                                       DEFAULT_WAVE_BAND[0], loop.aborted,
                                       reference=ref_offset if ref_offset.shape == offset.shape
                                       else None)
            if not verdict.stable:
                stable = False
                reasons.append(f'seed {seed}: {verdict.reason}')
            if np.count_nonzero(keep) < 3:
                pos.append(math.inf)
                head.append(math.inf)
                ratio.append(math.inf)
                powers.append(np.full(ndof, math.inf))
                continue
            metrics = _loop_metrics(case, loop, start)
            pos.append(metrics['position_rmse'])
            head.append(metrics.get('heading_rmse', math.nan))
            power = np.array([metrics['thrust_wave_band_power'][d] for d in DOF_NAMES[:ndof]])
            powers.append(power)
            ratio.append(float(np.mean(power / raw_power[k])))
        score = LoopScore(point, stable, float(np.mean(pos)), float(np.mean(head)),
                          float(np.mean(ratio)),
                          tuple(float(v) for v in np.mean(powers, axis=0)), tuple(reasons))
        scores.append(score)
        if log is not None:
            log(f'    loop {_describe(point)}: stable {stable}, position {score.position_rmse:.3f}'
                f' m, thrust ratio {score.thrust_ratio:.3g} ({time.monotonic() - begin:.1f} s)')
    return choose_loop_safe(scores, ndof), scores


def choose_loop_safe(scores: Sequence[LoopScore], ndof: int,
                     factor: float = LOOP_RMSE_FACTOR) -> LoopScore:
    """Least thrust ratio among stable candidates within ``factor`` × the best station keeping.

    3 DOF: heading RMSE too (if no candidate meets both, position alone). No stable candidate:
    the one with the least position RMSE (the caller notes it).
    """
    stable = [s for s in scores if s.stable and math.isfinite(s.position_rmse)]
    if not stable:
        return min(scores, key=lambda s: s.position_rmse)
    best_pos = min(s.position_rmse for s in stable)
    feasible = [s for s in stable if s.position_rmse <= factor * best_pos]
    if ndof == 3:
        best_head = min(s.heading_rmse for s in stable)
        both = [s for s in feasible if s.heading_rmse <= factor * best_head]
        feasible = both or feasible
    return min(feasible, key=lambda s: s.thrust_ratio)


def loop_candidates(ranked: Sequence[Evaluation], extra: Sequence[Point],
                    per_lowpass: int = LOOP_CANDIDATES_PER_LOWPASS) -> list[Point]:
    """``extra`` points, then the best ``per_lowpass`` of ``ranked`` per low-pass option.

    ``ranked``: the grid's evaluations, best first (one option per grid (offset, order) pair).
    """
    out: list[Point] = []
    seen: set[tuple[tuple[str, Any], ...]] = set()

    def add(point: Point) -> None:
        key = point_key(point)
        if key not in seen:
            seen.add(key)
            out.append(dict(point))

    for point in extra:
        add(point)
    counts: dict[tuple[Any, Any], int] = {}
    for result in ranked:
        if not math.isfinite(result.score):
            continue
        option = (result.point.get('lowpass_offset'), result.point.get('lowpass_order'))
        if counts.get(option, 0) < per_lowpass:
            counts[option] = counts.get(option, 0) + 1
            add(result.point)
    return out


# ------------------------------------------------------------------------------------- driver
def _describe(point: Mapping[str, Any]) -> str:
    return ', '.join(f'{k} {v:.4g}' if isinstance(v, float) else f'{k} {v}'
                     for k, v in point.items())


def _normalize_cascade(point: Mapping[str, Any]) -> Point:
    return _cascade_kwargs(point)


@dataclass
class ScenarioResult:
    """Everything written for one scenario."""

    name: str
    config: dict[str, Any]
    header: list[str]
    seconds: float


def _score_line(label: str, tuned: Evaluation, default: Evaluation, raw: Sequence[float],
                ndof: int) -> str:
    def fmt(values: Sequence[float]) -> str:
        return '[' + ', '.join(f'{v:.4g}' for v in values[:ndof]) + ']'

    return (f'{label}: rmse {fmt(tuned.rmse)} (score {tuned.score:.3f}) vs default '
            f'{fmt(default.rmse)} (score {default.score:.3f}); raw {fmt(raw)}')


def tune_scenario(name: str, seeds: Sequence[int], duration: float | None, command: str,
                  log: Callable[[str], None] = print) -> ScenarioResult:
    """Run the four searches of the module docstring for one scenario."""
    begin = time.monotonic()
    log(f'{name}:')
    case = prepare_case(name, seeds, duration, log)
    ndof = case.ndof
    raw = tuple(float(v) for v in np.mean(case.raw_rmse, axis=0))
    dof_names = ', '.join(DOF_NAMES[:ndof])
    notes: list[str] = []

    # 1. cascade, RMSE-optimal
    cascade = cascade_objective(case)
    grid = CASCADE_GRID if case.constant_omega else COARSE_CASCADE_GRID
    points = grid_points(grid)
    best_grid = grid_search(cascade, points)
    grid_ranked = sorted((cascade(p) for p in points),
                         key=lambda e: (not math.isfinite(e.score), e.score))
    best_cascade = refine(cascade, best_grid) if case.constant_omega else best_grid
    default_cascade = cascade(CASCADE_DEFAULT)
    if not case.constant_omega:
        notes.append('ω0 changes in the tuning record: cascade streamed (retuned as in the '
                     'benchmark) on the coarse grid, no refinement')
    log(f'  cascade: {_describe(best_cascade.point)} score {best_cascade.score:.3f} '
        f'(default {default_cascade.score:.3f}, {len(cascade.cache)} points)')

    # 2. cascade, loop-safe
    loop_lines: list[str] = []
    if case.scenario.controller.enabled:
        candidates = loop_candidates(grid_ranked, [best_cascade.point, CASCADE_DEFAULT])
        chosen, loop_scores = loop_safe_search(case, seeds, candidates, log)
        loop_safe = _normalize_cascade(chosen.point)
        if not chosen.stable:
            notes.append('no loop candidate was stable on every seed: loop-safe = the least '
                         'position RMSE')
        loop_lines = [f'  {_describe(s.point)}: stable {s.stable}, position rmse '
                      f'{s.position_rmse:.4g} m'
                      + (f', heading rmse {s.heading_rmse:.4g} rad' if ndof == 3 else '')
                      + f', thrust wave-band power / raw loop {s.thrust_ratio:.4g}'
                      + ('' if s.stable else f' ({"; ".join(s.reasons)})')
                      for s in loop_scores]
        loop_eval = cascade(loop_safe)
    else:
        loop_safe = _normalize_cascade(best_cascade.point)
        loop_eval = best_cascade
        notes.append('no controller: cascade_loop_safe = cascade (RMSE-optimal)')
    log(f'  cascade_loop_safe: {_describe(loop_safe)}')

    # 3. observer
    observer = observer_objective(case)
    best_observer = coordinate_search(observer, dict(RECORDING_OBSERVER), OBSERVER_GRID,
                                      OBSERVER_PASSES)
    default_observer = observer(dict(OBSERVER_DEFAULT))
    log(f'  observer: {_describe(best_observer.point)} score {best_observer.score:.3f} '
        f'(default {default_observer.score:.3f}, {len(observer.cache)} points)')

    # 4. smoothers
    smoother = smoother_objective(case)
    params = PredictorParams()
    targets = {'notch_zeta': params.notch_zeta, 'notch_depth': params.notch_depth,
               'lowpass_offset': params.lowpass_offset}
    targets_eval = smoother(targets)
    best_smoother = refine(smoother, grid_search(smoother, grid_points(CASCADE_GRID)))
    default_smoother = smoother(CASCADE_DEFAULT)
    log(f'  smoother_tuned: {_describe(best_smoother.point)} score {best_smoother.score:.3f} '
        f'(targets {targets_eval.score:.3f})')

    config = {
        'cascade': _normalize_cascade(best_cascade.point),
        'cascade_loop_safe': loop_safe,
        'observer': {k: float(best_observer.point[k]) for k in OBSERVER_DEFAULT},
        'smoother_targets': targets,
        'smoother_tuned': _normalize_cascade(best_smoother.point),
    }
    scores = {
        'dofs': list(DOF_NAMES[:ndof]),
        'raw_rmse': list(raw),
        'cascade': {'rmse': list(best_cascade.rmse), 'score': best_cascade.score,
                    'default_rmse': list(default_cascade.rmse),
                    'default_score': default_cascade.score},
        'cascade_loop_safe': {'rmse': list(loop_eval.rmse), 'score': loop_eval.score},
        'observer': {'rmse': list(best_observer.rmse), 'score': best_observer.score,
                     'default_rmse': list(default_observer.rmse),
                     'default_score': default_observer.score},
        'smoother_targets': {'rmse': list(targets_eval.rmse), 'score': targets_eval.score},
        'smoother_tuned': {'rmse': list(best_smoother.rmse), 'score': best_smoother.score,
                           'default_rmse': list(default_smoother.rmse),
                           'default_score': default_smoother.score},
    }
    seconds = time.monotonic() - begin
    date = datetime.datetime.now(datetime.UTC).strftime('%Y-%m-%d %H:%M UTC')
    config['tuning'] = {'command': command, 'date': date, 'seeds': list(seeds),
                        'duration': case.duration, 'recording': case.provenance,
                        'scores': scores, 'notes': notes, 'seconds': round(seconds, 1)}
    header = [
        f'Tuned classical baselines of scenario {name} (lf_predictor_ros.benchmark.'
        'baseline_tuning; schema in its docstring).',
        f'Command: {command}',
        f'Date: {date}; tuning seeds {list(seeds)} only (held-out seeds never used); '
        f'{case.duration:g} s per seed, h = {case.sample_time:g} s, scored after '
        f'{float(case.data[0]["t"][case.begin]):g} s.',
        f'Recordings: {"; ".join(sorted(set(case.provenance)))}'
        + (' (PID on the observer with RECORDING_OBSERVER gains, never on the truth)'
           if case.scenario.controller.enabled else '') + '.',
        'Score: RMSE vs truth_lf_pose per DOF / raw-measurement RMSE, mean over DOFs and seeds.',
        f'Cascade/smoother grid: {_grid_text(grid)} then coordinate refinement'
        + ('' if case.constant_omega else ' (coarse grid, no refinement for the cascade)')
        + f'; smoother grid: {_grid_text(CASCADE_GRID)} + refinement.',
        f'Observer: coordinate descent from {_describe(RECORDING_OBSERVER)} over '
        f'{_grid_text(OBSERVER_GRID)} ({len(observer.cache)} points).',
        f'RMSE per DOF ({dof_names}) [m, m, rad], mean over the seeds:',
        '  ' + _score_line('cascade', best_cascade, default_cascade, raw, ndof),
        '  ' + f'cascade_loop_safe: rmse {_fmt(loop_eval.rmse, ndof)} '
        f'(score {loop_eval.score:.3f})',
        '  ' + _score_line('observer', best_observer, default_observer, raw, ndof),
        '  ' + f'smoother_targets: rmse {_fmt(targets_eval.rmse, ndof)} '
        f'(score {targets_eval.score:.3f})',
        '  ' + _score_line('smoother_tuned', best_smoother, default_smoother, raw, ndof),
    ]
    if loop_lines:
        header.append(f'Closed-loop candidates (cascade, PID once per h, {case.duration:g} s, '
                      f'stability bounds from the observer loop; chosen: least thrust among '
                      f'stable within {LOOP_RMSE_FACTOR}× the best station keeping):')
        header.extend(loop_lines)
    header.extend(f'Note: {n}' for n in notes)
    header.append(f'Search time {seconds:.0f} s.')
    log(f'  done in {seconds:.0f} s')
    return ScenarioResult(name, config, header, seconds)


def _fmt(values: Sequence[float], ndof: int) -> str:
    return '[' + ', '.join(f'{v:.4g}' for v in list(values)[:ndof]) + ']'


def _grid_text(grid: Mapping[str, Sequence[Any]]) -> str:
    parts = []
    for key, values in grid.items():
        if key == 'lowpass':
            text = ', '.join('none' if off is None else f'{off:g}/o{order}'
                             for off, order in values)
            parts.append(f'lowpass (offset/order) {{{text}}}')
        else:
            parts.append(f'{key} {{{", ".join(f"{v:g}" for v in values)}}}')
    return '; '.join(parts)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: tune every scenario given (default: all in config/scenarios)."""
    args_list = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(prog='baseline_tuning', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--scenarios', nargs='*', default=None,
                        help='scenario names (default: every scenario that loads)')
    parser.add_argument('--seeds', nargs='*', type=int, default=list(TUNING_SEEDS))
    parser.add_argument('--duration', type=float, default=None,
                        help='simulated s per seed (default: 1800, 7200 when ω0 changes)')
    parser.add_argument('--out', default=str(CONFIG_DIR), help='output directory')
    args = parser.parse_args(args_list)
    if argv is None and os.environ.get('OMP_NUM_THREADS') is None:
        # BLAS threads on 2 shared cores make the observer's matrix exponentials 10× slower
        os.environ['OMP_NUM_THREADS'] = '1'
        os.execv(sys.executable, [sys.executable, '-m', MODULE, *args_list])
    try:
        check_seeds(args.seeds)
    except ValueError as err:
        parser.error(str(err))
    names = args.scenarios if args.scenarios else available_scenarios()
    command = ' '.join(['OMP_NUM_THREADS=1 python -m', MODULE, *args_list])
    start = time.monotonic()
    for name in names:
        try:
            load_scenario(name)
        except ValueError as err:
            print(f'{name}: skipped, does not load: {err}', flush=True)
            continue
        result = tune_scenario(name, args.seeds, args.duration, command,
                               log=lambda text: print(text, flush=True))
        path = write_baseline_config(config_path(name, args.out), result.config, result.header)
        print(f'  wrote {path}', flush=True)
    print(f'total {time.monotonic() - start:.0f} s', flush=True)
    return 0


__all__ = ['CASCADE_GRID', 'CONFIG_DIR', 'ENTRIES', 'OBSERVER_GRID', 'RECORDING_OBSERVER',
           'TUNING_SEEDS', 'CachedObjective', 'Evaluation', 'LoopScore', 'TuningCase',
           'cascade_objective', 'cascade_outputs', 'check_seeds', 'choose_loop_safe',
           'coordinate_search', 'default_config', 'grid_points', 'grid_search',
           'load_baseline_config', 'loop_candidates', 'loop_safe_search', 'make_cascade',
           'make_observer', 'observer_base_gains', 'observer_objective', 'prepare_case',
           'refine', 'smoother_objective', 'smoother_settings', 'tune_scenario',
           'write_baseline_config']


if __name__ == '__main__':
    sys.exit(main())
