"""The adaptive LF predictor: thesis Algorithm 4.1 as a real-time estimator.

`AdaptivePredictor.update(t, pose, force)` is called once per sample (uniform grid, sample time h;
`core.alignment` makes that grid from real sensor streams) and returns the LF pose predicted for
t + h (lines 14–17). Every Δ samples it hands a *copy* of its buffers to a worker thread that runs
`core.retraining.run_retraining` (frequency estimate → zero-phase targets → training →
validation). Finished results are picked up at the start of a later `update` with a non-blocking
queue read, and an accepted network is put in service by replacing one reference to an immutable
`NumpyNnarmax`: the predict path never waits for training and never sees mixed weights.

Before the first accepted training, and whenever the network cannot predict (a new data segment
after a gap, a non-finite output), the output comes from a causal notch + low-pass cascade tuned to
the latest ω0 estimate (or the prior), and `status().state` says 'warming_up' or 'fallback'.

Conventions: positions [m], heading [rad], forces [N, N, N·m] in the body frame. Internally the
heading is unwrapped (continuous across ±π) and, for 3 DOF, forces are rotated to the earth frame
with the measured heading (u = R(ψ)τ, Fossen 2011 §7.1: η̈ ≈ R(ψ)ν̇), so the network does not have
to learn the rotation the thesis found hard (§5.3). With ``regressor_frame`` 'body' the network
turns every regressor row (and its predicted step) into the body frame of the row's newest
heading (``core.regressors``), so these earth-frame buffers serve both frames unchanged. Outputs
have the heading wrapped to (−π, π].
For 1 DOF only the north component is estimated; east and yaw of the output are the measured
east and yaw of the same sample passed through unfiltered (never a made-up 0: on a 3-DOF vessel
run with ``ndof`` 1 a zero heading would be up to 180° wrong; the node flags the pass-through in
/diagnostics).

Bumpless transfer (off by default, issue 13): with ``switch_blend_time`` T > 0, when the source
of the output changes (cascade → network, network → cascade, old → new network, a checkpoint
loaded) the published estimate moves from the old source's value to the new one's with a smooth
ramp (w = 3s² − 2s³, s = elapsed / T, no step in value or rate), both sources running. An old
network that can no longer predict (implausible, not finite, a new data segment) is replaced by
the last published output held as an offset that fades out over T; a switch back to the old
source during a blend reverses it. ``max_output_rate`` (per DOF, 0 = no limit) then bounds how
fast the published estimate moves. Both act on the published output only: the regressors,
feedback history and trainings see exactly what they see with both off, and with both off the
output is bit-identical to the plain switch.

Roughness guard (on by default, ``roughness_guard_time`` T = 30 s; `core.roughness`): a
network whose prediction has, over T, ``ROUGHNESS_RATIO`` (50) times the mean-square second
difference of the measured pose in any DOF is no LF filter in this loop (in a DP loop a network
with the thrust among its regressors can close a limit cycle with the controller's D term,
docs/BENCHMARKS.md "Eighteenth session"). It is retired: the network in service before it serves
again (a second trip retires that one too, then the cascade fallback serves) until the next
accepted training (which starts from the retired weights, as after a network a training
retires).
Counted in ``counters['rough_retirements']``; the motion gate's twin runs without it.

Output notch (off by default, issue 13): with ``output_notch_zeta`` ζ > 0 the published estimate
(after the motion gate, if on) runs through a causal notch at the current ω0 estimate (depth
``notch_depth``; `baselines.cascade.CascadeFilter` without its low-pass, retuned with the output
kept continuous whenever ω0 changes, restarted with the data segment). The learned filter is
fitted for the smallest error against the targets and lets part of the wave peak through, which a
DP loop turns into wave-band thrust; the notch takes out the peak at a phase lag of about 2ζ/ω0
seconds in the LF band (Fossen 2011 §11.3.2, the classical cascade's notch). Like the bumpless
transfer it acts on the published output only (regressors, feedback and trainings unchanged).

Checkpoints: `save(path)` writes the network in service to ``path`` (``network.save_checkpoint``);
with the motion gate on, the twin's network goes to the sibling file ``path + '.twin'``
(`twin_checkpoint_path`, same format) and `load(path)` restores the twin from it when it is there
(a checkpoint without one, e.g. from a gate-off predictor, loads with a cold twin). A gate-off
predictor writes and reads ``path`` alone, as it always did. With ``checkpoint_path`` set, each
network's worker saves its own file after each of its accepted trainings.

Bad input: `update` raises ValueError for a non-finite or wrongly shaped pose/force and leaves its
state unchanged (the node filters such samples before they get here). A training that raises is
caught on the worker; the network in service stays, and the status reports the error.
"""
from __future__ import annotations

import atexit
from collections import deque
from collections.abc import Iterator, Mapping
import math
from pathlib import Path
import queue
import threading
import time
from typing import Any
import weakref

import numpy as np
from numpy.typing import NDArray
import torch

from lf_predictor_ros.core.baselines.cascade import CascadeFilter, CascadePlan, plan_cascade
from lf_predictor_ros.core.estimator import EstimatorState, EstimatorStatus
from lf_predictor_ros.core.filters import low_pass_step
from lf_predictor_ros.core.finite import all_finite
from lf_predictor_ros.core.fit_process import FitProcess, JobAbandonedError, shared_fit_process
from lf_predictor_ros.core.frequency import FrequencyEstimate, spectrum_fit_by
from lf_predictor_ros.core.heading import ContinuousHeading, wrap_angle, wrap_pose
from lf_predictor_ros.core.job_worker import JobWorker
from lf_predictor_ros.core.motion_gate import (
    MotionGate,
    dead_zoned,
    gate_validated,
    moving_offset,
    shifted,
)
from lf_predictor_ros.core.network import (
    NnarmaxNet,
    NnarmaxSpec,
    NumpyNnarmax,
    load_checkpoint,
    predict_step,
    save_checkpoint,
)
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.retraining import (
    RetrainResult,
    Snapshot,
    estimate_frequency,
    first_training_samples,
    network_spec,
    run_retraining,
)
from lf_predictor_ros.core.roughness import RoughnessGuard
from lf_predictor_ros.core.targets import TargetWindow
from lf_predictor_ros.core.training import warm_up
from lf_predictor_ros.core.yaw_moment_trigger import YawMomentTrigger

# Sanity guard: a prediction farther from the newest measurement than this many RMS of the
# wave-frequency motion seen in training (plus a floor) is not believed; the cascade stands in
# and the feedback history is re-seeded from it (stops a free-running recursion from running away).
# The floor is ``PredictorParams.guard_floor`` [m, m, rad].
GUARD_SPREADS = 6.0
# Appended to a checkpoint's path to name the motion gate twin's checkpoint beside it.
TWIN_SUFFIX = '.twin'
# The force argument of the output notch's `CascadeFilter.update` (it ignores the force).
_NO_FORCE = np.zeros(3)
_NO_FORCE.flags.writeable = False
_NO_ROWS = np.zeros((0, 3))  # the feedback history of a network without feedback (nfb 0)
_NO_ROWS.flags.writeable = False

FloatArray = NDArray[np.float64]


class _NewestRows:
    """The newest rows of a stream in one array: the newest n rows are a view, oldest first.

    Every row is written twice (at its index modulo the capacity and the capacity above it),
    so the newest rows are always contiguous: no copy of a deque per prediction or snapshot.
    """

    __slots__ = ('_capacity', '_count', '_rows')

    def __len__(self) -> int:
        """Rows held: those appended, at most the capacity (as a deque with maxlen)."""
        return min(self._count, self._capacity)

    def __iter__(self) -> Iterator[FloatArray]:
        """The rows held, oldest first."""
        return iter(self.newest(len(self)))

    def __init__(self, capacity: int) -> None:
        self._capacity = capacity
        self._count = 0  # rows appended
        self._rows: FloatArray | None = None  # (2 capacity, width) once the width is known

    def append(self, row: FloatArray) -> None:
        rows = self._rows
        if rows is None:
            rows = self._rows = np.zeros((2 * self._capacity, row.shape[0]))
        i = self._count % self._capacity
        rows[i] = row
        rows[i + self._capacity] = row
        self._count += 1

    def newest(self, count: int) -> FloatArray:
        """The newest min(count, held) rows, oldest first (a view: valid until the next append)."""
        n = min(count, self._count, self._capacity)
        if self._rows is None or n <= 0:
            return np.array([])  # as np.array of no rows
        end = (self._count - 1) % self._capacity + self._capacity + 1
        return self._rows[end - n:end]


class _Transfer:
    """A running bumpless transfer: the old source, blended out from ``start`` [s].

    ``offset`` not None: the old value is the new source's value plus this held offset (an old
    source that cannot run any more); otherwise ``source`` is the old source, a network or None
    for the cascade.
    """

    __slots__ = ('offset', 'source', 'start')

    def __init__(self, source: NumpyNnarmax | None, offset: FloatArray | None,
                 start: float) -> None:
        self.source = source
        self.offset = offset
        self.start = start


def twin_checkpoint_path(path: str) -> str:
    """Where `AdaptivePredictor.save(path)` puts the motion gate twin's checkpoint.

    ``path + '.twin'``: a sibling of the holding network's file (same folder, so the same
    permissions and disk), named from the whole path whatever its suffix, and never a name a
    holding checkpoint ending in '.pt' could have.
    """
    return path + TWIN_SUFFIX


def _smoothstep(phase: float) -> float:
    """Ramp 0 → 1 over phase 0 → 1 with zero slope at both ends (3s² − 2s³)."""
    s = min(max(phase, 0.0), 1.0)
    return s * s * (3.0 - 2.0 * s)


_LIVE_PREDICTORS: weakref.WeakSet[AdaptivePredictor] = weakref.WeakSet()


@atexit.register
def _stop_training_at_exit() -> None:
    """Stop running trainings before the interpreter exits.

    A torch training still running on a daemon thread while Python finalizes aborts the process
    ('terminate called without an active exception'); stopping it at an epoch boundary and
    joining it lets a script that forgot `close()` exit cleanly.
    """
    for predictor in list(_LIVE_PREDICTORS):
        predictor.close()


class _JobOutcome:
    """A finished job: a result, or the exception it raised."""

    def __init__(self, generation: int, result: RetrainResult | None,
                 error: BaseException | None, saved_error: str | None = None,
                 frequency: FrequencyEstimate | None = None,
                 fallback_plan: CascadePlan | None = None,
                 notch_plans: Mapping[float, CascadePlan] | None = None) -> None:
        self.generation = generation
        self.result = result
        self.error = error
        self.saved_error = saved_error
        self.frequency = frequency  # set by a frequency-only job (before the first training)
        self.fallback_plan = fallback_plan  # the cascade fallback at the result's ω0
        self.notch_plans = notch_plans  # the notches at that ω0, by width ζ


def fallback_design(params: PredictorParams) -> dict[str, Any]:
    """`CascadeFilter`'s design arguments of the predictor's cascade fallback."""
    return {'notch_zeta': params.fallback_notch_zeta, 'notch_depth': params.notch_depth,
            'lowpass_offset': params.lowpass_offset}


def notch_design(params: PredictorParams, notch_zeta: float) -> dict[str, Any]:
    """`CascadeFilter`'s design arguments of a notch at ω0 alone (width ``notch_zeta``)."""
    return {'notch_zeta': notch_zeta, 'notch_depth': params.notch_depth, 'lowpass_offset': None}


def retrain_and_plan(params: PredictorParams, snapshot: Snapshot,
                     incumbent: dict[str, torch.Tensor] | None, targets: TargetWindow | None,
                     frequency: FrequencyEstimate | float | None,
                     stop: threading.Event | None,
                     before_restart: tuple[float, TargetWindow] | None,
                     plan_fallback: bool, notch_zetas: tuple[float, ...] = (),
                     ) -> tuple[RetrainResult, CascadePlan | None, dict[float, CascadePlan]]:
    """`run_retraining`, and the filters retuned to its ω0 planned at it.

    ``plan_fallback``: the cascade fallback; ``notch_zetas``: the widths of the notches the
    predictor retunes (``output_notch_zeta``, ``motion_gate_yaw_notch``), planned by width. In
    the job (the child process), so that applying the result on the predict path does not
    design a filter (`plan_cascade`; docs/BENCHMARKS.md, sixty-ninth and seventieth sessions).
    """
    result = run_retraining(params, snapshot, incumbent, targets, frequency, stop,
                            before_restart)
    return (result, *plan_wave_filters(params, result.frequency.wave_peak_freq, plan_fallback,
                                       notch_zetas))


def estimate_and_plan(params: PredictorParams, y: FloatArray,
                      previous: FrequencyEstimate | float | None, plan_fallback: bool,
                      notch_zetas: tuple[float, ...] = (),
                      ) -> tuple[FrequencyEstimate, CascadePlan | None, dict[float, CascadePlan]]:
    """`estimate_frequency` (the ω0 jobs before the first training), and the filters planned.

    As `retrain_and_plan`: in the job (the child process), so that applying the estimate on the
    predict path retunes the cascade fallback and the notches without designing them
    (docs/BENCHMARKS.md, seventy-first session). Raises what `estimate_frequency` raises.
    """
    estimate = estimate_frequency(params, y, previous)
    return (estimate, *plan_wave_filters(params, estimate.wave_peak_freq, plan_fallback,
                                         notch_zetas))


def plan_wave_filters(params: PredictorParams, wave_peak_freq: float, plan_fallback: bool,
                      notch_zetas: tuple[float, ...],
                      ) -> tuple[CascadePlan | None, dict[float, CascadePlan]]:
    """The plans of the filters retuned to ω0 [rad/s]: the fallback's (if asked), the notches'."""
    plan = plan_fallback_at(params, wave_peak_freq) if plan_fallback else None
    notches = {zeta: plan_cascade(wave_peak_freq, params.sample_time,
                                  **notch_design(params, zeta)) for zeta in notch_zetas}
    return plan, notches


def plan_fallback_at(params: PredictorParams, wave_peak_freq: float) -> CascadePlan:
    """The cascade fallback's `CascadePlan` at ω0 [rad/s] (`retrain_and_plan`)."""
    return plan_cascade(wave_peak_freq, params.sample_time, **fallback_design(params))


class AdaptivePredictor:
    """Adaptive NNARMAX LF-pose predictor (implements `core.estimator.LfEstimator`)."""

    def __init__(self, params: PredictorParams, *, background: bool = True,
                 checkpoint_path: str | None = None, max_trainings: int | None = None,
                 training_lock: threading.Lock | None = None,
                 worker_name: str = 'lf-predictor-training',
                 cascade_output: bool = True) -> None:
        """Create an untrained predictor.

        ``background``: train on a worker thread (True, for nodes) or inline at the retraining
        instant (False: deterministic, for replay and benchmarks). ``checkpoint_path``: the worker
        saves every accepted network there (the motion gate twin's worker its own to
        `twin_checkpoint_path` of it). ``max_trainings``: stop retraining after that many
        accepted trainings (1 gives the thesis's static network; None = adaptive).
        ``training_lock``: held by a worker while it trains, so predictors sharing it train one
        after the other (the motion gate's twin shares its holding network's). ``worker_name``:
        the name of the worker thread (`core.job_worker`) that runs the trainings and ω0 jobs.
        ``cascade_output`` False: the caller never reads the output while the network does not
        serve (the motion gate's twin, `_gated`); with ``nfb`` 0 and no output smoothing the
        cascade fallback is then neither run nor retuned (its output could reach nothing) and
        the measured position stands in for it.
        """
        self.params = params
        self.max_trainings = max_trainings
        self.ndof = params.ndof
        self.sample_time = params.sample_time
        self.background = background
        self._checkpoint_path = checkpoint_path
        self._capacity = max(params.training_samples + params.transient_samples,
                             params.estimation_samples, params.filter_samples) + params.max_lag
        self._first_training = first_training_samples(params)
        self._training_lock = training_lock or threading.Lock()
        self._outcomes: queue.SimpleQueue[_JobOutcome] = queue.SimpleQueue()
        self._stop = threading.Event()
        self._worker = JobWorker(worker_name)  # trainings and ω0 jobs, one at a time
        # the worker's retrainings and ω0 spectrum fits run in a child process
        # (core.fit_process); inline: here
        self._fit_process: FitProcess | None = shared_fit_process() if background else None
        self._generation = 0
        self._model: NumpyNnarmax | None = None
        self._state_dict: dict[str, torch.Tensor] | None = None
        self._frequency: FrequencyEstimate | float | None = params.wave_peak_prior
        self._trainings = 0
        self._rejected = 0
        self._overruns = 0
        self._errors = 0
        self._last_loss: float | None = None
        self._train_seconds: float | None = None
        self._model_time: float | None = None
        self._message = 'collecting data'
        self._last_error: str | None = None
        self._fallback = CascadeFilter(params.ndof, params.sample_time, self._fallback_freq(),
                                       **fallback_design(params))
        self._output_notch: CascadeFilter | None = None  # output_notch_zeta > 0
        if params.output_notch_zeta > 0.0:
            self._output_notch = self._wave_notch(params.ndof, params.output_notch_zeta)
        self._now: float | None = None
        self._segment = 0
        self._fb_next: int = -1
        self._wave_spread: FloatArray | None = None
        # (the wave spread it was made from, the guard's bound per DOF), see _plausible
        self._guard_bound: tuple[FloatArray, list[float]] | None = None
        self._guard_trips = 0
        self._guard_floor = np.array(params.guard_floor[:params.ndof])
        self._no_thrust = 0  # accepted trainings whose thrust test failed (thrust_validation)
        self._thrust_held = 0  # accepted trainings that kept the thrust weights (thrust_hold)
        self._smoothing = params.switch_blend_time > 0.0 or any(
            rate > 0.0 for rate in params.max_output_rate[:params.ndof])
        # the cascade's output can reach the output or the regressors (see cascade_output)
        self._run_cascade = cascade_output or params.nfb > 0 or self._smoothing
        # Motion gate (issue 13): a ramp-invariant twin on the same data, blended in by
        # core.motion_gate when the vessel moves faster than it usually does.
        self._moving: AdaptivePredictor | None = None
        self._gate: MotionGate | None = None
        if params.motion_gate:
            self._moving = AdaptivePredictor(
                params.replace(motion_gate=False, ramp_invariant=True,
                               ny=params.motion_gate_ny or params.ny,
                               roughness_guard_time=0.0),  # the guard: holding network only
                background=background,
                checkpoint_path=twin_checkpoint_path(checkpoint_path) if checkpoint_path else None,
                max_trainings=max_trainings, training_lock=self._training_lock,
                worker_name='lf-predictor-twin-training', cascade_output=False)
            self._gate = MotionGate(params.ndof, params.sample_time,
                                    time_constant=params.motion_gate_time,
                                    window=params.training_window,
                                    fade_in=params.motion_gate_fade_in)
        self._roughness = (RoughnessGuard(params.ndof, params.sample_time,
                                          params.roughness_guard_time)
                           if params.roughness_guard_time > 0.0 else None)
        self._previous_model: NumpyNnarmax | None = None  # the network before _model
        self._rough_retirements = 0
        self._gain = np.zeros(params.ndof)
        # the offset the gate scaled at the last sample (None: none), for untaken_twin_offset
        self._scaled_offset: FloatArray | None = None
        smoothing = params.motion_gate_smoothing
        self._gate_alpha = 1.0 if smoothing <= 0.0 else min(1.0, params.sample_time / smoothing)
        self._gate_offset = np.zeros(params.ndof)  # LP(moving − holding) (motion_gate_smoothing)
        # motion_gate_validation: per DOF, may the gate act (shut until the first check)
        self._gate_valid = np.full(params.ndof, not params.motion_gate_validation)
        # motion_gate_yaw false: the gate never acts on the heading
        self._gate_dofs = np.array([True, True, params.motion_gate_yaw][:params.ndof])
        # motion_gate_yaw_notch: a notch at ω0 on the gate's heading difference (1 channel)
        self._gate_yaw_notch: CascadeFilter | None = None
        # motion_gate_yaw_moment_ratio: the heading gain from the yaw moment
        self._yaw_trigger: YawMomentTrigger | None = None
        if params.motion_gate and params.motion_gate_yaw and params.ndof == 3 and \
                params.motion_gate_yaw_moment_ratio > 0.0:
            self._yaw_trigger = YawMomentTrigger(params.sample_time,
                                                 params.motion_gate_yaw_moment_ratio,
                                                 params.motion_gate_yaw_hold,
                                                 params.motion_gate_yaw_warmup)
        if params.motion_gate and params.motion_gate_yaw and params.ndof == 3 and \
                params.motion_gate_yaw_notch > 0.0:
            self._gate_yaw_notch = self._wave_notch(1, params.motion_gate_yaw_notch)
        self._clear_output_state()
        self._start_segment()
        if background:
            warm_up()  # import torch's lazy modules now, not on the first training
            if self._fit_process is not None:
                self._fit_process.start()  # the child now, not at the first ω0 fit
            _LIVE_PREDICTORS.add(self)

    # ---- the LfEstimator interface ----------------------------------------------------------

    def update(self, t: float, pose: FloatArray, force: FloatArray) -> FloatArray:
        """Add the sample at time t; return the LF pose predicted for t + h (see module doc)."""
        pose_arr, force_arr = _checked(pose, 'pose'), _checked(force, 'force')
        if not math.isfinite(t):
            raise ValueError(f'sample time stamp must be finite, got {t}')
        self._now = t
        self._collect_outcomes(t)
        y = self._position(pose_arr)
        u = self._force_channels(force_arr, pose_arr[2])
        self._u.append(u)
        self._y.append(y)
        self._k += 1
        # the cascade fallback's estimate in position coordinates (the measurement without it)
        fallback = self._position(self._fallback.update(t, pose_arr, force_arr),
                                  update_heading=False) if self._run_cascade else y
        if self._fb_next != self._k:  # no network prediction exists for this sample
            self._fb.append(fallback)
        prediction = self._predict()
        if self._roughness is not None and self._roughness.update(y, prediction):
            prediction = self._retire_rough_network()
        model = self._model
        if prediction is not None and not self._plausible(prediction, y):
            self._guard_trips += 1
            self._message = 'network prediction implausible: cascade fallback'
            prediction = None
            self._fb.clear()
            self._fb.append(fallback)
        if prediction is None:
            self._used_network = False
            estimate = fallback
            self._fb_next = -1
        else:
            self._used_network = True
            estimate = prediction
            self._fb.append(prediction)
            self._fb_next = self._k + 1
        if self._smoothing:  # output only: the buffers above are not touched
            estimate = self._bumpless(t, estimate, model if prediction is not None else None,
                                      fallback)
        self._maybe_retrain(t)
        return self._notched(t, self._gated(t, self._output(estimate, pose_arr), pose_arr,
                                            force_arr))

    def _retire_rough_network(self) -> FloatArray | None:
        """``roughness_guard_time``: the network in service makes the loop oscillate: retire it.

        The network before it serves again (if there is one; a second trip retires that one too),
        else the cascade fallback, until the next accepted training; its weights stay the next
        warm start, as for a network retired by a training. Returns the new source's prediction.
        """
        self._rough_retirements += 1
        self._guard_trips += 1
        self._model, self._previous_model = self._previous_model, None
        self._fb.clear()
        assert self._roughness is not None
        self._roughness.reset()
        self._message = ('network rougher than the measurement (a limit cycle in the loop?): '
                         'retired, ' + ('the network before it serves' if self._model is not None
                                        else 'cascade fallback'))
        return self._predict()

    def reset(self) -> None:
        """Forget everything learned and collected (parameters stay); a running job is dropped.

        The dropped job stops at its next epoch boundary; the next job waits for that.
        """
        if self._moving is not None and self._gate is not None:
            self._moving.reset()
            self._gate.reset()
        if self._yaw_trigger is not None:
            self._yaw_trigger.reset()
        self._gate_valid = np.full(self.ndof, not self.params.motion_gate_validation)
        self._stop.set()
        self._generation += 1
        self._stop = threading.Event()
        self._model = self._previous_model = None
        self._state_dict = None
        self._frequency = self.params.wave_peak_prior
        self._trainings = self._rejected = 0
        self._last_loss = self._train_seconds = self._model_time = None
        self._last_error = None
        self._wave_spread = None
        self._message = 'reset: collecting data'
        self._tune_wave_filters(self._fallback_freq())
        self._clear_output_state()
        self.restart_segment()

    def status(self) -> EstimatorStatus:
        """Health for diagnostics (state, ω0, last loss and training time, model age, fill)."""
        state: EstimatorState
        if self._model is None and self._trainings > 0:
            state = 'fallback'  # the network was retired: worse than the cascade
        elif self._model is None:
            state = 'error' if self._last_error and self._trainings == 0 and \
                self._errors > 0 else 'warming_up'
        else:
            state = 'trained' if self._used_network else 'fallback'
        age = None
        if self._model_time is not None and self._now is not None:
            age = max(0.0, self._now - self._model_time)
        return EstimatorStatus(
            state=state, wave_peak_freq=self.wave_peak_freq, message=self._message,
            last_loss=self._last_loss, train_seconds=self._train_seconds, model_age=age,
            buffer_fill=min(1.0, len(self._y) / self._capacity), trainings=self._trainings,
            rejected_trainings=self._rejected)

    # ---- extra controls ---------------------------------------------------------------------

    def restart_segment(self) -> None:
        """Start a new data segment (after a gap or a time jump): the trained network stays.

        Regressors and training windows never span the restart: buffers, targets and feedback
        are cleared; predictions resume once max(nu, ny, nfb) new samples have arrived. With
        ``switch_blend_time`` T > 0 the output fades from the last published one if the next
        sample comes less than T later (else it starts afresh).
        """
        self._segment += 1
        self._start_segment()
        self._fallback.reset()
        if self._output_notch is not None:
            self._output_notch.reset()
        if self._moving is not None and self._gate is not None:
            self._moving.restart_segment()
            self._gate.restart()
        if self._gate_yaw_notch is not None:
            self._gate_yaw_notch.reset()

    def discard_running_job(self) -> None:
        """Drop the result of a running training or ω0 job; the network in service stays.

        For a data fault found after the fact (a frozen or drifting reference): the job's
        snapshot may hold faulty samples, so its result must not be used. The worker stops at its
        next epoch boundary; no new job starts until it has ended.
        """
        if self._moving is not None:
            self._moving.discard_running_job()
        self._stop.set()
        self._generation += 1
        self._stop = threading.Event()

    def request_retrain(self) -> tuple[bool, str]:
        """Ask for a training at the next sample; (False, reason) when it cannot happen."""
        if len(self._y) < self._first_training:
            return False, (f'not enough data: {len(self._y)} of {self._first_training} samples '
                           'needed for the first training')
        if self._job_running():
            return False, 'a training is already running'
        self._retrain_requested = True
        if self._moving is not None:
            self._moving.request_retrain()
        return True, 'training starts with the next sample'

    def wait_for_training(self, timeout: float | None = None) -> bool:
        """Block until the running jobs finish or ``timeout`` [s] has passed (None: no limit).

        True when none is running any more; with the motion gate the twin's job and the
        holding network's share the one timeout. For tests and offline tools only.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        done = True if self._moving is None else self._moving.wait_for_training(timeout)
        return self._worker.wait(None if deadline is None
                                 else max(0.0, deadline - time.monotonic())) and done

    def close(self) -> None:
        """Stop a running training (it is abandoned at its next epoch boundary).

        This one's stop is set before the twin is closed: the twin's worker may be waiting for
        the shared training lock, which this one's training holds until it stops.
        """
        self._stop.set()
        if self._moving is not None:
            self._moving.close()
        self.wait_for_training(timeout=5.0)
        self._worker.shutdown()

    @property
    def checkpoint_path(self) -> str | None:
        """Where the worker saves each accepted network (None or '': nowhere).

        Setting it also points the motion gate twin's worker at `twin_checkpoint_path` of it.
        """
        return self._checkpoint_path

    @checkpoint_path.setter
    def checkpoint_path(self, path: str | None) -> None:
        self._checkpoint_path = path
        if self._moving is not None:
            self._moving.checkpoint_path = twin_checkpoint_path(path) if path else None

    @property
    def using_network(self) -> bool:
        """True when the last output came from the network (``status().state == 'trained'``)."""
        return self._model is not None and self._used_network

    @property
    def wave_peak_freq(self) -> float | None:
        """Latest ω0 estimate [rad/s] (or the prior), None before the first estimate."""
        if isinstance(self._frequency, FrequencyEstimate):
            return self._frequency.wave_peak_freq
        return self._frequency

    @property
    def targets_peak_damping(self) -> float:
        """The sea's peak damping λ the current targets' filter was designed with (NaN: none).

        The fitted λ of the ω0 estimate, or NaN where ``notch_broadband_holding_only`` kept a
        manoeuvring window's notch narrow (`retraining.targets_peak_damping`): whoever filters
        other signals like the targets (the vessel memory's thrust) asks this, not the raw λ.
        """
        return self._targets_damping

    @property
    def narrow_reference(self) -> FloatArray | None:
        """The current targets' samples filtered with the narrow ``notch_zeta`` (read-only).

        None when the targets' notch is that narrow one (`retraining.narrow_reference`); else
        shape (len(targets), ndof), aligned with `targets`. The odometry's calibration reference.
        """
        return self._narrow_reference

    @property
    def model(self) -> NumpyNnarmax | None:
        """The network in service (immutable), None before the first accepted training."""
        return self._model

    @property
    def counters(self) -> dict[str, int]:
        """Trainings accepted/rejected, overruns (a retrain due while one ran), errors."""
        counts = {'trainings': self._trainings, 'rejected_trainings': self._rejected,
                  'overruns': self._overruns, 'training_errors': self._errors,
                  'guard_trips': self._guard_trips,
                  'rough_retirements': self._rough_retirements,
                  'segments': self._segment, 'trainings_without_thrust': self._no_thrust,
                  'trainings_thrust_held': self._thrust_held}
        if self._moving is not None:
            counts.update({f'moving_{key}': value for key, value in
                           self._moving.counters.items() if key != 'segments'})
        return counts

    @property
    def twin_model(self) -> NumpyNnarmax | None:
        """The motion gate twin's network in service (None: gate off, or the twin is cold)."""
        return None if self._moving is None else self._moving.model

    @property
    def motion_gain(self) -> FloatArray:
        """The motion gate's gain g per DOF at the last sample (zeros when the gate is off)."""
        return self._gain.copy()

    @property
    def untaken_twin_offset(self) -> FloatArray:
        """(1 − g) · the twin's offset per DOF at the last sample: the motion left out.

        The offset is the one the gate scales (the moving twin's estimate minus the holding
        output, low-passed with ``motion_gate_smoothing``, the heading notched with
        ``motion_gate_yaw_notch``; heading wrapped); g the published gain. In a move or a turn
        the twin follows and the holding filter lags, so this is what the published estimate
        probably lags by (``OdometryParams.pose_twin_gain``). Zeros when the gate is off or the
        twin is not on its network.
        """
        if self._scaled_offset is None:
            return np.zeros(self.ndof)
        return np.asarray((1.0 - self._gain) * self._scaled_offset, dtype=np.float64)

    @property
    def motion_gate_valid(self) -> NDArray[np.bool_]:
        """Per DOF, whether the gate may act (always True without motion_gate_validation)."""
        return self._gate_valid.copy()

    @property
    def omega_fits_here(self) -> int:
        """Background jobs this process computed on a worker thread: no child (0 inline).

        ω0 fits, retrainings and vessel-memory jobs; process-wide (one `core.fit_process` child
        serves every predictor and vessel memory of the process).
        """
        return 0 if self._fit_process is None else self._fit_process.failures

    @property
    def source_switches(self) -> int:
        """Changes of the output's source seen with bumpless transfer on (0 when off)."""
        return self._switches

    @property
    def targets(self) -> TargetWindow | None:
        """Current target window (for inspection and plots)."""
        return self._targets

    def save(self, path: str) -> None:
        """Write the network in service to a checkpoint; ValueError if there is none.

        With the motion gate on, the twin's network is written to `twin_checkpoint_path`
        (``path + '.twin'``) when it has one; when it has none, a twin file left there by an
        earlier save is removed, so that `load` never pairs this network with a stale twin.
        Gate off: ``path`` alone, nothing else touched.
        """
        if self._state_dict is None:
            raise ValueError('no trained network to save yet: wait for the first training')
        save_checkpoint(path, network_spec(self.params), self._state_dict, self._meta())
        if self._moving is None:
            return
        twin_path = twin_checkpoint_path(path)
        if self._moving._state_dict is None:
            Path(twin_path).unlink(missing_ok=True)
        else:
            self._moving.save(twin_path)

    def load(self, path: str, *, strict_twin: bool = True) -> None:
        """Warm start from a checkpoint; ValueError (clear message) if it does not fit.

        With the motion gate on, the twin is restored from `twin_checkpoint_path` (``path +
        '.twin'``) too. No twin file: the twin stays as it is (cold in a new predictor) and the
        status message says so. A twin file that does not fit the twin (its spec, or another
        sample_time) or is corrupt: ValueError and nothing is loaded, or with ``strict_twin``
        False the holding network is loaded and the twin stays cold (the status message says
        why; the node's carry-over after a run-time change of ``motion_gate_ny``).
        """
        checkpoint = self._read_checkpoint(path)
        twin_path = twin_checkpoint_path(path)
        twin_checkpoint = None
        note = ''
        if self._moving is not None:
            try:
                twin_checkpoint = self._moving._read_checkpoint(twin_path)
            except FileNotFoundError:
                note = f'; motion gate twin cold (no {Path(twin_path).name})'
            except (ValueError, OSError) as exc:
                if strict_twin:
                    raise ValueError(f'{exc}; or delete {twin_path} (the motion gate twin of '
                                     f'{path}) to start the twin cold') from exc
                note = f'; motion gate twin cold ({Path(twin_path).name} not loaded: {exc})'
        self._install(path, checkpoint)
        if self._moving is not None and twin_checkpoint is not None:
            self._moving._install(twin_path, twin_checkpoint)
            note = f'; motion gate twin from {Path(twin_path).name}'
        self._message = f'warm start from {Path(path).name}{note}'

    def _read_checkpoint(
            self, path: str) -> tuple[NnarmaxSpec, dict[str, torch.Tensor], dict[str, Any]]:
        """A checkpoint that fits this predictor: (spec, state, meta); ValueError if not."""
        spec, state, meta = load_checkpoint(path, expected_spec=network_spec(self.params))
        if float(meta.get('sample_time', self.sample_time)) != self.sample_time:
            raise ValueError(f'checkpoint {path} was trained at sample_time '
                             f'{meta.get("sample_time")} s, this predictor runs at '
                             f'{self.sample_time} s: use the same sample_time or retrain')
        return spec, state, meta

    def _install(self, path: str, checkpoint: tuple[NnarmaxSpec, dict[str, torch.Tensor],
                                                    dict[str, Any]]) -> None:
        """Put a checked checkpoint's network in service (its ω0 and loss with it)."""
        spec, state, meta = checkpoint
        self._state_dict = state
        self._previous_model = None  # a loaded network has no predecessor to fall back to
        self._model = NumpyNnarmax.from_module(
            NnarmaxNet.from_state(spec, state)).with_saved_ranges(meta)
        self._model_time = None
        freq = meta.get('wave_peak_freq')
        if isinstance(freq, (int, float)) and math.isfinite(freq) and freq > 0:  # else: kept
            self._frequency = float(freq)
            self._tune_wave_filters(float(freq))
        self._last_loss = meta.get('loss')
        self._message = f'warm start from {Path(path).name}'

    # ---- internals --------------------------------------------------------------------------

    def _start_segment(self) -> None:
        # thrust and pose rows of the segment: the regressors' and the snapshots' rows are views
        self._u = _NewestRows(self._capacity)
        self._y = _NewestRows(self._capacity)
        self._fb: deque[FloatArray] = deque(maxlen=max(1, self.params.nfb))
        self._heading = ContinuousHeading()
        self._gate_offset = np.zeros(self.ndof)
        # (k, holding output, gated output) per sample, for motion_gate_validation
        self._gate_log: deque[tuple[int, FloatArray, FloatArray]] = deque(maxlen=self._capacity)
        self._gate_checked: TargetWindow | None = None
        self._k = -1
        self._fb_next = -1
        self._last_train_k: int | None = None
        self._last_freq_k: int | None = None
        self._targets: TargetWindow | None = None
        # sea_change_revert: (ω0, targets) in service before the newest restart, and its index
        self._before_restart: tuple[float, TargetWindow, int] | None = None
        self._targets_damping = math.nan  # targets_peak_damping of ``_targets``
        self._narrow_reference: FloatArray | None = None  # narrow_reference of ``_targets``
        self._retrain_requested = False
        self._used_network = False
        if self._roughness is not None:  # second differences never span a segment restart
            self._roughness.reset()

    def _tune_wave_filters(self, wave_peak_freq: float,
                           fallback_plan: CascadePlan | None = None,
                           notch_plans: Mapping[float, CascadePlan] | None = None) -> None:
        """Retune the cascade fallback and the notches to ω0 [rad/s] (outputs continuous).

        ``fallback_plan`` / ``notch_plans``: the fallback / the notches (by width) planned at
        that ω0 by the job (`retrain_and_plan`); a filter without a plan designs itself.
        """
        if self._run_cascade:
            self._fallback.set_wave_peak_freq(wave_peak_freq, fallback_plan)
        plans = notch_plans or {}
        for notch, zeta in self._notches():
            notch.set_wave_peak_freq(wave_peak_freq, plans.get(zeta))

    def _notches(self) -> list[tuple[CascadeFilter, float]]:
        """The notches retuned with ω0 and their widths ζ (`_wave_notch`)."""
        return [(notch, zeta) for notch, zeta in (
            (self._output_notch, self.params.output_notch_zeta),
            (self._gate_yaw_notch, self.params.motion_gate_yaw_notch)) if notch is not None]

    def _wave_notch(self, channels: int, notch_zeta: float) -> CascadeFilter:
        """A causal notch at ω0 (width ``notch_zeta``, depth notch_depth, no low-pass)."""
        return CascadeFilter(channels, self.params.sample_time, self._fallback_freq(),
                             **notch_design(self.params, notch_zeta))

    def _notched(self, t: float, out: FloatArray) -> FloatArray:
        """The published pose through the output notch (``output_notch_zeta``; off: ``out``).

        Only the estimated DOFs are filtered (1 DOF: east and yaw stay the measured ones). A
        non-finite output passes unchanged and restarts the notch, which starts again in steady
        state at the next finite output (no step).
        """
        if self._output_notch is None:
            return out
        if not np.all(np.isfinite(out)):
            self._output_notch.reset()
            return out
        notched = np.array(out, dtype=np.float64)
        notched[:self.ndof] = self._output_notch.update(t, out, _NO_FORCE)[:self.ndof]
        return notched

    def _fallback_freq(self) -> float:
        freq = self.wave_peak_freq
        if freq is None:
            low, high = self.params.wave_band
            freq = math.sqrt(low * high)  # geometric band centre until ω0 is estimated
        return float(freq)

    def _position(self, pose: FloatArray, update_heading: bool = True) -> FloatArray:
        if self.ndof == 1:
            return np.array([pose[0]])
        yaw = float(pose[2])
        if update_heading:
            yaw = self._heading.update(yaw)
        else:
            ref = self._heading.value
            yaw = yaw if ref is None else ref + float(wrap_angle(yaw - ref))
        return np.array([pose[0], pose[1], yaw])

    def _force_channels(self, force: FloatArray, yaw: float) -> FloatArray:
        if self.ndof == 1:
            return np.array([force[0]])
        c, s = math.cos(yaw), math.sin(yaw)
        return np.array([c * force[0] - s * force[1], s * force[0] + c * force[1], force[2]])

    def _predict(self) -> FloatArray | None:
        model = self._model
        if model is None:
            return None
        prediction = self._predict_with(model)
        if prediction is None:
            return None
        if not all_finite(prediction):
            self._message = 'network output not finite: cascade fallback'
            return None
        return np.asarray(prediction, dtype=np.float64)

    def _predict_with(self, model: NumpyNnarmax) -> FloatArray | None:
        """The raw prediction of ``model`` from the buffers; None while they are too short."""
        p = self.params
        if len(self._y) < p.max_lag or len(self._fb) < p.nfb:
            return None
        u_hist = self._u.newest(max(p.nu, 1))  # only the rows the regressors need:
        y_hist = self._y.newest(max(p.ny, 1))  # the buffers hold up to N + ε samples
        fb_hist = _newest(self._fb, p.nfb) if p.nfb else _NO_ROWS  # nfb 0: not read
        return predict_step(model, u_hist, y_hist, fb_hist)

    def _plausible(self, prediction: FloatArray, y: FloatArray) -> bool:
        spread = self._wave_spread
        if spread is None:
            return True
        guard = self._guard_bound
        if guard is None or guard[0] is not spread:  # a new network's spread: a new bound
            guard = self._guard_bound = (
                spread, (GUARD_SPREADS * spread + self._guard_floor).tolist())
        bound = guard[1]
        predicted, measured = np.asarray(prediction).tolist(), np.asarray(y).tolist()
        if not (isinstance(bound, list) and isinstance(predicted, list) and
                isinstance(measured, list) and len(bound) == len(predicted) == len(measured)):
            return bool(np.all(np.abs(prediction - y) <= bound))  # not one pose: broadcast
        # np.all(|prediction − y| <= bound) of one pose (NaN is not plausible)
        return all(abs(a - b) <= c for a, b, c in zip(predicted, measured, bound, strict=True))

    # ---- bumpless transfer and rate limit (output only; off with the defaults) ---------------

    def _clear_output_state(self) -> None:
        self._last_source: NumpyNnarmax | None = None
        self._source_known = False  # no output yet: the first one is no switch
        self._transfer: _Transfer | None = None
        self._last_out: FloatArray | None = None  # last published estimate (position coords)
        self._last_t: float | None = None
        self._last_cascade: tuple[int, FloatArray] | None = None  # (segment, cascade value)
        self._switches = 0

    def _bumpless(self, t: float, value: FloatArray, source: NumpyNnarmax | None,
                  cascade: FloatArray) -> FloatArray:
        """The published estimate: ``value`` of ``source`` blended and rate limited."""
        blend_time = self.params.switch_blend_time
        last_t = self._last_t
        continuous = last_t is not None and 0.0 < t - last_t < blend_time
        out = value
        if blend_time > 0.0:
            if not continuous:
                self._transfer = None  # first sample, a time jump or a gap of ≥ T: no blend
            elif self._source_known and source is not self._last_source:
                self._switches += 1
                self._begin_transfer(t, value, source, cascade)
            self._last_source, self._source_known = source, True
            out = self._blended(t, value, cascade)
        out = self._rate_limited(t, out)
        self._last_out, self._last_t = out.copy(), t
        self._last_cascade = (self._segment, cascade)
        return out

    def _begin_transfer(self, t: float, value: FloatArray, source: NumpyNnarmax | None,
                        cascade: FloatArray) -> None:
        """Start blending from what the output was about to be to ``source``."""
        previous, running = self._last_source, self._transfer
        previous_value = self._source_value(previous, cascade)
        if running is None and previous_value is not None:
            self._transfer = _Transfer(previous, None, t)  # the old source keeps running
            return
        if running is not None and previous_value is not None:
            phase = (t - running.start) / self.params.switch_blend_time
            if running.offset is None and running.source is source and phase < 1.0:
                # back to the old source of the blend: run the same ramp in reverse
                start = t - (1.0 - phase) * self.params.switch_blend_time
                self._transfer = _Transfer(previous, None, start)
                return
            old = self._old_value(running, previous_value, cascade)
            if old is not None:
                reference = old + _smoothstep(phase) * self._difference(previous_value, old)
                self._transfer = _Transfer(None, self._difference(reference, value), t)
                return
        # the old source cannot run (implausible, not finite, new segment): fade from the last
        # published output, held as an offset to the new source (to the cascade's value at that
        # output when the cascade takes over in the same segment: the output keeps its motion)
        assert self._last_out is not None  # a switch needs an earlier output
        reference = value
        if source is None and self._last_cascade is not None and \
                self._last_cascade[0] == self._segment:
            reference = self._last_cascade[1]
        self._transfer = _Transfer(None, self._difference(self._last_out, reference), t)

    def _blended(self, t: float, value: FloatArray, cascade: FloatArray) -> FloatArray:
        transfer = self._transfer
        if transfer is None:
            return value
        phase = (t - transfer.start) / self.params.switch_blend_time
        if phase >= 1.0:
            self._transfer = None
            return value
        old = self._old_value(transfer, value, cascade)
        if old is None:  # the old network stopped predicting: fade from the last output
            assert self._last_out is not None
            transfer = self._transfer = _Transfer(None, self._difference(self._last_out, value),
                                                  t)
            return value + transfer.offset  # type: ignore[operator]
        blended: FloatArray = old + _smoothstep(phase) * self._difference(value, old)
        return blended

    def _old_value(self, transfer: _Transfer, new_value: FloatArray,
                   cascade: FloatArray) -> FloatArray | None:
        """The old source's value now (None if it cannot run any more)."""
        if transfer.offset is not None:
            held: FloatArray = new_value + transfer.offset
            return held
        return self._source_value(transfer.source, cascade)

    def _source_value(self, source: NumpyNnarmax | None,
                      cascade: FloatArray) -> FloatArray | None:
        """A source's value now: the cascade, or a network if it predicts plausibly."""
        if source is None:
            return cascade
        prediction = self._predict_with(source)
        if prediction is None or not np.all(np.isfinite(prediction)) or \
                not self._plausible(prediction, self._y.newest(1)[0]):
            return None
        return np.asarray(prediction, dtype=np.float64)

    def _rate_limited(self, t: float, value: FloatArray) -> FloatArray:
        """``value`` moved from the last output by at most max_output_rate × elapsed time."""
        rates = np.array(self.params.max_output_rate[:self.ndof])
        last, last_t = self._last_out, self._last_t
        if not np.any(rates > 0.0) or last is None or last_t is None or not t > last_t:
            return value
        bound = np.where(rates > 0.0, rates * (t - last_t), np.inf)
        limited: FloatArray = last + np.clip(self._difference(value, last), -bound, bound)
        return limited

    def _difference(self, a: FloatArray, b: FloatArray) -> FloatArray:
        """The difference a − b of two positions, heading wrapped to (−π, π]."""
        return wrap_pose(np.asarray(a, dtype=np.float64) - b, self.ndof)

    def _gated(self, t: float, out: FloatArray, pose: FloatArray,
               force: FloatArray) -> FloatArray:
        """The holding network's output blended with the moving twin's (``core.motion_gate``).

        Only while the twin uses its network (its cascade fallback is the holding side's);
        the holding side may be on its cascade fallback, which lags a move as its network does.
        The gate's velocity and usual velocity are those of the twin's network alone: while the
        twin is on its fallback the gate restarts (its history of the network's motion stays),
        so it opens only after ``GATE_MIN_FILL`` of a window of the network's own outputs.
        With ``motion_gate_yaw_moment_ratio`` the heading's gain is the yaw moment's
        (``core.yaw_moment_trigger``, fed every sample's moment, or with
        ``motion_gate_yaw_network_level`` only those applied while the twin uses its network:
        the moments a DP loop applies on the cascade fallback's estimates are another filter's
        loop's, as the gate's usual velocity) instead of the velocity's.
        """
        if self._moving is None or self._gate is None:
            return out
        moving = self._moving.update(t, pose, force)
        # motion_gate_yaw_moment_ratio: the heading gain of this sample, from the yaw moment;
        # with motion_gate_yaw_network_level only the moments applied while the twin serves
        # from its network are evidence (NaN: skipped, the hold goes on)
        yaw_gain = None
        if self._yaw_trigger is not None:
            yaw_gain = self._yaw_trigger.update(
                float(force[2]) if self._moving.using_network
                or not self.params.motion_gate_yaw_network_level else math.nan)
        offset = moving_offset(out, moving, self.ndof)
        if not self._moving.using_network or not all_finite(offset):
            # The gate measures the twin's network alone: the usual velocity of the cascade
            # fallback is another filter's, and the step where the source switches is no motion.
            self._gate.restart()
            self._gain = np.zeros(self.ndof)
            self._scaled_offset = None
            self._gate_offset = np.zeros(self.ndof)
            if self._gate_yaw_notch is not None:
                self._gate_yaw_notch.reset()
            self._validate_gate(out, out)
            return out
        gain = dead_zoned(self._gate.update(moving), self.params.motion_gate_dead_zone)
        if self._gate_alpha < 1.0:
            # LP(moving − holding) of core.motion_gate (motion_gate_smoothing)
            self._gate_offset = low_pass_step(self._gate_offset, offset, self._gate_alpha)
            offset = self._gate_offset
        if self._gate_yaw_notch is not None:
            offset = self._yaw_notched(t, offset)
        # gain · motion_gate_yaw mask, then · the validation mask (bool → 1.0 / 0.0)
        gains = [g * (1.0 if on else 0.0)
                 for g, on in zip(gain.tolist(), self._gate_dofs.tolist(), strict=True)]
        if self.params.motion_gate_validation:  # the gated output is only logged for it
            self._validate_gate(out, shifted(out, np.array(gains) * offset, self.ndof))
        if yaw_gain is not None:  # (the validation above judged the velocity gain)
            gains[2] = yaw_gain
        gains = [g * (1.0 if on else 0.0)
                 for g, on in zip(gains, self._gate_valid.tolist(), strict=True)]
        self._gain = np.array(gains, dtype=np.float64)
        self._scaled_offset = offset
        return shifted(out, self._gain * offset, self.ndof)

    def _yaw_notched(self, t: float, offset: FloatArray) -> FloatArray:
        """The gate's offset with its heading entry through the notch at ω0 (a new array).

        ``motion_gate_yaw_notch``: the difference is a small wrapped angle, filtered as one
        channel (the notch starts from the first difference in steady state after a reset).
        """
        assert self._gate_yaw_notch is not None
        notched = np.array(offset, dtype=np.float64)
        notched[2] = self._gate_yaw_notch.update(t, np.array([offset[2], 0.0, 0.0]),
                                                 _NO_FORCE)[0]
        return notched

    def _validate_gate(self, holding: FloatArray, gated: FloatArray) -> None:
        """motion_gate_validation: log this sample's two outputs; check at a new target window.

        The output predicted at sample k is for k + 1: it is compared with target k + 1. The
        newest ε targets (filter transients) are left out.
        """
        if not self.params.motion_gate_validation:
            return
        self._gate_log.append((self._k, holding[:self.ndof].copy(), gated[:self.ndof].copy()))
        targets = self._targets
        if targets is None or targets is self._gate_checked:
            return
        self._gate_checked = targets
        usable = len(targets) - self.params.transient_samples
        if usable <= 0:
            return
        values = np.asarray(targets.values, dtype=np.float64).reshape(len(targets), -1)[:usable]
        wanted = targets.indices()[:usable] - 1  # the sample whose output predicted the target
        log = list(self._gate_log)  # a deque indexes in O(n)
        logged = np.array([entry[0] for entry in log])
        where = np.searchsorted(logged, wanted)
        found = (where < logged.shape[0]) & (logged[np.minimum(where, logged.shape[0] - 1)]
                                             == wanted)
        rows = where[found]
        holding_rows = np.array([log[i][1] for i in rows]).reshape(-1, self.ndof)
        gated_rows = np.array([log[i][2] for i in rows]).reshape(-1, self.ndof)
        self._gate_valid = gate_validated(holding_rows, gated_rows, values[found],
                                          self._gate_valid, max(1, usable // 2))

    def _output(self, estimate: FloatArray, measured: FloatArray) -> FloatArray:
        """Estimate as a pose; for 1 DOF east and yaw are the measurement, unfiltered."""
        out = np.array(measured, dtype=np.float64)
        out[:self.ndof] = estimate
        out[2] = float(wrap_angle(out[2]))
        return out

    def _job_running(self) -> bool:
        return self._worker.busy

    def _maybe_retrain(self, t: float) -> None:
        n = len(self._y)
        if n < self._first_training:
            self._maybe_estimate_frequency(n)
            return
        if self.max_trainings is not None and self._trainings >= self.max_trainings:
            return
        due = self._last_train_k is None or \
            self._k - self._last_train_k >= self.params.retrain_samples
        if not (due or self._retrain_requested):
            return
        if self._job_running():
            if self._k == (self._last_train_k or 0) + self.params.retrain_samples:
                self._overruns += 1
            return
        self._retrain_requested = False
        self._last_train_k = self._k
        snapshot = Snapshot(u=self._u.newest(len(self._u)).copy(),
                            y=self._y.newest(len(self._y)).copy(), end_index=self._k,
                            segment=self._segment)
        args = (self._generation, snapshot, self._state_dict, self._targets, self._frequency,
                self._stop, self._revertible())
        if self.background:
            self._worker.submit(self._job, *args)
        else:
            self._job(*args)
            self._collect_outcomes(t)

    def _revertible(self) -> tuple[float, TargetWindow] | None:
        """``sea_change_revert``: what a restart at most 2Δ ago replaced, else None.

        A query: an older entry is only ignored here, the next restart replaces it.
        """
        before = self._before_restart
        if before is None or self._k - before[2] > 2 * self.params.retrain_samples:
            return None
        return before[0], before[1]

    def _maybe_estimate_frequency(self, n: int) -> None:
        """Before the first training: estimate ω0 early (every Δ) to tune the fallback cascade."""
        if isinstance(self._frequency, FrequencyEstimate) or n < self._first_training // 2:
            return
        if self._last_freq_k is not None and \
                self._k - self._last_freq_k < self.params.retrain_samples:
            return
        if self._job_running():
            return
        self._last_freq_k = self._k
        args = (self._generation, self._y.newest(len(self._y)).copy(), self._frequency)
        if self.background:
            self._worker.submit(self._frequency_job, *args)
        else:
            self._frequency_job(*args)

    def _frequency_job(self, generation: int, y: FloatArray,
                       previous: FrequencyEstimate | float | None) -> None:
        """Worker body of an ω0 job (`estimate_and_plan`, in the child as `_job`)."""
        plan_fallback = self._run_cascade
        notch_zetas = tuple(zeta for _, zeta in self._notches())

        def here() -> tuple[FrequencyEstimate, CascadePlan | None, dict[float, CascadePlan]]:
            with spectrum_fit_by(self._fit_process):
                return estimate_and_plan(self.params, y, previous, plan_fallback, notch_zetas)

        try:
            if self._fit_process is None:
                estimate, plan, notch_plans = here()
            else:
                estimate, plan, notch_plans = self._fit_process.run(
                    estimate_and_plan, self.params, y, previous, plan_fallback, notch_zetas,
                    fallback=here)
        except (ValueError, FloatingPointError):
            return  # too little data for the spectrum yet: try again after Δ
        self._outcomes.put(_JobOutcome(generation, None, None, frequency=estimate,
                                       fallback_plan=plan, notch_plans=notch_plans))

    def _job(self, generation: int, snapshot: Snapshot,
             incumbent: dict[str, torch.Tensor] | None, targets: TargetWindow | None,
             frequency: FrequencyEstimate | float | None, stop: threading.Event,
             before_restart: tuple[float, TargetWindow] | None = None) -> None:
        """Worker body: never raises; the outcome goes through the queue."""
        plan_fallback = self._run_cascade
        notch_zetas = tuple(zeta for _, zeta in self._notches())

        def here() -> tuple[RetrainResult, CascadePlan | None, dict[float, CascadePlan]]:
            with spectrum_fit_by(self._fit_process):
                return retrain_and_plan(self.params, snapshot, incumbent, targets, frequency,
                                        stop, before_restart, plan_fallback, notch_zetas)

        try:
            with self._training_lock:  # one training at a time per lock (the gate's twin)
                if self._fit_process is None:
                    result, plan, notch_plans = here()
                else:  # in the child (core.fit_process), where it holds no GIL of the node's
                    result, plan, notch_plans = self._fit_process.run(
                        retrain_and_plan, self.params, snapshot, incumbent, targets, frequency,
                        None, before_restart, plan_fallback, notch_zetas, stop=stop,
                        fallback=here)
        except JobAbandonedError:
            return  # stopped (closed, or its result discarded): nobody takes an outcome
        except Exception as exc:  # noqa: BLE001 - any failure must keep the node alive
            self._outcomes.put(_JobOutcome(generation, None, exc))
            return
        saved_error = None
        if result.accepted and result.state_dict is not None and self.checkpoint_path:
            try:
                save_checkpoint(self.checkpoint_path, network_spec(self.params),
                                result.state_dict, self._meta(result))
            except (OSError, ValueError) as exc:
                saved_error = f'checkpoint not saved: {exc}'
        self._outcomes.put(_JobOutcome(generation, result, None, saved_error,
                                       fallback_plan=plan, notch_plans=notch_plans))

    def _collect_outcomes(self, t: float) -> None:
        if self._outcomes.empty():  # the usual case, without raising queue.Empty
            return
        while True:
            try:
                outcome = self._outcomes.get_nowait()
            except queue.Empty:
                return
            if outcome.generation == self._generation:
                self._apply(outcome, t)

    def _apply(self, outcome: _JobOutcome, t: float) -> None:
        if outcome.frequency is not None:
            if outcome.frequency.confident or self._frequency is None:
                self._frequency = outcome.frequency
                self._tune_wave_filters(outcome.frequency.wave_peak_freq,
                                        outcome.fallback_plan, outcome.notch_plans)
                self._message = (f'collecting data; ω0 ≈ {outcome.frequency.wave_peak_freq:.3f} '
                                 'rad/s, cascade fallback tuned to it')
            return
        if outcome.error is not None or outcome.result is None:
            self._errors += 1
            self._last_error = f'{type(outcome.error).__name__}: {outcome.error}'
            self._message = f'training failed, network in service kept ({self._last_error})'
            return
        result = outcome.result
        self._train_seconds = result.seconds
        if result.segment == self._segment:
            self._remember_restart(result)
            self._targets = result.targets
            self._targets_damping = result.targets_peak_damping
            self._narrow_reference = result.narrow_reference
        self._frequency = result.frequency
        self._tune_wave_filters(result.frequency.wave_peak_freq, outcome.fallback_plan,
                                outcome.notch_plans)
        if result.restarted:
            # the network before is the old sea's: a retirement falls back to the cascade, tuned
            # to the new ω0, not to a network trained on waves that are gone
            self._previous_model = None
        if result.accepted and result.model is not None:
            if not result.restarted:
                self._previous_model = self._model
            self._model, self._state_dict = result.model, result.state_dict
            self._no_thrust += 0 if result.thrust_used else 1
            self._thrust_held += 1 if result.thrust_held else 0
            self._wave_spread = result.wave_spread
            self._model_time = t
            self._trainings += 1
            self._last_loss = result.loss
            self._last_error = None
            self._message = (f'trained #{self._trainings}: loss {result.loss:.3g} in '
                             f'{result.seconds:.2f} s, ω0 {result.frequency.wave_peak_freq:.3f}')
        else:
            self._rejected += 1
            self._message = f'training rejected: {result.reason}'
            if result.retire_incumbent and self._model is not None:
                self._model = None  # weights stay as the next warm start
                self._message += '; network in service is worse than the cascade: retired'
        if outcome.saved_error:
            self._message += f'; {outcome.saved_error}'

    def _remember_restart(self, result: RetrainResult) -> None:
        """``sea_change_revert``: keep what a restart replaces; forget it once reverted."""
        if result.reverted:
            self._before_restart = None
        elif result.restarted and self.params.sea_change_revert and \
                self._targets is not None and self._frequency is not None:
            old = self._frequency
            freq = old.wave_peak_freq if isinstance(old, FrequencyEstimate) else float(old)
            self._before_restart = (freq, self._targets, result.end_index)

    def _meta(self, result: RetrainResult | None = None) -> dict[str, Any]:
        meta: dict[str, Any] = {'sample_time': self.sample_time, 'ndof': self.ndof,
                                'params': _jsonable(self.params.to_dict()),
                                'saved_unix_time': time.time()}
        freq = result.frequency.wave_peak_freq if result else self.wave_peak_freq
        meta['wave_peak_freq'] = freq
        meta['loss'] = result.loss if result else self._last_loss
        model = result.model if result else self._model
        if model is not None:  # regressor_clip: the ranges travel with the network
            meta.update(model.range_meta())
        return meta


def _newest(rows: deque[FloatArray], count: int) -> FloatArray:
    """The newest ``count`` rows of a buffer, oldest first, without copying the rest."""
    n = min(count, len(rows))
    return np.array([rows[i] for i in range(-n, 0)])


def _checked(value: FloatArray, name: str) -> FloatArray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (3,) or not all_finite(arr):
        raise ValueError(f'{name} must be 3 finite numbers [north, east, yaw] / [X, Y, N], got '
                         f'{value!r}')
    return arr


def _jsonable(values: dict[str, Any]) -> dict[str, Any]:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in values.items()}
