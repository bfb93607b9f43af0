"""One benchmark case: simulate a scenario, run every estimator on the same data, score them.

ROS-free (numpy, scipy, torch via the core). Every estimator sees the same measurements, resampled
to the predictor's sample time h (decimation of the simulator's output), and is scored against the
simulator's LF ground truth after a warm-up (the first training plus two retraining periods):

| name | what |
|---|---|
| `adaptive` | the product: Algorithm 4.1, retrained every Δ (inline, deterministic) |
| `frozen` | the same network trained once and then frozen (the thesis's static condition) |
| `cascade` | causal notch + low-pass, retuned to the true ω0 |
| `observer` | nonlinear passive observer with the true (linearized) model and the true ω0 |
| `observer_mistuned` | the observer with M ×1.3, D ×0.7 and ω0 ×1.2 |
| `smoother` | zero-phase notch + low-pass over the whole record at the true ω0 (non-causal) |
| `raw` | the measurement itself |

The observer's bias gains follow anchors §4 with the supply vessel's reference length for every
vessel: K4 = 0.1·diag(M)·g/L, K3 = 0.1·√(g/L)·K4 (L = 76.2 m).
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
import math
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lf_predictor_ros.core.baselines.cascade import CascadeFilter
from lf_predictor_ros.core.baselines.observer import PassiveObserver
from lf_predictor_ros.core.baselines.smoother import smooth_poses
from lf_predictor_ros.core.evaluation import Metrics, score
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.predictor import AdaptivePredictor
from lf_predictor_ros.core.retraining import first_training_samples
from sim_ros.physics.vessels import GRAVITY, SUPPLY_LENGTH
from sim_ros.simulation import Scenario, SimRecord, Simulator, load_scenario, simulate

FloatArray = NDArray[np.float64]

ESTIMATORS = ('adaptive', 'frozen', 'cascade', 'observer', 'observer_mistuned', 'smoother', 'raw')
MISTUNE_MASS, MISTUNE_DAMPING, MISTUNE_FREQ = 1.3, 0.7, 1.2


@dataclass(frozen=True)
class CaseResult:
    """Scores of every estimator on one (scenario, seed)."""

    scenario: str
    seed: int
    ndof: int
    duration: float
    warmup: float
    metrics: dict[str, Metrics]
    info: dict[str, Any]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {'scenario': self.scenario, 'seed': self.seed, 'ndof': self.ndof,
                'duration': self.duration, 'warmup': self.warmup,
                'metrics': {k: v.to_dict() for k, v in self.metrics.items()}, 'info': self.info}


def scenario_ndof(scenario: Scenario) -> int:
    """1 for the thesis's 1-DOF vessel, 3 otherwise."""
    return 1 if Simulator(scenario, 0).ndof == 1 else 3


def predictor_params(scenario: Scenario, overrides: dict[str, Any] | None = None,
                     ) -> PredictorParams:
    """Default predictor parameters for a scenario (ndof, h = max(1 s, sensor period))."""
    h = max(1.0, scenario.sample_time)
    return PredictorParams(ndof=scenario_ndof(scenario), sample_time=h, **(overrides or {}))


def _decimate(record: SimRecord, stride: int) -> dict[str, FloatArray]:
    sl = slice(stride - 1, None, stride)
    return {'t': record.t[sl], 'y': record.measured_pose[sl], 'u': record.thrust[sl],
            'truth': record.truth_lf_pose[sl], 'omega': record.wave_peak_freq[sl]}


def _run_streaming(estimator: Any, data: dict[str, FloatArray], retune: bool) -> FloatArray:
    out = np.empty_like(data['y'])
    last = math.nan
    for k in range(len(data['t'])):
        omega = float(data['omega'][k])
        if retune and omega != last:
            estimator.set_wave_peak_freq(omega * getattr(estimator, 'freq_factor', 1.0))
            last = omega
        out[k] = estimator.update(float(data['t'][k]), data['y'][k], data['u'][k])
    return out


def _observer_factory(ndof: int, h: float, omega0: float, mass: FloatArray,
                      damping: FloatArray, freq_factor: float) -> Callable[[], PassiveObserver]:
    k4 = 0.1 * np.diag(mass) * GRAVITY / SUPPLY_LENGTH
    k3 = 0.1 * math.sqrt(GRAVITY / SUPPLY_LENGTH) * k4

    def make() -> PassiveObserver:
        m = mass[:ndof, :ndof] if ndof == 3 else float(mass[0, 0])
        d = damping[:ndof, :ndof] if ndof == 3 else float(damping[0, 0])
        obs = PassiveObserver(ndof, h, omega0 * freq_factor, m, d, k3=k3[:ndof], k4=k4[:ndof])
        obs.freq_factor = freq_factor  # type: ignore[attr-defined]
        return obs
    return make


def run_case(scenario_name: str, seed: int, *, duration: float | None = None,
             params_overrides: dict[str, Any] | None = None,
             estimators: Sequence[str] = ESTIMATORS) -> CaseResult:
    """Simulate ``scenario_name`` with ``seed`` and score the estimators (module docstring)."""
    scenario = load_scenario(scenario_name)
    params = predictor_params(scenario, params_overrides)
    record = simulate(scenario, seed=seed, duration=duration)
    stride = max(1, int(round(params.sample_time / scenario.sample_time)))
    data = _decimate(record, stride)
    ndof, h = params.ndof, params.sample_time
    model = Simulator(scenario, seed).true_model()
    omega0 = float(np.median(data['omega']))
    outputs: dict[str, FloatArray] = {}
    info: dict[str, Any] = {'sample_time': h, 'params': params.to_dict()}
    for name in estimators:
        start = time.monotonic()
        if name in ('adaptive', 'frozen'):
            predictor = AdaptivePredictor(params, background=False,
                                          max_trainings=1 if name == 'frozen' else None)
            raw = _run_streaming(predictor, data, retune=False)
            outputs[name] = np.vstack([raw[:1], raw[:-1]])  # raw[k] is the estimate for t[k+1]
            info[f'{name}_counters'] = predictor.counters
        elif name == 'cascade':
            outputs[name] = _run_streaming(CascadeFilter(ndof, h, omega0), data, True)
        elif name in ('observer', 'observer_mistuned'):
            mis = name == 'observer_mistuned'
            mass = model.mass * (MISTUNE_MASS if mis else 1.0)
            damping = model.damping * (MISTUNE_DAMPING if mis else 1.0)
            make = _observer_factory(ndof, h, omega0, mass, damping,
                                     MISTUNE_FREQ if mis else 1.0)
            outputs[name] = _run_streaming(make(), data, retune=True)
        elif name == 'smoother':
            outputs[name] = smooth_poses(data['y'], h, omega0, ndof)
        elif name == 'raw':
            outputs[name] = data['y'].copy()
        else:
            raise ValueError(f'unknown estimator {name!r}; choose from {ESTIMATORS}')
        info[f'{name}_seconds'] = round(time.monotonic() - start, 3)
    warmup_samples = first_training_samples(params) + 2 * params.retrain_samples
    begin = min(warmup_samples, len(data['t']) // 2)
    metrics = {name: score(data['t'][begin:], out[begin:], data['truth'][begin:], ndof)
               for name, out in outputs.items()}
    return CaseResult(scenario=scenario_name, seed=seed, ndof=ndof,
                      duration=float(data['t'][-1]), warmup=float(data['t'][begin]),
                      metrics=metrics, info=info)
