"""The LF state estimator: the adaptive predictor + its vessel memory + LF odometry.

``LfStateEstimator`` is what nodes, replay and the benchmark run when they need more than the
LF pose (issue 14): every ``update`` feeds the ``AdaptivePredictor`` (thesis Alg. 4.1) and hands
its LF pose to ``LfOdometry`` (velocity, covariances, dead reckoning). Whenever a retraining has
produced new zero-phase targets, the vessel memory is learned from them and the applied thrust
(``core.lf_dynamics.learn_vessel_memory``) and the covariances are recalibrated against them.
With ``background`` the vessel memory and the calibration run on a worker thread (the update
path only hands over copies and picks up a finished result, it never waits), as the network's
training does.

``coast(t, force)`` is the dead-reckoning step for a time with thrust but no accepted pose.
"""
from __future__ import annotations

from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np
from numpy.typing import NDArray

from lf_predictor_ros.core.estimator import EstimatorStatus
from lf_predictor_ros.core.lf_dynamics import VesselMemory, learn_vessel_memory
from lf_predictor_ros.core.odometry import (
    Covariances,
    EstimateSource,
    LfOdometry,
    OdometryEstimate,
    OdometryParams,
    Published,
    calibrate,
)
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.predictor import AdaptivePredictor
from lf_predictor_ros.core.retraining import target_filter
from lf_predictor_ros.core.targets import TargetWindow

FloatArray = NDArray[np.float64]


class LfStateEstimator:
    """Adaptive predictor + vessel memory + odometry (see the module docstring)."""

    def __init__(self, params: PredictorParams, odometry: OdometryParams | None = None, *,
                 background: bool = True, predictor: AdaptivePredictor | None = None,
                 checkpoint_path: str | None = None) -> None:
        """Create; ``predictor`` may be given (e.g. a warm-started one), else a new one."""
        self.params = params
        self.ndof = params.ndof
        self.sample_time = params.sample_time
        self.background = background
        self.predictor = predictor or AdaptivePredictor(
            params, background=background, checkpoint_path=checkpoint_path)
        self.odometry = LfOdometry(params.ndof, params.sample_time, odometry)
        self._capacity = params.training_samples + params.transient_samples + params.max_lag + \
            params.retrain_samples * 2
        self._executor: ThreadPoolExecutor | None = None
        self._job: Future[tuple[VesselMemory | None, Covariances | None]] | None = None
        self._memory_error: str | None = None
        self._restart_buffers()

    def update(self, t: float, pose: FloatArray, force: FloatArray) -> tuple[
            FloatArray, OdometryEstimate | None]:
        """One sample: (LF pose valid at t + h, odometry for t + h) (see AdaptivePredictor).

        The odometry is None when t + h is older than an estimate already given (poses arriving
        late after dead reckoning has moved on): the predictor still learns from the sample.
        """
        lf_pose = self.predictor.update(t, pose, force)
        self._times.append(t)
        self._forces.append(np.array(force[:self.ndof], dtype=np.float64))
        self._count += 1
        self._collect()
        self._maybe_learn()
        if self.odometry.is_late(t + self.sample_time):
            return lf_pose, None  # older than an estimate already dead-reckoned
        source: EstimateSource = 'network' if self.predictor.using_network else 'fallback'
        odom = self.odometry.track(t + self.sample_time, lf_pose, force, source)
        return lf_pose, odom

    def coast(self, t: float, force: FloatArray) -> OdometryEstimate | None:
        """Thrust at t without an accepted pose: dead reckoning (None when lost or never fixed)."""
        self._collect()
        return self.odometry.coast(t, force)

    def restart_segment(self) -> None:
        """A new data segment for the predictor.

        The odometry keeps its state for dead reckoning across the gap (and its calibration
        and vessel memory).
        """
        self.predictor.restart_segment()
        self._restart_buffers()

    def reset(self) -> None:
        """Forget everything (predictor, odometry, memory)."""
        self.predictor.reset()
        self.odometry.reset()
        self._job = None
        self._restart_buffers()

    def status(self) -> EstimatorStatus:
        """The predictor's status."""
        return self.predictor.status()

    def close(self) -> None:
        """Stop the workers."""
        self.predictor.close()
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None

    @property
    def memory(self) -> VesselMemory | None:
        """The vessel memory in use."""
        return self.odometry.memory

    @property
    def memory_error(self) -> str | None:
        """Why the last vessel-memory job failed (None if it did not)."""
        return self._memory_error

    # ---- internals -------------------------------------------------------------------------

    def _restart_buffers(self) -> None:
        self._times: deque[float] = deque(maxlen=self._capacity)
        self._forces: deque[FloatArray] = deque(maxlen=self._capacity)
        self._count = 0  # samples in this segment (= predictor's index + 1)
        self._seen_targets: TargetWindow | None = None
        self._job = None

    def _maybe_learn(self) -> None:
        targets = self.predictor.targets
        if targets is None or targets is self._seen_targets or self._job is not None:
            return
        self._seen_targets = targets
        first = self._count - len(self._times)  # segment index of the oldest buffered sample
        idx = targets.indices() - first
        keep = (idx >= 0) & (idx < len(self._times))
        if np.count_nonzero(keep) < 3:
            return
        times = np.array(self._times)[idx[keep]]
        values = np.array(targets.values, dtype=np.float64).reshape(len(targets), -1)[keep]
        # the newest ε targets are still filter transients (targets.training_mask): left out
        usable = max(3, values.shape[0] - self.params.transient_samples)
        times, values, rows = times[:usable], values[:usable], idx[keep][:usable]  # contiguous
        odometry = self.odometry
        args = (self.params, times, values, np.array(self._forces)[rows],
                self.predictor.wave_peak_freq, odometry.published(),
                odometry.params.dead_reckoning_timeout, odometry.params.min_calibration_samples,
                odometry.params.pose_lag_prior,
                _input_gain(odometry.params.vessel_inertia, self.ndof))
        if self.background:
            if self._executor is None:
                self._executor = ThreadPoolExecutor(1, thread_name_prefix='lf-vessel-memory')
            self._job = self._executor.submit(_learn, *args)
        else:
            self._apply(_learn(*args))

    def _collect(self) -> None:
        job = self._job
        if job is None or not job.done():
            return
        self._job = None
        try:
            self._apply(job.result())
        except Exception as exc:  # noqa: BLE001 - reported in the diagnostics, never raised
            self._memory_error = f'{type(exc).__name__}: {exc}'

    def _apply(self, result: tuple[VesselMemory | None, Covariances | None]) -> None:
        self.odometry.apply_learned(*result)
        self._memory_error = None


def _learn(params: PredictorParams, times: FloatArray, values: FloatArray, forces: FloatArray,
           wave_peak_freq: float | None, published: list[Published], horizon: float,
           min_samples: int, lag_prior: float,
           input_gain: FloatArray | None = None) -> tuple[VesselMemory | None,
                                                          Covariances | None]:
    """Worker job: the vessel memory of one target window and the calibrated covariances.

    ``forces``: the thrust at the targets' instants; the targets' zero-phase filter (at
    ``wave_peak_freq``; None: no ω0 yet, no filter) is designed here, off the predict path
    (≈ 0.6 ms), and the fit applies it to the forces too (`lf_dynamics.paired_forces`).
    The memory is None if it cannot be learned; the covariances compare the published estimates
    with the window (`odometry.calibrate`).
    """
    sos = None if wave_peak_freq is None else target_filter(params, wave_peak_freq)
    try:
        memory: VesselMemory | None = learn_vessel_memory(values, forces, params.sample_time,
                                                          horizon, input_gain, sos)
    except ValueError:
        memory = None
    return memory, calibrate(published, times, values, params.ndof, params.sample_time,
                             min_samples, lag_prior)


def _input_gain(inertia: tuple[float, ...], ndof: int) -> FloatArray | None:
    """1 / M_ii for the estimated DOFs, or None when the inertia is not given (0)."""
    if inertia[0] <= 0.0:
        return None
    return 1.0 / np.array(inertia[:ndof], dtype=np.float64)
