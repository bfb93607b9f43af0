"""One benchmark case: simulate a scenario, run every estimator on the same data, score them.

ROS-free (numpy, scipy, torch via the core). Every estimator sees the same measurements, resampled
to the predictor's sample time h as the predictor node does it (`InputAligner`: the mean of the
measured poses of each interval), and is scored against the simulator's LF ground truth after a
warm-up (the first training plus two retraining periods):

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
vessel: K4 = 0.1·diag(M)·g/L, K3 = 0.1·√(g/L)·K4 (L = 76.2 m). Every estimator is built by one
factory (`make_estimator`) for both uses below.

**Open loop** (every scenario): the estimators run on the recorded data of the scenario's own
run (closed-loop scenarios: the PID on the true LF pose). Scores: `core.evaluation.score`.

**Closed loop** (scenarios with ``controller.enabled``): one run of
`sim_ros.simulation.simulate_in_loop` per estimator, same seed (same waves, environment and sensor
noise), the scenario's PID fed that estimator's output. The estimator is called every h with the
mean measured pose of the interval and the applied thrust of that instant (the same decimated input
as open loop) and the PID holds its output in between. The predictor's output is its prediction for
t + h, used at once (it compensates the hold); the baselines return their estimate at t. The loop
`ideal` is the PID on the true LF pose (the scenario's own run: the reference), `smoother`
has no loop (it is non-causal: it needs the whole record before it outputs anything). Scores:
`core.evaluation.loop_metrics` after the open-loop warm-up and the stability verdict of
`benchmark.stability` (bounds relative to the ideal loop).

**Adaptation** (scenarios whose ω0 schedule changes inside the scored record, e.g.
``omega_schedule``): `benchmark.adaptation` on the open-loop errors of `adaptive` and `frozen`
(north error for 1 DOF, horizontal error for 3 DOF), window Δ = params.retrain_period.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
import math
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from lf_predictor_ros.benchmark import stability
from lf_predictor_ros.benchmark.adaptation import (
    AdaptationEvent,
    adaptation_events,
    change_times,
    rolling_rmse,
)
from lf_predictor_ros.core.alignment import block_mean_poses, mean_pose
from lf_predictor_ros.core.baselines.cascade import CascadeFilter
from lf_predictor_ros.core.baselines.observer import PassiveObserver
from lf_predictor_ros.core.baselines.smoother import smooth_poses
from lf_predictor_ros.core.estimator import EstimatorStatus
from lf_predictor_ros.core.evaluation import (
    DEFAULT_WAVE_BAND,
    DOF_NAMES,
    WELCH_SEGMENT,
    LoopRun,
    Metrics,
    loop_metrics,
    score,
)
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.predictor import AdaptivePredictor
from lf_predictor_ros.core.retraining import first_training_samples
from sim_ros.physics.vessels import GRAVITY, SUPPLY_LENGTH, LinearModel
from sim_ros.simulation import (
    Scenario,
    SimRecord,
    Simulator,
    load_scenario,
    simulate,
    simulate_in_loop,
)

FloatArray = NDArray[np.float64]

ESTIMATORS = ('adaptive', 'frozen', 'cascade', 'observer', 'observer_mistuned', 'smoother', 'raw')
LOOP_ESTIMATORS = ('ideal', 'adaptive', 'frozen', 'cascade', 'observer', 'observer_mistuned',
                   'raw')
MISTUNE_MASS, MISTUNE_DAMPING, MISTUNE_FREQ = 1.3, 0.7, 1.2
PREDICTORS = ('adaptive', 'frozen')  # outputs valid at t + h


@dataclass(frozen=True)
class LoopSeries:
    """What the closed-loop figure shows of one loop (not in the JSON)."""

    t: FloatArray  # [s] decimated to h
    offset: FloatArray  # (m, ndof) true LF pose − setpoint, heading wrapped
    thrust_omega: FloatArray  # [rad/s] Welch frequencies of the thrust PSD
    thrust_psd: FloatArray  # (f, ndof) one-sided PSD of the applied thrust [N²/Hz, …]


@dataclass(frozen=True)
class AdaptationSeries:
    """What the adaptation figure shows (not in the JSON)."""

    t: FloatArray  # [s]
    adaptive_rmse: FloatArray  # rolling RMSE over Δ
    frozen_rmse: FloatArray
    wave_peak_freq: FloatArray  # [rad/s] true ω0
    changes: tuple[float, ...]
    window: float  # Δ [s]


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
    closed_loop: dict[str, dict[str, Any]] = field(default_factory=dict)
    adaptation: list[AdaptationEvent] | None = None
    loop_series: dict[str, LoopSeries] = field(default_factory=dict, repr=False, compare=False)
    adaptation_series: AdaptationSeries | None = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (the figure series are left out)."""
        out = {'scenario': self.scenario, 'seed': self.seed, 'ndof': self.ndof,
               'duration': self.duration, 'warmup': self.warmup,
               'metrics': {k: v.to_dict() for k, v in self.metrics.items()}, 'info': self.info,
               'closed_loop': self.closed_loop}
        if self.adaptation is not None:
            out['adaptation'] = [event.to_dict() for event in self.adaptation]
        return out


@dataclass(frozen=True)
class EstimatorSetup:
    """What the factory needs: DOFs, h, predictor parameters, the true model and ω0."""

    ndof: int
    sample_time: float
    params: PredictorParams
    model: LinearModel
    wave_peak_freq: float  # [rad/s] initial tuning of the baselines (then retuned per sample)


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
    return 1 if Simulator(scenario, 0).ndof == 1 else 3


def predictor_params(scenario: Scenario, overrides: dict[str, Any] | None = None,
                     ) -> PredictorParams:
    """Default predictor parameters for a scenario (ndof, h = max(1 s, sensor period)).

    ``overrides`` win, ``sample_time`` included (h must stay a multiple of the sensor period).
    """
    values: dict[str, Any] = {'ndof': scenario_ndof(scenario),
                              'sample_time': max(1.0, scenario.sample_time)}
    values.update(overrides or {})
    params = PredictorParams(**values)
    ratio = params.sample_time / scenario.sample_time
    if ratio < 1.0 - 1e-9 or abs(ratio - round(ratio)) > 1e-9:
        raise ValueError(f'predictor sample_time {params.sample_time} s must be a whole multiple '
                         f"of the scenario's sensor period {scenario.sample_time} s: the "
                         'benchmark decimates the measurements to it')
    return params


def _observer(setup: EstimatorSetup, mistuned: bool) -> PassiveObserver:
    mass = setup.model.mass * (MISTUNE_MASS if mistuned else 1.0)
    damping = setup.model.damping * (MISTUNE_DAMPING if mistuned else 1.0)
    k4 = 0.1 * np.diag(mass) * GRAVITY / SUPPLY_LENGTH
    k3 = 0.1 * math.sqrt(GRAVITY / SUPPLY_LENGTH) * k4
    ndof = setup.ndof
    m = mass[:ndof, :ndof] if ndof == 3 else float(mass[0, 0])
    d = damping[:ndof, :ndof] if ndof == 3 else float(damping[0, 0])
    omega0 = setup.wave_peak_freq * (MISTUNE_FREQ if mistuned else 1.0)
    return PassiveObserver(ndof, setup.sample_time, omega0, m, d, k3=k3[:ndof], k4=k4[:ndof])


def make_estimator(name: str, setup: EstimatorSetup) -> StreamingEstimator:
    """A fresh causal estimator of the module table, ready to be streamed."""
    if name in PREDICTORS:
        predictor = AdaptivePredictor(setup.params, background=False,
                                      max_trainings=1 if name == 'frozen' else None)
        return StreamingEstimator(predictor, retune=False)
    if name == 'cascade':
        return StreamingEstimator(CascadeFilter(setup.ndof, setup.sample_time,
                                                setup.wave_peak_freq), retune=True)
    if name in ('observer', 'observer_mistuned'):
        mistuned = name == 'observer_mistuned'
        return StreamingEstimator(_observer(setup, mistuned), retune=True,
                                  freq_factor=MISTUNE_FREQ if mistuned else 1.0)
    if name == 'raw':
        return StreamingEstimator(MeasurementPassThrough(setup.ndof, setup.sample_time), False)
    if name == 'smoother':
        raise ValueError("'smoother' is non-causal (zero-phase over the whole record): it has no "
                         'streaming form; use smooth_poses on a recorded run')
    raise ValueError(f'unknown estimator {name!r}; choose from {ESTIMATORS}')


def _decimate(record: SimRecord, stride: int) -> dict[str, FloatArray]:
    """The record on the grid h: every ``stride``-th sample.

    The measured pose is averaged over the interval (`InputAligner`, ``average_poses`` on);
    thrust, truth and ω0 are those of the grid instant.
    """
    sl = slice(stride - 1, None, stride)
    return {'t': record.t[sl], 'y': block_mean_poses(record.measured_pose, stride),
            'u': record.thrust[sl], 'truth': record.truth_lf_pose[sl],
            'omega': record.wave_peak_freq[sl]}


def _run_streaming(stream: StreamingEstimator, data: dict[str, FloatArray]) -> FloatArray:
    out = np.empty_like(data['y'])
    for k in range(len(data['t'])):
        out[k] = stream.step(float(data['t'][k]), data['y'][k], data['u'][k],
                             float(data['omega'][k]))
    return out


def _counters(stream: StreamingEstimator) -> dict[str, int] | None:
    counters = getattr(stream.estimator, 'counters', None)
    return dict(counters) if isinstance(counters, dict) else None


def run_open_loop(data: dict[str, FloatArray], setup: EstimatorSetup, names: Sequence[str],
                  info: dict[str, Any]) -> dict[str, FloatArray]:
    """Every estimator over the decimated record; outputs aligned to data['t'] (n, 3)."""
    outputs: dict[str, FloatArray] = {}
    for name in names:
        start = time.monotonic()
        if name == 'smoother':
            outputs[name] = smooth_poses(data['y'], setup.sample_time, setup.wave_peak_freq,
                                         setup.ndof)
        else:
            stream = make_estimator(name, setup)
            out = _run_streaming(stream, data)
            if name in PREDICTORS:
                out = np.vstack([out[:1], out[:-1]])  # out[k] was the estimate for t[k+1]
                info[f'{name}_counters'] = _counters(stream)
            outputs[name] = out
        info[f'{name}_seconds'] = round(time.monotonic() - start, 3)
    return outputs


def _thrust_spectrum(thrust: FloatArray, sample_time: float,
                     ndof: int) -> tuple[FloatArray, FloatArray]:
    """Welch PSD of the thrust per DOF (the segments of `band_power`), ω in rad/s."""
    if thrust.shape[0] < 16:  # a loop aborted during the warm-up: nothing to show
        return np.zeros(0), np.zeros((0, ndof))
    nperseg = min(thrust.shape[0], max(16, int(round(WELCH_SEGMENT / sample_time))))
    freq, psd = signal.welch(thrust[:, :ndof], fs=1.0 / sample_time, nperseg=nperseg,
                             detrend='constant', axis=0)
    return 2.0 * math.pi * freq, np.asarray(psd, dtype=np.float64)


def _nan_loop_metrics(ndof: int) -> dict[str, Any]:
    out: dict[str, Any] = {'samples': 0, 'position_rmse': math.nan, 'max_excursion': math.nan,
                           'thrust_wave_band_power': {d: math.nan for d in DOF_NAMES[:ndof]},
                           'thrust_total_variation': {d: math.nan for d in DOF_NAMES[:ndof]}}
    if ndof == 3:
        out['heading_rmse'] = math.nan
    return out


@dataclass(frozen=True)
class _LoopOutcome:
    record: SimRecord
    aborted: bool
    info: dict[str, Any]


class _GridInput:
    """A loop's estimator fed as the predictor node feeds it: one call per grid interval h.

    Called by `simulate_in_loop` at every sensor sample; every ``stride``-th call it passes the
    estimator the mean of the interval's measured poses (`InputAligner` with ``average_poses``
    on: the anti-aliasing of the decimation, as `_decimate` does for the open loop) and the thrust
    of that instant, and returns the estimate; in between it returns the last one (the PID holds
    it).
    """

    def __init__(self, stream: StreamingEstimator, schedule: Callable[[float], float],
                 stride: int) -> None:
        self.stream = stream
        self.schedule = schedule
        self.stride = stride
        self._poses: list[FloatArray] = []
        self._held: FloatArray | None = None

    def __call__(self, t: float, pose: FloatArray, thrust: FloatArray) -> FloatArray:
        """The estimate to hold after this sensor sample."""
        self._poses.append(pose)
        if len(self._poses) == self.stride:
            mean = mean_pose(np.array(self._poses))
            self._poses = []
            self._held = self.stream.step(t, mean, thrust, self.schedule(t))
        return pose if self._held is None else self._held


def _run_loop(name: str, scenario: Scenario, seed: int, duration: float | None,
              setup: EstimatorSetup, ideal: SimRecord) -> _LoopOutcome:
    if name == 'ideal':
        return _LoopOutcome(ideal, False, {})
    stream = make_estimator(name, setup)
    grid_input = _GridInput(stream, scenario.waves.peak_freq,
                            max(1, int(round(setup.sample_time / scenario.sample_time))))
    # the PID runs once per estimate (h) and the thruster command is held, as `dp_controller`
    # does on each /lf_pose message in the DDS pipeline
    run = simulate_in_loop(scenario, seed, duration, grid_input, scenario.sample_time,
                           abort_excursion=stability.ABORT_EXCURSION,
                           pid_period=setup.sample_time)
    info: dict[str, Any] = {'nonfinite_estimates': run.nonfinite_estimates,
                            'aborted_at': run.aborted_at}
    counters = _counters(stream)
    if counters is not None:
        info['counters'] = counters
    return _LoopOutcome(run.record, run.aborted_at is not None, info)


def run_closed_loops(scenario: Scenario, seed: int, duration: float | None,
                     setup: EstimatorSetup, names: Sequence[str], ideal: SimRecord,
                     start: float) -> tuple[dict[str, dict[str, Any]], dict[str, LoopSeries]]:
    """One closed loop per name (module docstring), scored over t ≥ start."""
    ndof = setup.ndof
    setpoint = np.asarray(scenario.controller.setpoint, dtype=np.float64)
    stride = max(1, int(round(setup.sample_time / scenario.sample_time)))
    limit_source = Simulator(scenario, seed)
    limit = scenario.controller.tau_max or limit_source.actuator_limit()
    order = ['ideal', *[n for n in names if n != 'ideal']]  # the ideal loop sets the bounds
    results: dict[str, dict[str, Any]] = {}
    series: dict[str, LoopSeries] = {}
    bounds = (math.inf, math.inf)
    ideal_offset = np.empty((0, ndof))
    for name in order:
        begin = time.monotonic()
        outcome = _run_loop(name, scenario, seed, duration, setup, ideal)
        rec = outcome.record
        keep = rec.t >= start
        offset = stability.pose_offset(rec.truth_lf_pose[keep], setpoint, ndof)
        if name == 'ideal':
            bounds = stability.excursion_bounds(*stability.max_offsets(offset, ndof))
            ideal_offset = offset
        loop = LoopRun(rec.t, rec.truth_lf_pose, rec.thrust)
        metrics = (loop_metrics(loop, ndof, tuple(setpoint), DEFAULT_WAVE_BAND, start)
                   if np.count_nonzero(keep) >= 3 else _nan_loop_metrics(ndof))
        # the ideal loop is the reference itself: what it shows is the forced response
        same_samples = ideal_offset.shape == offset.shape
        verdict = stability.assess(offset, scenario.sample_time, ndof, bounds,
                                   DEFAULT_WAVE_BAND[0], outcome.aborted,
                                   reference=ideal_offset if same_samples else None)
        metrics['stability'] = verdict.to_dict()
        metrics['saturated_fraction'] = stability.saturated_fraction(
            rec.thrust_command[keep], None if limit is None else np.asarray(limit), ndof)
        metrics.update(outcome.info)
        metrics['seconds'] = round(time.monotonic() - begin, 3)
        if name in names:
            results[name] = metrics
            omega, psd = _thrust_spectrum(rec.thrust[keep], scenario.sample_time, ndof)
            sl = slice(stride - 1, None, stride)
            series[name] = LoopSeries(
                rec.t[sl], stability.pose_offset(rec.truth_lf_pose[sl], setpoint, ndof),
                omega, psd)
    return results, series


def _horizontal_error(estimate: FloatArray, truth: FloatArray, ndof: int) -> FloatArray:
    if ndof == 1:
        return np.asarray(estimate[:, 0] - truth[:, 0], dtype=np.float64)
    return np.asarray(np.hypot(estimate[:, 0] - truth[:, 0], estimate[:, 1] - truth[:, 1]),
                      dtype=np.float64)


def score_adaptation(scenario: Scenario, data: dict[str, FloatArray],
                     outputs: dict[str, FloatArray], params: PredictorParams, begin: int,
                     ) -> tuple[list[AdaptationEvent], AdaptationSeries] | None:
    """Adaptation events of adaptive vs frozen over the scored record (None: nothing to score)."""
    if not all(name in outputs for name in PREDICTORS):
        return None
    t = data['t'][begin:]
    if t.size < 2:
        return None
    changes = change_times(scenario.waves.peak_freq, float(t[0]), float(t[-1]))
    if not changes:
        return None
    errors = {name: _horizontal_error(outputs[name][begin:], data['truth'][begin:], params.ndof)
              for name in PREDICTORS}
    window = params.retrain_period
    events = adaptation_events(t, errors['adaptive'], errors['frozen'], changes, window)
    series = AdaptationSeries(t, rolling_rmse(t, errors['adaptive'], window),
                              rolling_rmse(t, errors['frozen'], window), data['omega'][begin:],
                              changes, window)
    return events, series


def run_case(scenario_name: str, seed: int, *, duration: float | None = None,
             params_overrides: dict[str, Any] | None = None,
             estimators: Sequence[str] = ESTIMATORS,
             loop_estimators: Sequence[str] | None = None) -> CaseResult:
    """Simulate ``scenario_name`` with ``seed`` and score the estimators (module docstring).

    ``loop_estimators``: closed loops to run (None: `LOOP_ESTIMATORS` when the scenario has its
    controller enabled, else none; () for none).
    """
    scenario = load_scenario(scenario_name)
    params = predictor_params(scenario, params_overrides)
    record = simulate(scenario, seed=seed, duration=duration)
    stride = max(1, int(round(params.sample_time / scenario.sample_time)))
    data = _decimate(record, stride)
    setup = EstimatorSetup(params.ndof, params.sample_time, params,
                           Simulator(scenario, seed).true_model(),
                           float(np.median(data['omega'])))
    info: dict[str, Any] = {'sample_time': setup.sample_time, 'params': params.to_dict()}
    outputs = run_open_loop(data, setup, estimators, info)
    warmup_samples = first_training_samples(params) + 2 * params.retrain_samples
    begin = min(warmup_samples, len(data['t']) // 2)
    truth = data['truth'][begin:]
    metrics = {name: score(data['t'][begin:], out[begin:], truth, params.ndof)
               for name, out in outputs.items()}
    warmup = float(data['t'][begin])
    loops = (LOOP_ESTIMATORS if scenario.controller.enabled else ()) \
        if loop_estimators is None else tuple(loop_estimators)
    closed: dict[str, dict[str, Any]] = {}
    series: dict[str, LoopSeries] = {}
    if loops:
        unknown = [n for n in loops if n not in LOOP_ESTIMATORS]
        if unknown:
            raise ValueError(f'no closed loop for {unknown}; loops: {LOOP_ESTIMATORS} (the '
                             'smoother is non-causal and cannot be in a loop)')
        ideal = record if scenario.controller.feedback == 'truth_lf' and \
            scenario.controller.enabled else simulate(scenario, seed=seed, duration=duration,
                                                      controller=True, feedback='truth_lf')
        closed, series = run_closed_loops(scenario, seed, duration, setup, loops, ideal, warmup)
    adaptation = score_adaptation(scenario, data, outputs, params, begin)
    return CaseResult(scenario=scenario_name, seed=seed, ndof=params.ndof,
                      duration=float(data['t'][-1]), warmup=warmup, metrics=metrics, info=info,
                      closed_loop=closed,
                      adaptation=None if adaptation is None else adaptation[0],
                      loop_series=series,
                      adaptation_series=None if adaptation is None else adaptation[1])


__all__ = ['ESTIMATORS', 'LOOP_ESTIMATORS', 'AdaptationSeries', 'CaseResult', 'EstimatorSetup',
           'LoopSeries', 'MeasurementPassThrough', 'StreamingEstimator', 'make_estimator',
           'predictor_params', 'run_case', 'run_closed_loops', 'run_open_loop',
           'scenario_ndof', 'score_adaptation']
