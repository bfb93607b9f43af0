"""One benchmark case: a fair recording, every estimator on it, every causal one in its own loop.

ROS-free (numpy, scipy, torch via the core). The modules of the benchmark keep the leak out by
construction:

- `recordings`: the data and where it came from. A scenario with a DP controller is recorded with
  the loop closed on a realistic causal estimator (``recording_loop``, the tuned passive
  observer by default), never on the true LF pose; open-loop scenarios as they are.
- `estimators`: the estimator table and its factory (tuned baselines from config/baselines).
- `scoring`: open-loop and closed-loop metrics, the leak check verdict, statistics over seeds.

**Open loop**: every estimator over the grid arrays of the recording (h = the predictor's
sample time, the interval mean of the measured poses), scored against the true LF pose after a
warm-up (the first training plus two retraining periods). The recording's provenance is checked
first, and the thrust-only leak check (`recordings.leak_check` against the best causal
estimator) must pass, or the case raises `recordings.LeakError`.

**Closed loop**: one run of `sim_ros.simulation.simulate_in_loop` per causal estimator, same seed
(same waves, environment and sensor noise), the scenario's PID fed that estimator's output once
per h (the predictor's output is its prediction for t + h, used at once; the baselines return
their estimate at t). The loop `ideal` (PID on the true LF pose) only sets the stability bounds
and is shown for reference. Scores: `core.evaluation.loop_metrics` after the open-loop warm-up,
the estimate's own wave-band power, and `benchmark.stability`.

**Seen truth** (reported, not a verdict): the open-loop scores again against the LF truth a
filter of the measurement can see, the twin plus the slow part of the first-order wave motion
(`seen_truth`; the shaping-filter wave models put wave motion below the wave band).

**Adaptation** (scenarios whose ω0 schedule changes inside the scored record): `benchmark.
adaptation` on the open-loop errors of `adaptive` and `frozen`, window Δ = retrain_period.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
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
from lf_predictor_ros.benchmark.baseline_tuning import load_baseline_config, smoother_settings
from lf_predictor_ros.benchmark.estimators import (
    CAUSAL,
    ESTIMATORS,
    LIMITS,
    LOOP_ESTIMATORS,
    NON_CAUSAL,
    PREDICTORS,
    EstimatorSetup,
    MeasurementPassThrough,
    StreamingEstimator,
    make_estimator,
    predictor_params,
    scenario_ndof,
)
from lf_predictor_ros.benchmark.linear_limit import linear_limit
from lf_predictor_ros.benchmark.recordings import (
    LeakReport,
    Recording,
    check_scorable,
    grid_rows,
    grid_stride,
    leak_check,
    record,
    require_fair,
    run_loop,
)
from lf_predictor_ros.benchmark.seen_truth import recording_seen_truth
from lf_predictor_ros.core.baselines.smoother import smooth_poses
from lf_predictor_ros.core.evaluation import (
    DEFAULT_WAVE_BAND,
    DOF_NAMES,
    WELCH_SEGMENT,
    LoopRun,
    Metrics,
    band_power,
    band_rms,
    loop_metrics,
    score,
)
from lf_predictor_ros.core.heading import wrap_angle
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.retraining import first_training_samples
from sim_ros.simulation import (
    ClosedLoopRun,
    Scenario,
    SimRecord,
    Simulator,
    load_scenario,
    scenario_with_schedule_shift,
    simulate,
)

FloatArray = NDArray[np.float64]
DEFAULT_RECORDING_LOOP = 'observer'
# Stream key of `schedule_shift_for_seed`'s generator, apart from the simulator's seed streams.
SCHEDULE_SHIFT_STREAM = 0x5C4ED
LEAK_REFERENCE = 'oracle_kf'  # always in the leak check's set of causal estimators


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
    provenance: dict[str, Any] = field(default_factory=dict)  # recordings.Provenance.to_dict()
    leak: dict[str, Any] = field(default_factory=dict)  # recordings.LeakReport.to_dict()
    loop_series: dict[str, LoopSeries] = field(default_factory=dict, repr=False, compare=False)
    adaptation_series: AdaptationSeries | None = field(default=None, repr=False, compare=False)
    # the same scores against the LF truth a filter of the measurement can see
    # (`seen_truth.seen_lf_truth`; reported, not a verdict); linear_limit is left out (fitted
    # on the twin truth)
    seen_metrics: dict[str, Metrics] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (the figure series are left out)."""
        out = {'scenario': self.scenario, 'seed': self.seed, 'ndof': self.ndof,
               'duration': self.duration, 'warmup': self.warmup,
               'metrics': {k: v.to_dict() for k, v in self.metrics.items()}, 'info': self.info,
               'closed_loop': self.closed_loop, 'provenance': self.provenance,
               'leak': self.leak}
        if self.adaptation is not None:
            out['adaptation'] = [event.to_dict() for event in self.adaptation]
        if self.seen_metrics:
            out['seen_metrics'] = {k: v.to_dict() for k, v in self.seen_metrics.items()}
        return out


def _counters(stream: StreamingEstimator) -> dict[str, int] | None:
    counters = getattr(stream.estimator, 'counters', None)
    return dict(counters) if isinstance(counters, dict) else None


def _run_streaming(stream: StreamingEstimator, data: dict[str, FloatArray]) -> FloatArray:
    out = np.empty_like(data['y'])
    for k in range(len(data['t'])):
        out[k] = stream.step(float(data['t'][k]), data['y'][k], data['u'][k],
                             float(data['omega'][k]))
    return out


def run_open_loop(data: dict[str, FloatArray], setup: EstimatorSetup, names: Sequence[str],
                  info: dict[str, Any], begin: int = 0) -> dict[str, FloatArray]:
    """Every estimator over the grid arrays; outputs aligned to data['t'] (n, 3).

    ``begin``: first scored sample (the linear limit is fitted on the samples from there on).
    """
    outputs: dict[str, FloatArray] = {}
    for name in names:
        start = time.monotonic()
        if name in ('smoother_targets', 'smoother_tuned'):
            settings = smoother_settings(setup.baselines, name, setup.params)
            outputs[name] = smooth_poses(data['y'], setup.sample_time, setup.wave_peak_freq,
                                         setup.ndof, **settings)
        elif name == 'linear_limit':
            outputs[name] = linear_limit(data['y'], data['u'], data['truth'], setup.ndof,
                                         setup.params.nu, setup.params.ny, begin)
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
    """A loop's record and the estimates the PID was fed, one row per estimate (h)."""

    record: SimRecord
    aborted: bool
    info: dict[str, Any]
    estimate_t: FloatArray = field(default_factory=lambda: np.zeros(0))
    estimates: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))


def _run_loop(name: str, scenario: Scenario, seed: int, duration: float | None,
              setup: EstimatorSetup, ideal: SimRecord,
              recorded: ClosedLoopRun | None = None) -> _LoopOutcome:
    """One loop; ``recorded``: this estimator's loop already run by the fair recording."""
    if name == 'ideal':
        return _LoopOutcome(ideal, False, {})
    counters = None
    if recorded is None:
        stream = make_estimator(name, setup)
        run = run_loop(scenario, seed, duration, setup.sample_time, stream.step)
        counters = _counters(stream)
    else:
        run = recorded
    info: dict[str, Any] = {'nonfinite_estimates': run.nonfinite_estimates,
                            'aborted_at': run.aborted_at}
    if counters is not None:
        info['counters'] = counters
    times, estimates = _grid_estimates(run.estimate_t, run.estimates,
                                       grid_stride(scenario, setup.sample_time))
    return _LoopOutcome(run.record, run.aborted_at is not None, info, times, estimates)


def _grid_estimates(times: FloatArray, estimates: FloatArray,
                    stride: int) -> tuple[FloatArray, FloatArray]:
    """(times, estimates) at the estimator's own calls, one per h.

    `run_loop` records the estimate the PID holds at every sensor sample (``GridInput``: a new
    one every ``stride``-th sample, the same one in between); one sample per estimate is kept:
    the ``stride``-th, where each new estimate appears (as `LoopSeries` does), so every
    spectrum of a `_LoopOutcome` is taken at h. Before the twenty-fourth session the held 10 Hz
    series was read as if sampled at h, which put a 0.1 s scenario's wave band (0.3–1.3 rad/s)
    at 0.03–0.13 rad/s of the real series.
    """
    return times[stride - 1::stride], estimates[stride - 1::stride]


def _estimate_wave_power(outcome: _LoopOutcome, ndof: int, start: float,
                         sample_time: float) -> dict[str, float]:
    """Wave-band power of the estimate the PID was fed, per DOF (heading unwrapped)."""
    keep = outcome.estimate_t >= start
    est = outcome.estimates[keep, :ndof].copy()
    if est.shape[0] < 16 or not np.all(np.isfinite(est)):
        return {d: math.nan for d in DOF_NAMES[:ndof]}
    if ndof == 3:
        est[:, 2] = np.unwrap(est[:, 2])
    return {DOF_NAMES[i]: band_power(est[:, i], sample_time, DEFAULT_WAVE_BAND)
            for i in range(ndof)}


# [rad/s] the DP control band: the position loops' bandwidth is 0.1 rad/s (the heading's 0.2),
# and an estimate error there moves the vessel; an error above it mostly moves the thrust
CONTROL_BAND = (0.0, 0.1)
# [rad/s] between the control band and the wave band: the loop's own motion and the swell's
# tail lie here, and an estimate error here moves the vessel as much as one in the control band
# (docs/BENCHMARKS.md, twenty-fifth session)
BETWEEN_BAND = (0.1, 0.3)


def _loop_estimate_error(outcome: _LoopOutcome, ndof: int, start: float) -> FloatArray:
    """Estimate the PID was fed minus the true LF pose when it was fed, (m, ndof), from start.

    One row per estimate: estimate j, returned at ``estimate_t[j]``, is held by the PID from
    that instant (the adaptive predictor's LF pose predicted for t + h included: it is what the
    loop acts on), so it is compared with the truth at that sample. Heading error wrapped; only
    finite rows. `_timed_loop_estimate_error` gives their times too.
    """
    return _timed_loop_estimate_error(outcome, ndof, start)[1]


def _timed_loop_estimate_error(outcome: _LoopOutcome, ndof: int,
                               start: float) -> tuple[FloatArray, FloatArray]:
    """(times, errors) of `_loop_estimate_error`: each row's estimate time [s] with it."""
    rec = outcome.record
    keep = outcome.estimate_t >= start
    times, est = outcome.estimate_t[keep], outcome.estimates[keep, :ndof]
    index = np.searchsorted(rec.t, times - 1e-9)
    on_grid = index < rec.t.size
    on_grid[on_grid] = np.abs(rec.t[index[on_grid]] - times[on_grid]) <= 1e-6
    error = est[on_grid] - rec.truth_lf_pose[index[on_grid], :ndof]
    if ndof == 3:
        error[:, 2] = wrap_angle(error[:, 2])
    finite = np.all(np.isfinite(error), axis=1)
    return (np.asarray(times[on_grid][finite], dtype=np.float64),
            np.asarray(error[finite], dtype=np.float64))


def _estimate_errors(outcome: _LoopOutcome, ndof: int, start: float,
                     sample_time: float) -> dict[str, dict[str, float]]:
    """The loop's own estimate error per DOF: RMSE, and RMS in the bands below the waves.

    ``estimate_rmse``: RMSE of `_loop_estimate_error`. ``estimate_error_control_band``:
    √(Welch power in ``CONTROL_BAND`` + mean²), the part of the error the position loop follows;
    ``estimate_error_between_band``: √(Welch power in ``BETWEEN_BAND``), where a filter that
    trades lag for wave leakage puts what it takes out of the control band. They show whether a
    variant's estimate is better *in its own loop*, where the thrust it regresses on answers its
    own output, which the open loop on the fair recordings cannot show, and where in frequency.
    ``sample_time``: h. NaN with fewer than 16 estimates (an aborted or empty loop).
    """
    error = _loop_estimate_error(outcome, ndof, start)
    names = DOF_NAMES[:ndof]
    if error.shape[0] < 16:
        nan = {d: math.nan for d in names}
        return {'estimate_rmse': nan, 'estimate_error_control_band': dict(nan),
                'estimate_error_between_band': dict(nan)}
    rmse = np.sqrt(np.mean(error ** 2, axis=0))
    control = [band_rms(error[:, i], sample_time, CONTROL_BAND) for i in range(ndof)]
    between = [band_rms(error[:, i], sample_time, BETWEEN_BAND) for i in range(ndof)]
    return {'estimate_rmse': {d: float(rmse[i]) for i, d in enumerate(names)},
            'estimate_error_control_band': {d: control[i] for i, d in enumerate(names)},
            'estimate_error_between_band': {d: between[i] for i, d in enumerate(names)}}


def _loop_reference(scenario: Scenario, rec: SimRecord, ideal: SimRecord) -> FloatArray:
    """What a loop's pose is scored against, per sample (n, 3).

    Station keeping: the setpoint. With setpoint moves and turns (``setpoint_schedule``) the
    transients after each move would swamp every difference between the estimators, so the
    reference is the LF track of the ideal loop (PID on the true LF pose, same seed and
    schedule): the error is what the estimator in the loop costs against perfect knowledge.
    """
    if not scenario.controller.setpoint_schedule:
        return np.asarray(scenario.controller.setpoint_series(rec.t), dtype=np.float64)
    n = min(rec.t.size, ideal.t.size)
    track = np.array(ideal.truth_lf_pose[:n], dtype=np.float64)
    if n < rec.t.size:  # cannot happen: a loop never outlives the ideal one; keep the shape
        track = np.vstack([track, np.repeat(track[-1:], rec.t.size - n, axis=0)])
    return track


def run_closed_loops(scenario: Scenario, seed: int, duration: float | None,
                     setup: EstimatorSetup, names: Sequence[str], ideal: SimRecord,
                     start: float, recorded: Mapping[str, ClosedLoopRun] | None = None,
                     ) -> tuple[dict[str, dict[str, Any]], dict[str, LoopSeries]]:
    """One closed loop per name (module docstring), scored over t ≥ start.

    ``recorded``: loops already run (the fair recording's), reused instead of run again.
    """
    ndof = setup.ndof
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
        outcome = _run_loop(name, scenario, seed, duration, setup, ideal,
                            (recorded or {}).get(name))
        rec = outcome.record
        keep = rec.t >= start
        setpoint = _loop_reference(scenario, rec, ideal)
        offset = stability.pose_offset(rec.truth_lf_pose[keep], setpoint[keep], ndof)
        if name == 'ideal':
            bounds = stability.excursion_bounds(*stability.max_offsets(offset, ndof))
            ideal_offset = offset
        loop = LoopRun(rec.t, rec.truth_lf_pose, rec.thrust)
        metrics = (loop_metrics(loop, ndof, setpoint, DEFAULT_WAVE_BAND, start)
                   if np.count_nonzero(keep) >= 3 else _nan_loop_metrics(ndof))
        # the ideal loop is the reference itself: what it shows is the forced response
        same_samples = ideal_offset.shape == offset.shape
        verdict = stability.assess(offset, scenario.sample_time, ndof, bounds,
                                   DEFAULT_WAVE_BAND[0], outcome.aborted,
                                   reference=ideal_offset if same_samples else None)
        metrics['stability'] = verdict.to_dict()
        metrics['saturated_fraction'] = stability.saturated_fraction(
            rec.thrust_command[keep], None if limit is None else np.asarray(limit), ndof)
        if name != 'ideal':
            metrics['estimate_wave_band_power'] = _estimate_wave_power(
                outcome, ndof, start, setup.sample_time)
            metrics.update(_estimate_errors(outcome, ndof, start, setup.sample_time))
        metrics.update(outcome.info)
        metrics['seconds'] = round(time.monotonic() - begin, 3)
        if name in names:
            results[name] = metrics
            omega, psd = _thrust_spectrum(rec.thrust[keep], scenario.sample_time, ndof)
            sl = grid_rows(stride)
            series[name] = LoopSeries(
                rec.t[sl], stability.pose_offset(rec.truth_lf_pose[sl], setpoint[sl], ndof),
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


def _leak_report(recording: Recording, metrics: Mapping[str, Metrics], setup: EstimatorSetup,
                 begin: int) -> LeakReport | None:
    """The thrust-only leak check of a feedback-loop recording (None: open loop, no feedback).

    Compared with the best causal estimator there is: the oracle (a fair thrust cannot carry more
    than the measurements and the true model give) and the recording loop's estimator (the thrust
    carries its output) are always in the set, scored here if the case did not ask for them.
    """
    if recording.provenance.loop == 'open':  # exogenous thrust: the motion is its response
        return None
    data = recording.data()
    causal = {name: m.rmse for name, m in metrics.items() if name in CAUSAL}
    for reference in (LEAK_REFERENCE, recording.provenance.estimator):
        if reference is not None and reference not in causal:
            out = run_open_loop(data, setup, (reference,), {}, begin)[reference]
            causal[reference] = score(data['t'][begin:], out[begin:], data['truth'][begin:],
                                      setup.ndof).rmse
    return leak_check(recording, causal, setup.ndof, begin)


def make_setup(scenario: Scenario, seed: int, params: PredictorParams,
               wave_peak_freq: float | None = None) -> EstimatorSetup:
    """The estimator setup of a case: true model, ω0, the scenario's tuned baselines."""
    omega = float(scenario.waves.peak_freq(0.0)) if wave_peak_freq is None else wave_peak_freq
    return EstimatorSetup(params.ndof, params.sample_time, params,
                          Simulator(scenario, seed).true_model(), omega, scenario,
                          load_baseline_config(scenario.name))


def make_recording(scenario: Scenario, seed: int, duration: float | None, setup: EstimatorSetup,
                   recording_loop: str = DEFAULT_RECORDING_LOOP) -> Recording:
    """The fair recording of a case (`recordings.record` with the loop on ``recording_loop``)."""
    if recording_loop not in CAUSAL:
        raise ValueError(f'the recording loop needs a causal estimator, one of {CAUSAL}; got '
                         f'{recording_loop!r}')
    return record(scenario, seed, duration, setup.sample_time, recording_loop,
                  lambda name: make_estimator(name, setup).step)


def scored_start(params: PredictorParams, samples: int) -> int:
    """First scored grid sample: the first training plus two retraining periods."""
    return min(first_training_samples(params) + 2 * params.retrain_samples, samples // 2)


def schedule_shift_for_seed(seed: int, spread: float,
                            stream: int = SCHEDULE_SHIFT_STREAM) -> float:
    """The scheduled events' delay [s] for ``seed``: U(0, ``spread``), 0 when spread is 0.

    Drawn from its own stream (``stream``, by default ``SCHEDULE_SHIFT_STREAM``; the odometry
    bench's dropouts draw from another), so the sea, the noise and every other draw of the seed
    are unchanged. Every held-out seed has the same event times otherwise, and
    the predictor retrains at the same instants in every run: the benchmark's intervals would
    not cover the phase between trainings and manoeuvres (docs/BENCHMARKS.md, twenty-first
    session).
    """
    if not (math.isfinite(spread) and spread >= 0.0):
        raise ValueError(f'the schedule shift spread must be finite and >= 0 s, got {spread!r}')
    if spread == 0.0:
        return 0.0
    return float(np.random.default_rng((seed, stream)).uniform(0.0, spread))


def run_case(scenario_name: str, seed: int, *, duration: float | None = None,
             params_overrides: dict[str, Any] | None = None,
             estimators: Sequence[str] = ESTIMATORS,
             loop_estimators: Sequence[str] | None = None,
             recording_loop: str = DEFAULT_RECORDING_LOOP,
             recording: Recording | None = None,
             schedule_shift: float = 0.0) -> CaseResult:
    """Record ``scenario_name`` with ``seed`` fairly and score the estimators (module docstring).

    ``loop_estimators``: closed loops to run (None: `LOOP_ESTIMATORS` when the scenario has its
    controller enabled, else none; () for none). ``recording``: score this one instead of
    recording anew (its provenance must match and pass; a truth-fed one raises `LeakError`).
    ``schedule_shift`` [s]: every scheduled event that much later, setpoint moves and turns and
    wave peak frequency steps (`scenario_with_schedule_shift`; 0: the scenario as written), for
    every loop and the recording alike.
    """
    unknown = [n for n in estimators if n not in ESTIMATORS]
    if unknown:
        raise ValueError(f'unknown estimator(s) {unknown}; choose from {ESTIMATORS}')
    written = load_scenario(scenario_name)
    scenario = scenario_with_schedule_shift(written, schedule_shift)
    params = predictor_params(scenario, params_overrides)
    setup = make_setup(scenario, seed, params)
    if recording is None:
        recording = make_recording(scenario, seed, duration, setup, recording_loop)
    check_scorable(recording, scenario.name, seed)
    data = recording.data()
    # the smoothers use one ω0 for the whole record: the median of the true ω0
    setup = replace(setup, wave_peak_freq=float(np.median(data['omega'])))
    tuning = setup.baselines.get('tuning') or {}
    info: dict[str, Any] = {'sample_time': setup.sample_time, 'params': params.to_dict(),
                            'baselines': 'untuned defaults' if tuning.get('source') == 'defaults'
                            else 'config/baselines'}
    if scenario is not written:  # else the scenario has no events to move
        info['schedule_shift'] = schedule_shift
    begin = scored_start(params, len(data['t']))
    outputs = run_open_loop(data, setup, estimators, info, begin)
    truth = data['truth'][begin:]
    metrics = {name: score(data['t'][begin:], out[begin:], truth, params.ndof)
               for name, out in outputs.items()}
    seen_metrics = _seen_metrics(recording, data, outputs, params, begin, info)
    leak = _leak_report(recording, metrics, setup, begin)
    if leak is not None:
        require_fair(recording, leak)
    warmup = float(data['t'][begin])
    loops = (LOOP_ESTIMATORS if scenario.controller.enabled else ()) \
        if loop_estimators is None else tuple(loop_estimators)
    closed: dict[str, dict[str, Any]] = {}
    series: dict[str, LoopSeries] = {}
    if loops:
        unknown = [n for n in loops if n not in LOOP_ESTIMATORS]
        if unknown:
            raise ValueError(f'no closed loop for {unknown}; loops: {LOOP_ESTIMATORS} (the '
                             'smoothers and the linear limit are non-causal: no loop)')
        ideal = simulate(scenario, seed=seed, duration=duration, controller=True,
                         feedback='truth_lf')
        # the recording loop is that estimator's closed loop (same seed, loop and estimator);
        # a predictor's is run again for its training counters
        reuse = {} if recording.loop_run is None or recording.provenance.estimator in \
            PREDICTORS else {str(recording.provenance.estimator): recording.loop_run}
        closed, series = run_closed_loops(scenario, seed, duration, setup, loops, ideal, warmup,
                                          reuse)
    adaptation = score_adaptation(scenario, data, outputs, params, begin)
    return CaseResult(scenario=scenario_name, seed=seed, ndof=params.ndof,
                      duration=float(data['t'][-1]), warmup=warmup, metrics=metrics, info=info,
                      closed_loop=closed,
                      adaptation=None if adaptation is None else adaptation[0],
                      provenance=recording.provenance.to_dict(),
                      leak={} if leak is None else leak.to_dict(),
                      loop_series=series,
                      adaptation_series=None if adaptation is None else adaptation[1],
                      seen_metrics=seen_metrics)


def _seen_metrics(recording: Recording, data: dict[str, FloatArray],
                  outputs: dict[str, FloatArray], params: PredictorParams, begin: int,
                  info: dict[str, Any]) -> dict[str, Metrics]:
    """Scores against `seen_truth.recording_seen_truth` (empty without the wave motion).

    Also puts the RMS of the slow wave motion (seen − twin) per DOF into ``info``.
    """
    full = recording_seen_truth(recording, params.sample_time)
    if full is None:
        return {}
    seen = full[begin:]
    slow = seen - data['truth'][begin:]
    slow[:, 2] = wrap_angle(slow[:, 2])
    info['slow_wave_rms'] = [float(v) for v in np.sqrt(np.mean(slow**2, axis=0))[:params.ndof]]
    return {name: score(data['t'][begin:], out[begin:], seen, params.ndof)
            for name, out in outputs.items() if name != 'linear_limit'}


__all__ = ['CAUSAL', 'DEFAULT_RECORDING_LOOP', 'ESTIMATORS', 'LIMITS', 'LOOP_ESTIMATORS',
           'NON_CAUSAL', 'AdaptationSeries', 'CaseResult', 'EstimatorSetup', 'LoopSeries',
           'MeasurementPassThrough', 'StreamingEstimator', 'make_estimator', 'make_recording',
           'make_setup', 'predictor_params', 'run_case', 'run_closed_loops', 'run_open_loop',
           'scenario_ndof', 'score_adaptation', 'scored_start']
