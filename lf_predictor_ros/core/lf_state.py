"""The LF state estimator: the adaptive predictor + its vessel memory + LF odometry.

``LfStateEstimator`` is what nodes, replay and the benchmark run when they need more than the
LF pose (issue 14): every ``update`` feeds the ``AdaptivePredictor`` (thesis Alg. 4.1) and hands
its LF pose to ``LfOdometry`` (velocity, covariances, dead reckoning). Whenever a retraining has
produced new zero-phase targets, the vessel memory is learned from them and the applied thrust
(``core.lf_dynamics.learn_vessel_memory``) and the covariances are recalibrated against them.
With ``background`` the vessel memory and the calibration run in the child process of
`core.fit_process`, handed over by a worker thread (the update path only hands over copies and
picks up a finished result, it never waits), as the network's training does.

``coast(t, force)`` is the dead-reckoning step for a time with thrust but no accepted pose.
``command(t, force)`` logs the DP controller's command (``thrust_command``): without a given
``vessel_inertia`` the dead reckoner's thrust gain is the one implied by the controller's gains
(``core.controller_gains``). The last successful read is remembered: a window whose read fails
for lack of data (no run of contiguous estimates with commands long enough, no commands) keeps
the remembered gain, and its memory says so (``remembered from t=…``); a read that fails because
the PD law does not explain the commands (R² too low: the controller may have changed) forgets
it, as does ``reset``; with ``controller_read_keep_dofs`` a read that still explains them in
some DOFs keeps the remembered gain only in the DOFs no block believes (a turn spoils yaw's).
"""
from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
import math
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from lf_predictor_ros.core.controller_gains import (
    DIFFERENCE_SEARCH_FACTOR,
    DIFFERENCE_TIMES,
    MAX_NATURAL_FREQ_RATIO,
    MAX_SHIFT,
    MIN_R_SQUARED,
    MIN_SAMPLES,
    ControllerGains,
    believed_medians,
    block_bounds,
    damping_corrected_inertia,
    fitted_damping_scale,
    identity_gated,
    median_implied_inertia,
    median_natural_freq,
    median_r_squared_per_dof,
    read_controller_gains,
)
from lf_predictor_ros.core.error_models import Covariances, calibrate
from lf_predictor_ros.core.estimator import EstimatorStatus
from lf_predictor_ros.core.fit_process import FitProcess, shared_fit_process
from lf_predictor_ros.core.heading import unwrap_pose_series
from lf_predictor_ros.core.lf_dynamics import (
    FORCE_MARGIN,
    MIN_DAMPING_RATE,
    VesselMemory,
    body_velocity,
    fit_lf_dynamics,
    learn_vessel_memory,
    paired_forces,
)
from lf_predictor_ros.core.manoeuvre import manoeuvring
from lf_predictor_ros.core.odometry import LfOdometry, OdometryEstimate
from lf_predictor_ros.core.odometry_params import (
    DAMPING_MEMORY_DOFS,
    FITTED_DAMPING_DOFS,
    OdometryParams,
)
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.predictor import AdaptivePredictor
from lf_predictor_ros.core.published_columns import EstimateSource, Published, PublishedColumns
from lf_predictor_ros.core.readonly import ReadOnlyArrays
from lf_predictor_ros.core.retraining import target_filter
from lf_predictor_ros.core.row_buffer import RowBuffer
from lf_predictor_ros.core.targets import TargetWindow

FloatArray = NDArray[np.float64]
ReadOutcome = Literal['read', 'no_data', 'no_fit']


@dataclass(frozen=True)
class ReadPool:
    """The controller's block reads kept across windows (``controller_read_pool_blocks``).

    Attributes:
        end: stamp of the newest published estimate a pooled block used [s]; later reads take
            only blocks of estimates after it, so every sample is read once.
        blocks: one `ControllerGains` per full block, oldest first.
    """

    end: float
    blocks: tuple[ControllerGains, ...]


@dataclass(frozen=True)
class ControllerRead(ReadOnlyArrays):
    """One attempt to read the DP controller's implied thrust gain (`implied_input_gain`).

    Attributes:
        gain: 1/M_ii per DOF (M_ii = Kd² / (4 Kp)), None if the controller was not read.
        note: what was read (implied inertia, R² per DOF, the samples used) or why not.
        outcome: 'read'; 'no_data' (no commands or published estimates, or no contiguous run
            long enough: says nothing about the controller); 'no_fit' (enough data, but the PD
            law with positive gains does not explain every DOF: another controller, or none).
        stamp: the newest published estimate the read used [s] (None unless read or partly
            read).
        natural_freq: 2 Kp / Kd per DOF of the read (the median over the believed blocks)
            [rad/s] (None unless read).
        partial_gain, partial_freq: a block read ('no_fit') that believes some DOFs but not all:
            1/M_ii and 2 Kp / Kd of the believed DOFs, NaN in the others (None otherwise;
            `_learn`'s ``controller_keep_dofs``).
    """

    gain: FloatArray | None
    note: str
    outcome: ReadOutcome
    stamp: float | None = None
    natural_freq: FloatArray | None = None
    partial_gain: FloatArray | None = None
    partial_freq: FloatArray | None = None

    def __post_init__(self) -> None:
        """Keep read-only copies of the arrays (a read is handed between threads)."""
        for name in ('gain', 'natural_freq', 'partial_gain', 'partial_freq'):
            value = getattr(self, name)
            if value is not None:
                copy = np.array(value, dtype=np.float64)
                copy.setflags(write=False)
                object.__setattr__(self, name, copy)


BODY_DOFS = ('surge', 'sway', 'yaw')  # the DOFs a controller read is per
# A pooled read (``controller_read_pool_blocks``) starts its pool again when this many newest
# blocks in a row explain no DOF (a PD law explains no command: the controller was switched off,
# e.g. to joystick, or changed); otherwise older blocks would keep the read, and the memory
# ``dp_controlled``, for up to the whole pool's time [blocks]
POOL_RESTART_BLOCKS = 2
# With ``controller_read_difference`` a block's difference velocity is filtered from this many
# of the longest time constants searched before the block where its run began earlier, so that
# the filter is warm (e^−10 of its start left) as the controller's was [-]
DIFFERENCE_WARM_UP = 10.0

# what a vessel-memory job returns: the memory, the calibration, the controller read in force,
# the pooled block reads after it (``controller_read_pool_blocks``; None: not pooled). The pool
# travels on its own: a read that is not in force ('no_fit') has read its blocks all the same
Learned = tuple[VesselMemory | None, Covariances | None, ControllerRead | None,
                ReadPool | None]
# the damping memory: per DOF the damping rate kept and the excitation it was identified with
KeptDamping = tuple[FloatArray, FloatArray]


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
        self._job: Future[Learned] | None = None
        self._memory_error: str | None = None
        # the last successful controller read (held here, handed to the worker by value)
        self._controller_read: ControllerRead | None = None
        # the damping rates kept across windows (``dead_reckoning_damping_memory``)
        self._kept_damping: KeptDamping | None = None
        # the controller's block reads kept across windows (``controller_read_pool_blocks``)
        self._read_pool: ReadPool | None = None
        # the controller's commands, kept across segments (matched to the published estimates);
        # rows in arrays, so a memory job takes them without building arrays in the callback
        self._command_times = RowBuffer(capacity=self._capacity)
        self._commands = RowBuffer((self.ndof,), capacity=self._capacity)
        self._restart_buffers()

    def update(self, t: float, pose: FloatArray, force: FloatArray) -> tuple[
            FloatArray, OdometryEstimate | None]:
        """One sample: (LF pose valid at t + h, odometry for t + h) (see AdaptivePredictor).

        The odometry is None when t + h is older than an estimate already given (poses arriving
        late after dead reckoning has moved on): the predictor still learns from the sample.
        """
        lf_pose = self.predictor.update(t, pose, force)
        self._times.append(t)
        self._forces.append(force[:self.ndof])
        self._count += 1
        self._collect()
        self._maybe_learn()
        if self.odometry.is_late(t + self.sample_time):
            return lf_pose, None  # older than an estimate already dead-reckoned
        source: EstimateSource = 'network' if self.predictor.using_network else 'fallback'
        # the untaken twin offset only where the odometry uses it (pose_twin_gain > 0)
        offset = self.predictor.untaken_twin_offset if self.odometry.params.pose_twin_gain > 0.0 \
            else None
        self._hand_wave_peak_freq()
        odom = self.odometry.track(t + self.sample_time, lf_pose, force, source, offset)
        return lf_pose, odom

    def command(self, t: float, force: FloatArray) -> bool:
        """The DP controller's commanded force for the estimate stamped t (``thrust_command``).

        Logged for reading the controller's gains (``OdometryParams.controller_inertia``,
        `implied_input_gain`); False (ignored) if t is not newer than the last command.

        Raises:
            ValueError: a non-finite stamp or force, or fewer than ndof force entries.
        """
        tau = np.array(force, dtype=np.float64).reshape(-1)
        if not math.isfinite(t) or tau.shape[0] < self.ndof or not np.all(np.isfinite(tau)):
            raise ValueError(f'a thrust command needs a finite stamp and {self.ndof} finite '
                             f'force entries [N, N, N·m], got t={t}, force={force!r}')
        if len(self._command_times) and t <= self._command_times.view()[-1]:
            return False
        self._command_times.append(float(t))
        self._commands.append(tau[:self.ndof])
        return True

    def coast(self, t: float, force: FloatArray) -> OdometryEstimate | None:
        """Thrust at t without an accepted pose: dead reckoning (None when lost or never fixed)."""
        self._collect()
        self._hand_wave_peak_freq()
        return self.odometry.coast(t, force)

    def restart_segment(self) -> None:
        """A new data segment for the predictor.

        The odometry keeps its state for dead reckoning across the gap (and its calibration
        and vessel memory).
        """
        self.predictor.restart_segment()
        self._restart_buffers()

    def carry_over(self, previous: LfStateEstimator) -> None:
        """Continue ``previous``'s odometry, command log and controller read (new parameters).

        For a predictor re-created with new tuning parameters (same ndof and sample time): the
        dead reckoning, the calibration, the vessel memory and what was read of the controller
        go on; the data buffers of this estimator start empty. ValueError if the ndof or the
        sample time differ (then start afresh instead).
        """
        odometry = previous.odometry
        if odometry.ndof != self.ndof or odometry.sample_time != self.sample_time:
            raise ValueError(f'cannot carry over an odometry of ndof {odometry.ndof} at '
                             f'{odometry.sample_time} s into ndof {self.ndof} at '
                             f'{self.sample_time} s: start a new one (reset)')
        self.odometry = odometry
        self._controller_read = previous.controller_read
        self._kept_damping = previous._kept_damping
        self._read_pool = previous._read_pool
        for t, tau in zip(previous._command_times.view(), previous._commands.view(),
                          strict=True):
            self._command_times.append(t)
            self._commands.append(tau)

    def reset(self) -> None:
        """Forget everything (predictor, odometry, memory, the remembered controller read)."""
        self.predictor.reset()
        self.odometry.reset()
        self._job = None
        self._controller_read = None
        self._kept_damping = None
        self._read_pool = None
        self._command_times.clear()
        self._commands.clear()
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
    def controller_read(self) -> ControllerRead | None:
        """The last successful read of the controller's gains, still in force (None if none).

        A new vessel memory uses it when its own read fails for lack of data; a read that
        finds no PD law (``no_fit``) or a ``reset`` forgets it; a new successful read replaces it.
        """
        return self._controller_read

    @property
    def memory_learning(self) -> bool:
        """A vessel-memory job (fit, checks, the controller read) is running on its thread."""
        job = self._job
        return job is not None and not job.done()

    @property
    def memory_error(self) -> str | None:
        """Why the last vessel-memory job failed (None if it did not)."""
        return self._memory_error

    # ---- internals -------------------------------------------------------------------------

    def _hand_wave_peak_freq(self) -> None:
        """The predictor's newest ω0 to the odometry (one that is no frequency: None)."""
        freq = self.predictor.wave_peak_freq
        usable = freq is not None and math.isfinite(freq) and freq > 0.0
        self.odometry.set_wave_peak_freq(freq if usable else None)

    def _restart_buffers(self) -> None:
        self._times = RowBuffer(capacity=self._capacity)
        self._forces = RowBuffer((self.ndof,), capacity=self._capacity)
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
        times = self._times.view()[idx[keep]]
        values = np.array(targets.values, dtype=np.float64).reshape(len(targets), -1)[keep]
        odometry = self.odometry
        narrow = self.predictor.narrow_reference if odometry.params.narrow_reference else None
        reference = values if narrow is None else \
            np.array(narrow, dtype=np.float64).reshape(len(targets), -1)[keep]
        # the newest ε targets are still filter transients (targets.training_mask): left out
        usable = max(3, values.shape[0] - self.params.transient_samples)
        times, values, rows = times[:usable], values[:usable], idx[keep][:usable]  # contiguous
        reference = reference[:usable]
        reading = odometry.params.controller_inertia
        # read-only snapshots (`RowBuffer.view`): later commands do not change them
        commands = (self._command_times.view(), self._commands.view()) if \
            reading and len(self._commands) else None
        head: tuple[Any, ...] = (self.params, times, values, self._forces.view()[rows],
                                 self.predictor.wave_peak_freq)
        tail: tuple[Any, ...] = (
            odometry.params.dead_reckoning_timeout, odometry.params.min_calibration_samples,
            odometry.params.pose_lag_prior,
            _input_gain(odometry.params.vessel_inertia, self.ndof), commands,
            self._controller_read if reading else None, self.predictor.targets_peak_damping,
            reference, odometry.params.pose_twin_fit,
            odometry.params.twist_reference_cutoff, odometry.params.pose_reference_cutoff,
            odometry.params.twist_likelihood_fit, odometry.params.twist_attenuation,
            odometry.params.pose_heading_speed_lag,
            odometry.params.controller_read_block_time,
            odometry.params.controller_read_earth_frame,
            odometry.params.dead_reckoning_force_margin,
            odometry.params.controller_read_damping,
            self._kept_damping,
            DAMPING_MEMORY_DOFS[odometry.params.dead_reckoning_damping_memory][:self.ndof],
            odometry.params.controller_read_stiffness_frame,
            odometry.params.controller_read_fitted_damping,
            odometry.params.controller_read_keep_dofs,
            odometry.params.free_fit_earth_fixed,
            odometry.params.controller_read_pair_ratio or math.inf,
            odometry.params.dead_reckoning_damping_refuse_bound,
            FITTED_DAMPING_DOFS[odometry.params.controller_read_fitted_damping_dofs][
                :self.ndof],
            odometry.params.dead_reckoning_damping_turn, self._read_pool,
            odometry.params.controller_read_pool_blocks,
            odometry.params.controller_read_lone_r_squared,
            odometry.params.controller_read_difference,
            odometry.params.controller_read_median_r_squared,
            odometry.params.controller_read_holding_only)
        if self.background:
            if self._executor is None:
                self._executor = ThreadPoolExecutor(1, thread_name_prefix='lf-vessel-memory')
            self._job = self._executor.submit(_learn_in_child, shared_fit_process(), head,
                                              odometry.published_columns(), tail)
        else:
            self._apply(_learn(*(*head, odometry.published(), *tail)))

    def _collect(self) -> None:
        job = self._job
        if job is None or not job.done():
            return
        self._job = None
        try:
            self._apply(job.result())
        except Exception as exc:  # noqa: BLE001 - reported in the diagnostics, never raised
            self._memory_error = f'{type(exc).__name__}: {exc}'

    def _apply(self, result: Learned) -> None:
        memory, covariances, controller_read, pool = result
        self.odometry.apply_learned(memory, covariances)
        self._controller_read = controller_read
        if pool is not None:
            self._read_pool = pool
        if memory is not None and memory.model is not None and memory.damping_score is not None:
            rate = -np.diag(memory.model.damping)
            if self.odometry.params.controller_read_fitted_damping:
                # kept as the damping force per velocity D_i = f_i / G_i, which a later window
                # turns into a rate under its own read gain (`_damping_chosen`)
                rate = rate / np.diag(memory.model.input_gain)
            self._kept_damping = (rate, memory.damping_score)
        self._memory_error = None


def _learn_in_child(process: FitProcess, head: tuple[Any, ...], published: PublishedColumns,
                    tail: tuple[Any, ...]) -> Learned:
    """`_learn` (``*head, published.records(), *tail``) in the child process (`core.fit_process`).

    The history goes as the odometry's columns (a snapshot of its `PublishedLog`: nothing to
    pack on this thread, whose GIL the node's callbacks wait for); without a child the job is
    computed on this thread.
    """
    return process.run(_learn_packed, head, published, tail,
                       fallback=lambda: _learn_packed(head, published, tail))


def _learn_packed(head: tuple[Any, ...], history: PublishedColumns,
                  tail: tuple[Any, ...]) -> Learned:
    """`_learn` with the history given as columns."""
    return _learn(*(*head, history.records(), *tail))


def _learn(params: PredictorParams, times: FloatArray, values: FloatArray, forces: FloatArray,
           wave_peak_freq: float | None, published: list[Published], horizon: float,
           min_samples: int, lag_prior: float, input_gain: FloatArray | None = None,
           commands: tuple[FloatArray, FloatArray] | None = None,
           remembered: ControllerRead | None = None,
           peak_damping: float = math.nan, reference: FloatArray | None = None,
           twin_fit: bool = False, twist_cutoff: float = 0.0, pose_cutoff: float = 0.0,
           twist_likelihood: bool = False, twist_attenuation: bool = False,
           heading_speed: bool = False, controller_block_time: float = 0.0,
           controller_earth_frame: bool = False,
           force_margin: float = FORCE_MARGIN, controller_damping: bool = False,
           kept_damping: KeptDamping | None = None,
           damping_memory: tuple[bool, ...] = (),
           controller_stiffness_frame: str = 'body',
           controller_fitted_damping: bool = False,
           controller_keep_dofs: bool = False, earth_fixed: bool = False,
           controller_pair_ratio: float = math.inf,
           damping_refuse_bound: bool = False,
           controller_fitted_dofs: tuple[bool, ...] = (),
           damping_turn: float = 0.0, read_pool: ReadPool | None = None,
           pool_blocks: int = 0,
           controller_lone_r_squared: float = 0.0,
           controller_difference: bool = False,
           controller_median_r_squared: float = 0.0,
           controller_holding_only: bool = False) -> Learned:
    """Worker job: the vessel memory of one target window, the covariances, the controller read.

    ``forces``: the thrust at the targets' instants; the targets' zero-phase filter (at
    ``wave_peak_freq`` and the sea's fitted ``peak_damping``, as the retraining designs it;
    None: no ω0 yet, no filter) is designed here, off the predict path (≈ 0.6 ms), and the fit
    applies it to the forces too (`lf_dynamics.paired_forces`).
    ``input_gain``: 1/M_ii from ``vessel_inertia``; without it and with ``commands`` (stamps,
    commanded forces) the gain implied by the DP controller's gains is used if the controller
    can be read (`implied_input_gain`). ``remembered``: the last successful read (None: none);
    it stands in when this read fails for lack of data (``no_data``, or no ``commands``), not
    when the commands do not fit a PD law (``no_fit``: the controller may have changed). A read
    or a remembered read marks the memory ``dp_controlled``, and the memory's message carries
    its note ('… remembered from t=… s' for a remembered one).
    The memory is None if it cannot be learned; the covariances compare the published estimates
    with ``reference`` (same instants; None: the targets ``values``;
    `error_models.calibrate`, which fits the untaken twin offset's coefficients with
    ``twin_fit``, and with ``twist_cutoff`` > 0
    [× ω0] compares the twist with the reference velocity low-passed below ``twist_cutoff`` ·
    ``wave_peak_freq``; no ω0 yet: the velocity as it is; ``pose_cutoff`` [× ω0]: the pose
    against the reference low-passed below ``pose_cutoff`` · ``wave_peak_freq``;
    ``twist_likelihood``: the twist model by maximum likelihood; ``twist_attenuation``: with
    ``twist_cutoff`` > 0 the twist models add what the reference's zero-phase filter, the
    targets' or with ``reference`` the narrow notch's, took below the cutoff;
    ``heading_speed``: the heading's lag part also from the horizontal speed;
    ``controller_block_time``, ``controller_earth_frame``, ``controller_stiffness_frame``: how
    the controller is read, `implied_input_gain`'s ``block_time``, ``earth_highpass`` and
    ``stiffness_frame``; ``force_margin``: the
    memory's force limit, `learn_vessel_memory`'s; ``controller_damping``: a read gain is
    corrected for the vessel's own damping rates (`controller_gains.damping_corrected_inertia`)
    and the memory learned again on it; ``damping_memory`` (with a known or read gain; per DOF,
    empty: none): in those DOFs the damping rate of the window with the more velocity energy,
    this one's or ``kept_damping``'s, and the memory learned with those rates fixed
    (`_damping_chosen`, decided before the memory is learned, so it is learned once).
    ``controller_keep_dofs``: a read that believes some DOFs but not all (``no_fit`` with a
    ``partial_gain``) takes the remembered read's value in the others (`_kept_per_dof`) instead
    of forgetting it: a PD law still explains the thrust in the believed DOFs, so the controller
    has not changed, and a turn or a move spoils a DOF's blocks, not the controller.
    ``controller_pair_ratio``: `implied_input_gain`'s ``pair_ratio``.
    ``damping_refuse_bound``, ``controller_fitted_dofs``, ``damping_turn``: `_damping_chosen`'s
    ``refuse_bound``, ``fitted_dofs`` and ``turn``.
    ``controller_lone_r_squared``: the R² a DOF needs that one block alone believes (or a read
    without blocks) (`implied_input_gain`'s ``lone_r_squared``); ``controller_difference``:
    its ``difference`` (the D term may act on the poses' own filtered difference);
    ``controller_median_r_squared``: its ``median_r_squared`` (the controller identity gate);
    ``controller_holding_only``: its ``holding_only`` (blocks of station keeping only).
    ``pool_blocks`` > 0: the controller is read from the last that many blocks ever read
    (`pooled_input_gain`, continuing ``read_pool``), and the pool after it is returned too.
    ``earth_fixed``: without a known or read gain, the fit's environment is one earth-fixed
    force and a constant yaw moment (`lf_dynamics.fit_lf_dynamics`).
    The read returned is the one in force afterwards: this read if it succeeded,
    ``remembered`` if it failed for lack of data, with ``controller_keep_dofs`` the two
    combined if it failed in some DOFs, else None; then the pool after the read (None unless
    ``pool_blocks`` > 0).
    """
    sos = None if wave_peak_freq is None else target_filter(params, wave_peak_freq,
                                                            peak_damping)
    source = 'vessel_inertia' if input_gain is not None else ''
    read: ControllerRead | None = None
    pool: ReadPool | None = None
    if commands is not None:
        bound = math.inf if wave_peak_freq is None else MAX_NATURAL_FREQ_RATIO * wave_peak_freq
        if pool_blocks > 0:
            read, pool = pooled_input_gain(published, *commands, params.sample_time,
                                           controller_block_time, read_pool, pool_blocks,
                                           controller_earth_frame, bound,
                                           controller_stiffness_frame, controller_pair_ratio,
                                           controller_lone_r_squared, controller_difference,
                                           controller_median_r_squared,
                                           holding_only=controller_holding_only)
        else:
            read = implied_input_gain(published, *commands, params.sample_time,
                                      controller_block_time, controller_earth_frame, bound,
                                      controller_stiffness_frame, controller_pair_ratio,
                                      controller_lone_r_squared, controller_difference,
                                      controller_median_r_squared,
                                      holding_only=controller_holding_only)
    elif remembered is not None:
        read = ControllerRead(None, 'controller gains: no commands', 'no_data')
    in_force: ControllerRead | None = read if read is not None and read.outcome == 'read' \
        else None
    note = '' if read is None else read.note
    if read is not None and read.outcome == 'no_data' and remembered is not None:
        in_force = remembered
        since = '' if remembered.stamp is None else f' from t={remembered.stamp:.1f} s'
        note = f'{remembered.note}, remembered{since} ({read.note})'
    if controller_keep_dofs and read is not None and read.outcome == 'no_fit' and \
            read.partial_gain is not None and remembered is not None and \
            remembered.gain is not None and remembered.gain.shape == read.partial_gain.shape:
        in_force = _kept_per_dof(read, remembered)
        note = in_force.note
    if input_gain is None and in_force is not None:
        input_gain, source = in_force.gain, 'controller'
    correcting = controller_damping or controller_fitted_damping
    read_freq = in_force.natural_freq if correcting and source == 'controller' and \
        in_force is not None else None
    gain, rate, score = input_gain, None, None
    if (read_freq is not None or any(damping_memory)) and input_gain is not None:
        gain, rate, score, parts = _damping_chosen(values, forces, params.sample_time, sos,
                                                   input_gain, read_freq, kept_damping,
                                                   damping_memory, controller_fitted_damping,
                                                   damping_refuse_bound,
                                                   controller_fitted_dofs, damping_turn)
        note = '; '.join(part for part in (note, *parts) if part)
    try:
        memory: VesselMemory | None = learn_vessel_memory(values, forces, params.sample_time,
                                                          horizon, gain, sos, force_margin,
                                                          rate, earth_fixed)
    except ValueError:
        memory = None
    if memory is not None and score is not None:
        memory = replace(memory, damping_score=score)
    if memory is not None and (source or note):
        memory = replace(memory, known_gain=source if memory.model is not None else '',
                         dp_controlled=in_force is not None,
                         message=f'{memory.message}; {note}' if note else memory.message)
    cutoff = 0.0 if wave_peak_freq is None else twist_cutoff * wave_peak_freq
    pose_edge = 0.0 if wave_peak_freq is None else pose_cutoff * wave_peak_freq
    reference_filter = None
    if twist_attenuation and wave_peak_freq is not None:
        # `retraining.narrow_reference` filters with the narrow notch, the targets with ``sos``
        reference_filter = sos if reference is None else target_filter(params, wave_peak_freq)
    return memory, calibrate(published, times, values if reference is None else reference,
                             params.ndof, params.sample_time, min_samples, lag_prior,
                             twin_fit, cutoff, pose_edge, twist_likelihood,
                             reference_filter, heading_speed), in_force, pool


def _kept_per_dof(read: ControllerRead, remembered: ControllerRead) -> ControllerRead:
    """``read``'s believed DOFs (``partial_gain`` finite), ``remembered``'s in the others.

    The natural frequency likewise (None unless both have one); the note names the DOFs kept.
    """
    assert read.partial_gain is not None and remembered.gain is not None
    fresh = np.isfinite(read.partial_gain)
    gain = np.where(fresh, read.partial_gain, remembered.gain)
    freq = None
    if read.partial_freq is not None and remembered.natural_freq is not None:
        freq = np.where(fresh, read.partial_freq, remembered.natural_freq)
    kept = ', '.join(BODY_DOFS[i] for i in np.flatnonzero(~fresh))
    since = '' if remembered.stamp is None else f' from t={remembered.stamp:.1f} s'
    inertia = ', '.join(f'{v:.3g}' for v in 1.0 / gain)
    return ControllerRead(gain, f'controller-implied inertia {inertia} ({read.note}; {kept} '
                                f'remembered{since})', 'read', read.stamp, freq)


def _damping_chosen(values: FloatArray, forces: FloatArray, sample_time: float,
                    sos: FloatArray | None, input_gain: FloatArray,
                    natural_freq: FloatArray | None, kept: KeptDamping | None,
                    damping_memory: tuple[bool, ...], fitted_damping: bool = False,
                    refuse_bound: bool = False, fitted_dofs: tuple[bool, ...] = (),
                    turn: float = 0.0
                    ) -> tuple[FloatArray, FloatArray | None, FloatArray | None, list[str]]:
    """The thrust gain and damping rates the window's memory is learned with, before it is.

    Returns (gain, fixed damping rates or None, damping scores or None, notes). The window's own
    rates f = −F_ii come from one least-squares fit on the whole window with ``input_gain``
    (`fit_lf_dynamics`, the refit `learn_vessel_memory` would make; no drift tests). A window in
    which a DOF hardly moves cannot identify its damping (rao_supply's yaw time constant came out
    33–240 s between turns, 8–12 s in windows with a turn, the truth 11.6 s: docs/BENCHMARKS.md,
    fifty-third session). In the DOFs of ``damping_memory`` the rate is the one of the window
    with the more velocity energy Σ ν_i² over the target body velocity (the information a
    least-squares fit of f_i has, for a given residual), this one or ``kept``'s; the memory is
    then learned once with those rates fixed (the scores go to its ``damping_score``; the other
    DOFs keep this window's fitted rate). With ``refuse_bound``, a rate this window's fit held
    at its bound (``MIN_DAMPING_RATE``: the data asked for no damping or a negative one, so the
    window did not identify it) never replaces a kept one, whatever its velocity energy: on
    rao_supply 1124 a window without a turn, after one the dropout had hidden, had 1.5× the
    start-up window's energy and its bound replaced a rate of 0.09 1/s (docs/BENCHMARKS.md,
    fifty-eighth session). With ``turn`` > 0 [rad] (3 DOF), the yaw's score is its energy only
    in a window whose heading spans at least ``turn`` (one that saw a turn), else 0, and a
    kept rate is replaced only by a window that scores more: a window without a turn fills an
    empty memory but never replaces a kept rate (rao_supply 1116: a window without a turn, its
    end in a 15 m move, had 5× the kept window's energy and fitted 2.9× the true yaw rate,
    the sway–yaw coupling of the move that the diagonal model lacks).
    With ``natural_freq`` (the read's 2 Kp / Kd) the read inertia is corrected for the rates
    (`controller_gains.damping_corrected_inertia`; with ``fitted_damping``,
    `controller_gains.fitted_damping_scale`, which also scales the rates by the same factor,
    keeping the fitted G / f), in the DOFs of ``fitted_dofs`` (empty: all; the others keep the
    read gain and their rate). When nothing changes (no rate kept, no correction), or the
    window cannot be fitted, the memory is learned as without this: ``input_gain``, no fixed
    rates.
    """
    n = input_gain.shape[0]
    dofs = np.array(damping_memory, dtype=bool)
    memorized = bool(np.any(dofs))
    try:
        model = fit_lf_dynamics(values, paired_forces(forces, sos), sample_time,
                                input_gain=input_gain)
    except ValueError:
        return input_gain, None, None, []
    rate = -np.diag(model.damping)
    score = np.sum(body_velocity(values, sample_time) ** 2, axis=0)
    gated = turn > 0.0 and n == 3
    if gated and np.ptp(values[:, 2]) < turn:
        score[2] = 0.0
    parts = []
    if kept is not None and dofs.shape == (n,) and kept[0].shape == (n,):
        outscored = kept[1] >= score if gated else kept[1] > score
        older = dofs & (outscored | (refuse_bound & (rate <= MIN_DAMPING_RATE)))
        # with ``fitted_damping`` the kept values are damping forces per velocity D_i: the rate
        # they make under this window's gain
        kept_rate = kept[0] * input_gain if fitted_damping else kept[0]
        rate, score = np.where(older, kept_rate, rate), np.where(older, kept[1], score)
        if np.any(older):
            parts.append('damping rates kept ' + ', '.join(
                f'{v:.3g}' if o else '–' for v, o in zip(rate, older, strict=True)) + ' 1/s')
    gain = input_gain
    if natural_freq is not None and fitted_damping:
        scale = fitted_damping_scale(natural_freq[:n], rate)
        if len(fitted_dofs) == n:
            scale = np.where(np.array(fitted_dofs, dtype=bool), scale, 1.0)
        gain, rate = input_gain / scale, rate / scale
        parts.append('inertia × ' + ', '.join(f'{v:.2f}' for v in scale) +
                     ' for the fitted damping')
    elif natural_freq is not None:
        inertia = 1.0 / input_gain
        corrected = damping_corrected_inertia(inertia, natural_freq[:n], rate)
        gain = 1.0 / corrected
        parts.append('inertia × ' + ', '.join(f'{v:.2f}' for v in corrected / inertia) +
                     ' for the damping')
    fixed = rate if memorized and parts else None  # nothing kept or corrected: its own fit
    return gain, fixed, score if memorized else None, parts


def implied_input_gain(published: list[Published], times: FloatArray, forces: FloatArray,
                       sample_time: float, block_time: float = 0.0,
                       earth_highpass: bool = False,
                       max_natural_freq: float = math.inf,
                       stiffness_frame: str = 'body',
                       pair_ratio: float = math.inf,
                       lone_r_squared: float = 0.0,
                       difference: bool = False,
                       median_r_squared: float = 0.0,
                       *, holding_only: bool = False) -> ControllerRead:
    """1/M_ii implied by the DP controller acting on the published estimates.

    ``times``, ``forces``: the controller's commands and their stamps (a controller stamps its
    command with the stamp of the estimate it acted on; `fit_controller_gains` also tries a few
    samples of shift). The applied thrust does not do: actuator lag (1 s shaft dynamics on the
    simulated supply vessel) turns the D term's high-frequency part into apparent stiffness,
    and Kd² / (4 Kp) came out at 0.03–0.13 of the inertia.

    Every published estimate is paired with the command stamped like it; the pairs form
    contiguous runs, broken by a gap in the stamps or by an estimate without a command (a late
    or lost sample or command). Every run of at least ``MIN_SAMPLES`` + 2 ``MAX_SHIFT`` pairs
    is used, pooled into one fit (no high-pass, integral or shift crosses a break); shorter
    runs are left out. So one short break costs only the samples around it, not the read.

    ``block_time`` > 0 [s]: each run is cut into blocks of that length (`block_bounds`), each
    block read on its own, and the inertia is per DOF the median over the blocks whose PD law
    is believed (`median_implied_inertia`): a manoeuvre then spoils one block, not every read
    after it. ``earth_highpass``, ``stiffness_frame``: the high-pass in the earth frame and the
    frame of the controller's stiffness (`fit_controller_gains`).
    ``max_natural_freq`` [rad/s]: a DOF whose gains imply a natural frequency 2 Kp / Kd at or
    above it is not believed (`ControllerGains.believed`; the learning job passes
    ``MAX_NATURAL_FREQ_RATIO`` × ω0; inf: no bound). ``pair_ratio``: with blocks, a DOF two
    blocks believe with inertias more than this factor apart is not believed
    (`controller_gains.median_implied_inertia`; inf: never). ``lone_r_squared``: the R² a DOF
    needs that one block alone believes, or the one read without blocks (nothing outvotes it;
    `controller_gains.median_implied_inertia`; 0: no more than any block).
    ``difference``: the D term may also act on the poses' own finite difference through a
    low-pass whose time constant the read finds, a controller that differentiates the pose
    (`controller_gains.read_controller_gains` over `DIFFERENCE_TIMES`; False: the published
    twist only). ``median_r_squared``: with at least `controller_gains.IDENTITY_MIN_BLOCKS`
    blocks, unless some DOF's median R² over them reaches it, no DOF is believed (the
    controller identity gate, `controller_gains.identity_gated`; 0: off; a read without
    blocks is not judged). ``holding_only``: with ``block_time`` > 0, a block whose estimates
    manoeuvred (`block_manoeuvred`) is not read; none left: 'no_data'.
    """
    if not published or times.shape[0] == 0:
        return ControllerRead(None, 'controller gains: no data', 'no_data')
    stamps, index, runs = _paired_runs(published, times, sample_time)
    need = MIN_SAMPLES + 2 * MAX_SHIFT
    longest = max((b - a for a, b in runs), default=0)
    runs = [(a, b) for a, b in runs if b - a >= need]
    if not runs:
        return ControllerRead(None, f'controller gains: longest contiguous run {longest} '
                                    f'samples, too few (need {need})', 'no_data')
    rows = np.concatenate([np.arange(a, b) for a, b in runs])
    poses = np.array([published[k].pose for k in rows])
    twists = np.array([published[k].twist for k in rows])
    paired = forces[index[rows]]
    lengths = [b - a for a, b in runs]
    offsets = np.r_[0, np.cumsum(lengths)].tolist()
    grid = DIFFERENCE_TIMES if difference else ()
    try:
        if block_time > 0.0:
            block = int(round(block_time / sample_time))
            blocks = [(offsets[j] + a, offsets[j] + b, _warm_lead(a, grid, sample_time))
                      for j, length in enumerate(lengths)
                      for a, b in block_bounds(length, block, need)]
            if holding_only:
                moved = len(blocks)
                blocks = [(a, b, lead) for a, b, lead in blocks
                          if not block_manoeuvred(poses[a:b], sample_time)]
                if not blocks:
                    return ControllerRead(None, f'controller gains: all {moved} blocks '
                                               'manoeuvred (holding only)', 'no_data')
            reads = [read_controller_gains(poses[a - lead:b], twists[a:b], paired[a:b],
                                           sample_time, difference_times=grid, lead=lead,
                                           earth_highpass=earth_highpass,
                                           stiffness_frame=stiffness_frame)
                     for a, b, lead in blocks]
            return _median_read(reads, float(stamps[rows[-1]]), rows.size, block_time,
                                max_natural_freq, pair_ratio, lone_r_squared,
                                median_r_squared)
        gains = read_controller_gains(poses, twists, paired, sample_time, difference_times=grid,
                                      run_starts=offsets[1:-1], earth_highpass=earth_highpass,
                                      stiffness_frame=stiffness_frame)
    except ValueError as exc:  # non-finite values: nothing learned about the controller
        return ControllerRead(None, f'controller gains: {exc}', 'no_data')
    inertia = gains.implied_inertia(max_natural_freq, max(MIN_R_SQUARED, lone_r_squared))
    r2 = ', '.join(f'{v:.2f}' for v in gains.r_squared)
    if inertia is None:
        return ControllerRead(None, f'controller gains not read (R² {r2})', 'no_fit')
    used = f'{rows.size} samples' + (f' in {len(runs)} runs' if len(runs) > 1 else '') + \
        ('; stiffness in the earth frame' if gains.stiffness_frame == 'earth' else '') + \
        (f"; Kd on the pose's own difference, T_v {gains.difference_time:.2g} s"
         if gains.difference_time > 0.0 else '')
    return ControllerRead(1.0 / inertia, (f"controller-implied inertia "
                                          f"{', '.join(f'{v:.3g}' for v in inertia)} "
                                          f'(R² {r2}; {used})'), 'read', float(stamps[rows[-1]]),
                          gains.natural_freq())


def block_manoeuvred(poses: FloatArray, sample_time: float) -> bool:
    """Did the estimates of one read block manoeuvre (`manoeuvre.manoeuvring`)?

    ``poses`` (m, ndof), the heading wrapped (`heading.unwrap_pose_series` here). A DP controller
    acts on the error from its filtered setpoint η_d, which the read does not know: holding
    station, η_d is constant and the high-pass removes it; through a setpoint move or a turn its
    transient is left in the thrust and the PD fit reads it as stiffness and damping (rao_supply
    and rao_swell, ten loops: blocks with a move read the surge inertia 0.17–0.90× the
    controller's, blocks holding station 0.90–1.08×; docs/BENCHMARKS.md, seventy-second session).
    """
    values = np.asarray(poses, dtype=np.float64)
    return manoeuvring(unwrap_pose_series(values, values.shape[1]), sample_time)


def _paired_runs(published: list[Published], times: FloatArray, sample_time: float
                 ) -> tuple[FloatArray, NDArray[np.intp], list[tuple[int, int]]]:
    """The published estimates paired with the commands stamped like them.

    Returns (the estimates' stamps, the index of each one's command, the contiguous runs
    [start, end) of paired estimates): a run is broken by a gap in the stamps or by an estimate
    without a command.
    """
    stamps = np.array([p.stamp for p in published])
    index = np.searchsorted(times, stamps - 0.5 * sample_time)
    index = np.clip(index, 0, times.shape[0] - 1)
    matched = np.abs(times[index] - stamps) < 0.5 * sample_time
    # blocks of equal `matched` without a gap in the stamps: [edges[j], edges[j + 1])
    edges = np.flatnonzero(np.r_[True, (np.diff(stamps) > 1.5 * sample_time) |
                                 (matched[1:] != matched[:-1]), True])
    runs = [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True) if matched[a]]
    return stamps, index, runs


def _warm_lead(before: int, grid: Sequence[float], sample_time: float) -> int:
    """Rows before a block that warm its difference filters up: at most ``before`` (0: none).

    ``DIFFERENCE_WARM_UP`` of the longest time constant the search over ``grid`` reaches
    (`controller_gains.read_controller_gains`); an empty grid needs none.
    """
    if not grid:
        return 0
    longest = max(grid) * DIFFERENCE_SEARCH_FACTOR
    return min(before, int(math.ceil(DIFFERENCE_WARM_UP * longest / sample_time)))


def pooled_input_gain(published: list[Published], times: FloatArray, forces: FloatArray,
                      sample_time: float, block_time: float, pool: ReadPool | None,
                      pool_blocks: int, earth_highpass: bool = False,
                      max_natural_freq: float = math.inf, stiffness_frame: str = 'body',
                      pair_ratio: float = math.inf,
                      lone_r_squared: float = 0.0,
                      difference: bool = False,
                      median_r_squared: float = 0.0,
                      *, holding_only: bool = False) -> tuple[ControllerRead, ReadPool]:
    """`implied_input_gain` from the last ``pool_blocks`` blocks ever read, each read once.

    The controller of a DP vessel does not change from one window to the next, but its read
    did: the history of one window holds 2–4 blocks of ``block_time``, most with a setpoint move
    or a turn in them, and their median moved the read yaw inertia by 0.4–2.5× between two
    dropouts of one loop (rao_supply 1148, docs/BENCHMARKS.md, fifty-ninth session). Here only
    the full blocks of paired estimates after ``pool.end`` are read (a run's tail shorter than
    a block waits for the next read; one cut by a gap is left out), appended to the pool, and
    the read is `_median_read` over the newest ``pool_blocks`` of them. Until the pool holds a
    block the read is `implied_input_gain`'s on the history, so it never comes later than
    without the pool (a first full block of 300 s had left the DDS dropout tests, whose dropout
    begins at 200 s, without a read). When the newest `POOL_RESTART_BLOCKS` blocks, a new one
    among them, explain no DOF, the pool starts again from them: the read is then 'no_fit' and
    forgotten, as a window's read whose blocks explain nothing (the controller may have been
    switched off or changed). ``lone_r_squared``, ``difference``, ``median_r_squared`` (over
    the pooled blocks), ``holding_only`` (a new block that manoeuvred is passed over, not
    pooled): as `implied_input_gain`. Returns (the read, the pool after it).
    """
    end = -math.inf if pool is None else pool.end
    kept: tuple[ControllerGains, ...] = () if pool is None else pool.blocks
    if not published or times.shape[0] == 0:
        return ControllerRead(None, 'controller gains: no data', 'no_data'), \
            pool if pool is not None else ReadPool(end, kept)
    stamps, index, runs = _paired_runs(published, times, sample_time)
    block = max(int(round(block_time / sample_time)), MIN_SAMPLES + 2 * MAX_SHIFT)
    grid = DIFFERENCE_TIMES if difference else ()
    new: list[ControllerGains] = []
    passed_over = False  # a new block that manoeuvred (holding_only): the pool's end moves
    for a, b in runs:
        first = a + int(np.searchsorted(stamps[a:b], end, side='right'))
        for start in range(first, b - block + 1, block):
            # only the new blocks are turned into arrays, with a lead that warms the
            # difference's filter up where the run began earlier
            lead = _warm_lead(start - a, grid, sample_time)
            rows = published[start - lead:start + block]
            poses = np.array([p.pose for p in rows])
            end = float(stamps[start + block - 1])
            if holding_only and block_manoeuvred(poses[lead:], sample_time):
                passed_over = True
                continue
            try:
                new.append(read_controller_gains(
                    poses, np.array([p.twist for p in rows[lead:]]),
                    forces[index[start:start + block]], sample_time, difference_times=grid,
                    lead=lead, earth_highpass=earth_highpass, stiffness_frame=stiffness_frame))
            except ValueError:  # non-finite values: this block says nothing
                pass
    pooled = kept + tuple(new)
    tail = pooled[-POOL_RESTART_BLOCKS:]
    restart = bool(new) and len(tail) == POOL_RESTART_BLOCKS and \
        not any(np.any(b.believed(max_natural_freq)) for b in tail)
    if restart:
        pooled = tail
    after = pool if pool is not None and not new and not passed_over else \
        ReadPool(end, pooled[-pool_blocks:])
    if not after.blocks:
        read = implied_input_gain(published, times, forces, sample_time, block_time,
                                  earth_highpass, max_natural_freq, stiffness_frame, pair_ratio,
                                  lone_r_squared, difference, median_r_squared,
                                  holding_only=holding_only)
        return replace(read, note=f'{read.note}; no full block of {block} samples pooled '
                                  'yet'), after
    read = _median_read(list(after.blocks), end, block * len(after.blocks), block_time,
                        max_natural_freq, pair_ratio, lone_r_squared, median_r_squared)
    restarted = f'; the newest {POOL_RESTART_BLOCKS} blocks explain no DOF, the pool starts ' \
        'again' if restart else ''
    return replace(read, note=f'{read.note}; pooled, {len(new)} new{restarted}'), after


def _median_read(reads: list[ControllerGains], stamp: float, samples: int,
                 block_time: float, max_natural_freq: float = math.inf,
                 pair_ratio: float = math.inf,
                 lone_r_squared: float = 0.0,
                 median_r_squared: float = 0.0) -> ControllerRead:
    """The read of `implied_input_gain` from one `ControllerGains` per block.

    ``median_r_squared``: the controller identity gate first (`controller_gains.identity_gated`).
    """
    median_r2 = median_r_squared_per_dof(reads)
    reads, gated = identity_gated(reads, median_r_squared)
    inertia, counts = median_implied_inertia(reads, max_natural_freq, pair_ratio,
                                             lone_r_squared)
    believed = ', '.join(f'{c}' for c in counts)
    earth = sum(read.stiffness_frame == 'earth' for read in reads)
    filters = [read.difference_time for read in reads if read.difference_time > 0.0]
    what = f'{believed} of {len(reads)} blocks of {block_time:.0f} s believed' + \
        (f', {earth} with the stiffness in the earth frame' if earth else '') + \
        (f", {len(filters)} with Kd on the pose's own difference (T_v median "
         f'{float(np.median(filters)):.2g} s)' if filters else '') + \
        (f"; median R² {', '.join(f'{v:.2f}' for v in median_r2)}, none reaches "
         f"{median_r_squared:g}: a controller on another estimator's poses?"
         if gated else '')
    if inertia is None:
        partial_inertia, partial_freq = believed_medians(reads, max_natural_freq, pair_ratio,
                                                         lone_r_squared)
        partial = bool(np.any(np.isfinite(partial_inertia)))
        return ControllerRead(None, f'controller gains not read ({what})', 'no_fit', stamp,
                              partial_gain=1.0 / partial_inertia if partial else None,
                              partial_freq=partial_freq if partial else None)
    return ControllerRead(1.0 / inertia, (f"controller-implied inertia "
                                          f"{', '.join(f'{v:.3g}' for v in inertia)} "
                                          f'(median; {what}; {samples} samples)'), 'read', stamp,
                          median_natural_freq(reads, max_natural_freq, pair_ratio,
                                              lone_r_squared))


def _input_gain(inertia: tuple[float, ...], ndof: int) -> FloatArray | None:
    """1 / M_ii for the estimated DOFs, or None when the inertia is not given (0)."""
    if inertia[0] <= 0.0:
        return None
    return 1.0 / np.array(inertia[:ndof], dtype=np.float64)
