"""Every estimator of the benchmark, built by one factory from one setup.

| name | causal | what |
|---|---|---|
| `adaptive` | yes | the product: Algorithm 4.1, retrained every Δ (inline, deterministic) |
| `frozen` | yes | the same network trained once and then frozen (the thesis's static condition) |
| `cascade` | yes | notch + low-pass at the true ω0, tuned for open-loop RMSE (config/baselines) |
| `cascade_loop_safe` | yes | the same family tuned in the loop: least wave-band thrust, stable |
| `observer` | yes | passive observer, true M, D and ω0, gains tuned (config/baselines) |
| `observer_mistuned` | yes | the tuned observer with M ×1.3, D ×0.7 and ω0 ×1.2 |
| `oracle_kf` | yes | Kalman filter with the simulator's true model and noise: the **limit** |
| `raw` | yes | the measurement itself |
| `smoother_targets` | no | zero-phase notch + low-pass at the predictor's target settings |
| `smoother_tuned` | no | the zero-phase smoother tuned for RMSE |
| `linear_limit` | no | best causal linear filter on the predictor's regressors, fit on the truth |

Causal estimators can close a DP loop; the non-causal rows (the smoothers need the whole record,
the linear limit needs the truth) are open-loop references only. Tuned baseline settings are read
from ``config/baselines/<scenario>.yaml`` (`benchmark.baseline_tuning`, which records the command
that produced them); every baseline sees the true ω0 (retuned when it changes), the predictor
estimates its own.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray
import yaml

from lf_predictor_ros.core.estimator import EstimatorStatus
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.predictor import AdaptivePredictor
from sim_ros.physics.vessels import LinearModel
from sim_ros.simulation import Scenario

FloatArray = NDArray[np.float64]

CAUSAL = ('adaptive', 'frozen', 'cascade', 'cascade_loop_safe', 'observer', 'observer_mistuned',
          'oracle_kf', 'raw')
NON_CAUSAL = ('smoother_targets', 'smoother_tuned', 'linear_limit')
ESTIMATORS = (*CAUSAL, *NON_CAUSAL)
LOOP_ESTIMATORS = ('ideal', *CAUSAL)  # ideal: the PID on the true LF pose (reference only)
PREDICTORS = ('adaptive', 'frozen')  # outputs valid at t + h
LIMITS = ('oracle_kf', 'linear_limit')  # rows that know the truth or the true model
MISTUNE_MASS, MISTUNE_DAMPING, MISTUNE_FREQ = 1.3, 0.7, 1.2


@dataclass(frozen=True)
class EstimatorSetup:
    """What the factory needs: DOFs, h, predictor parameters, the true model, ω0, the scenario."""

    ndof: int
    sample_time: float
    params: PredictorParams
    model: LinearModel
    wave_peak_freq: float  # [rad/s] initial tuning of the baselines (then retuned per sample)
    scenario: Scenario | None = None
    baselines: Mapping[str, Any] = field(default_factory=dict)  # config/baselines/<scenario>


class MeasurementPassThrough:
    """The `raw` estimator: returns the measured pose (an `LfEstimator`)."""

    def __init__(self, ndof: int, sample_time: float) -> None:
        """No state; ndof and sample_time only for the protocol."""
        self.ndof = ndof
        self.sample_time = sample_time

    def update(self, t: float, pose: FloatArray, force: FloatArray) -> FloatArray:
        """A copy of the measurement."""
        return np.array(pose, dtype=np.float64)

    def reset(self) -> None:
        """Nothing to forget."""

    def status(self) -> EstimatorStatus:
        """Always running."""
        return EstimatorStatus(state='ok', message='measurement passed through')


class StreamingEstimator:
    """An estimator fed one sample at a time; baselines are retuned when the true ω0 changes."""

    def __init__(self, estimator: Any, retune: bool, freq_factor: float = 1.0) -> None:
        """Wrap `estimator`; ``freq_factor`` scales the true ω0 (the mistuned observer)."""
        self.estimator = estimator
        self.retune = retune
        self.freq_factor = freq_factor
        self._omega = math.nan

    def step(self, t: float, pose: FloatArray, force: FloatArray,
             wave_peak_freq: float) -> FloatArray:
        """Retune if ω0 changed, then `update`; returns the estimator's output."""
        if self.retune and wave_peak_freq != self._omega:
            self.estimator.set_wave_peak_freq(wave_peak_freq * self.freq_factor)
            self._omega = wave_peak_freq
        return np.asarray(self.estimator.update(t, pose, force), dtype=np.float64)


def scenario_ndof(scenario: Scenario) -> int:
    """1 for the thesis's 1-DOF vessel, 3 otherwise."""
    return scenario.ndof


def param_overrides(items: Sequence[str]) -> dict[str, Any]:
    """``FIELD=VALUE`` strings (YAML values) → PredictorParams overrides; ValueError if invalid."""
    out: dict[str, Any] = {}
    for item in items:
        name, sep, text = item.partition('=')
        if not sep or not name:
            raise ValueError(f'--param {item!r}: write FIELD=VALUE, e.g. motion_gate=true')
        value = yaml.safe_load(text)
        out[name] = tuple(value) if isinstance(value, list) else value
    PredictorParams.from_dict(out)  # unknown fields and invalid values raise here, before a run
    return out


def predictor_params(scenario: Scenario, overrides: Mapping[str, Any] | None = None,
                     ) -> PredictorParams:
    """Default predictor parameters for a scenario (ndof, h = max(1 s, sensor period)).

    ``overrides`` win, ``sample_time`` included (h must stay a multiple of the sensor period).
    """
    values: dict[str, Any] = {'ndof': scenario_ndof(scenario),
                              'sample_time': max(1.0, scenario.sample_time)}
    values.update(overrides or {})
    unknown = sorted(set(values) - {f.name for f in fields(PredictorParams)})
    if unknown:
        raise ValueError(f'unknown predictor parameter(s) {unknown}: overrides take '
                         'PredictorParams fields (docs: README, "Predictor parameters")')
    params = PredictorParams(**values)
    ratio = params.sample_time / scenario.sample_time
    if ratio < 1.0 - 1e-9 or abs(ratio - round(ratio)) > 1e-9:
        raise ValueError(f'predictor sample_time {params.sample_time} s must be a whole multiple '
                         f"of the scenario's sensor period {scenario.sample_time} s: the "
                         'benchmark decimates the measurements to it')
    return params


def make_estimator(name: str, setup: EstimatorSetup) -> StreamingEstimator:
    """A fresh causal estimator of the module table, ready to be streamed."""
    # imported here: baseline_tuning runs loops through this factory (no import cycle)
    from lf_predictor_ros.benchmark import baseline_tuning

    config = setup.baselines
    if name in PREDICTORS:
        predictor = AdaptivePredictor(setup.params, background=False,
                                      max_trainings=1 if name == 'frozen' else None)
        return StreamingEstimator(predictor, retune=False)
    if name in ('cascade', 'cascade_loop_safe'):
        return StreamingEstimator(baseline_tuning.make_cascade(
            config.get(name, {}), setup.ndof, setup.sample_time, setup.wave_peak_freq),
            retune=True)
    if name in ('observer', 'observer_mistuned'):
        mistuned = name == 'observer_mistuned'
        observer = baseline_tuning.make_observer(config.get('observer', {}), setup.model,
                                                 setup.ndof, setup.sample_time,
                                                 setup.wave_peak_freq, mistuned=mistuned)
        return StreamingEstimator(observer, retune=True,
                                  freq_factor=MISTUNE_FREQ if mistuned else 1.0)
    if name == 'oracle_kf':
        from lf_predictor_ros.benchmark.oracle import make_oracle

        if setup.scenario is None:
            raise ValueError('oracle_kf needs the scenario (its true model): set '
                             'EstimatorSetup.scenario')
        return StreamingEstimator(make_oracle(setup.scenario, setup.sample_time), retune=True)
    if name == 'raw':
        return StreamingEstimator(MeasurementPassThrough(setup.ndof, setup.sample_time), False)
    if name in NON_CAUSAL:
        raise ValueError(f'{name!r} is non-causal (it needs the whole record or the truth): it '
                         'has no streaming form and cannot be in a loop')
    raise ValueError(f'unknown estimator {name!r}; choose from {ESTIMATORS}')


__all__ = ['CAUSAL', 'ESTIMATORS', 'LIMITS', 'LOOP_ESTIMATORS', 'MISTUNE_DAMPING',
           'MISTUNE_FREQ', 'MISTUNE_MASS', 'NON_CAUSAL', 'PREDICTORS', 'EstimatorSetup',
           'MeasurementPassThrough', 'StreamingEstimator', 'make_estimator', 'predictor_params',
           'scenario_ndof']
