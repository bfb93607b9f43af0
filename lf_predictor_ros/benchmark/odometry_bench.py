r"""LF odometry benchmark (issue 14): covariance consistency, twist, dead reckoning, D-term loop.

Per scenario and seed, on the fair recording (`suite.make_recording`: open-loop scenarios as
they are, DP scenarios with the loop closed on the tuned observer), the recorded measurements
and thrust are replayed open loop into `LfStateEstimator` (``background=False``, deterministic)
and scored against the true LF pose. The estimate of update k is valid at t[k] + h, so it is
compared with truth[k + 1]; the true twist is ``body_velocity`` of the true LF pose (heading
unwrapped, central differences).

1. **Covariance consistency** (run without dropouts, scored after ``suite.scored_start``: the
   first training plus 2Δ). Per DOF the normalized error x = e / σ (σ² the published variance)
   and jointly NEES/n = eᵀ P⁻¹ e / n, for the pose and the twist. The test and its bounds: the
   time average of x² of a consistent estimator is 1. The errors are strongly autocorrelated,
   so the average has N_eff = N / (2 τ_int) independent samples, τ_int = 1/2 + Σ_k ρ(k) the
   integrated autocorrelation time of x in samples (Sokal's automatic window: the smallest
   window M ≥ ``TAU_WINDOW_C`` · τ_int(M)), and a consistent run lies in
   [χ²₀.₀₂₅(N_eff) / N_eff, χ²₀.₉₇₅(N_eff) / N_eff] with 95 % probability. Joint: the same
   with N_eff = Σ over DOFs (the DOFs treated as independent). Reported over held-out runs: the
   fraction of runs inside their interval and the mean over runs with its Student-t 95 %
   interval. Note: for Gaussian x the variance of the mean of x² involves Σρ², not Σρ; with
   ρ of x (as stated here) the bounds are up to √2 wider than that Gaussian value for slowly
   decaying positive correlation (narrower where ρ oscillates); ``inside_rho2`` reports the
   verdict with N_eff from ρ² as well. The same test is also reported against the LF truth a
   filter of the measurement can see (quantities ``pose_seen``, ``twist_seen``:
   `seen_truth.recording_seen_truth`, the twin plus the part of the first-order wave motion
   below the wave band: the shaping filter's tail and aliasing, a few mm since the simulator's
   force-superposition fixes of the eighteenth session).
2. **Twist accuracy** (same run): RMSE per DOF of the published twist against the true LF body
   velocity, next to the zero estimate (RMS of the true velocity) and the PID's own velocity:
   the filtered finite difference (T_v = ``VELOCITY_FILTER_TIME`` = 1 s, one step per h, earth
   frame rotated to the body, as `sim_ros.control.pid.pid_step`) of the published LF pose.
3. **Dead-reckoning drift** (second run, same recording): pose dropouts (``default_dropouts``:
   three non-overlapping 130 s dropouts after the first training). In a dropout every grid
   sample calls ``coast(t, thrust)``; when poses return, ``restart_segment()`` and ``update``.
   Drift = |estimate − true LF| per DOF at ``DRIFT_TIMES`` (30 / 60 / 120 s) after the last
   fix, and whether the 95 % covariance ellipse (eᵀ P⁻¹ e ≤ χ²₀.₉₅(n)) contains the truth, next
   to the oracle Kalman filter predicting only (its ``update`` with a NaN pose propagates
   without a measurement update) through the same dropouts and to holding the last published
   pose. With ``--dead-reckoning-commands`` the recorded thrust also reaches the estimator as
   the DP controller's commands (the recording keeps only the applied thrust: a stand-in for
   a bag whose ``thrust_command`` came from a controller on another estimator, with the
   actuator lag in it, which the read does not expect: `lf_state.implied_input_gain`).
4. **Closed loop with the D term from lf_odom**: `recordings.run_loop` with the predictor in
   the loop, once with the PID's own finite-difference D term (the suite's ``adaptive`` loop) and
   once with ``velocity`` = the twist of `LfStateEstimator`; metrics as the suite computes them
   (`suite.run_closed_loops`, scored after the same warm-up): position RMSE, heading RMSE and
   thrust wave-band power.
5. **Closed loop through pose dropouts** (``--dropout-loops``): the same DP loop with pose
   dropouts (``default_dropouts`` with ``DROPOUT_LOOP_LENGTH``: within the dead-reckoning
   timeout), for the predictor with pose and D term from lf_odom (`LfStateEstimator`: ``coast``
   in a dropout, ``restart_segment`` after it; 'lost' gives no estimate and the PID holds its
   last one) and for the tuned passive observer (the classical answer: its model alone,
   ``PassiveObserver.coast``). Per dropout: the largest horizontal distance [m] and heading
   difference [rad] of the loop's true LF pose from the loop reference (the setpoint; with a
   setpoint schedule the ideal loop's LF track, PID on the true LF pose, same seed: as the
   suite scores loops) during the dropout and in the ``AFTER_DROPOUT`` s after it, next to the
   same windows of the same estimator's loop without dropouts (items 4 and the observer loop).
   Trust in the loop (lf_odom only): the fraction of the dead-reckoned estimates of each dropout
   whose 95 % covariance ellipse (eᵀ P⁻¹ e ≤ χ²₀.₉₅(n), e against the loop's true LF pose at the
   estimate's stamp) contains the truth, and at the end of the dropout the published horizontal
   standard deviation √(P_NN + P_EE) next to the horizontal error. With
   ``--dropout-loop-velocity difference`` lf_odom's loops (with and without dropouts) take the
   D term from the PID's own finite difference of lf_odom's pose instead of its twist: a DP
   stack that takes only the position (`dp_controller`'s default ``velocity_source``).

The dropouts of items 3 and 5 come at the same times in every seed unless ``--dropout-spread``
delays each seed's by its own draw (``dropout_shift_for_seed``; the JSON's ``dropout_shift``).
``--dropout-moves LOW HIGH`` instead starts item 5's dropouts U(LOW, HIGH) s after each setpoint
change (``move_dropouts``; scenarios with a setpoint schedule): the dead reckoning in moves; a
negative LOW (above −60 s, the dropout's length) starts some before the change, so that the move
or turn begins inside the dropout.

Usage (2 Dask workers; ``--scheduler none`` runs in this process)::

    python -m lf_predictor_ros.benchmark.odometry_bench run --seeds 1 2 --no-loops \\
        --pose-cov-scale 1 --twist-cov-scale 1 -o /tmp/odo_tuning.json
    python -m lf_predictor_ros.benchmark.odometry_bench calibrate /tmp/odo_tuning.json

    python -m lf_predictor_ros.benchmark.odometry_bench run --seeds 11 12 ... -o held_out.json
    python -m lf_predictor_ros.benchmark.odometry_bench report held_out.json

``calibrate`` also prints ``pose_log_spread`` / ``twist_log_spread``, the standard deviation of
log(per-DOF mean NEES) over the runs (what a scale cannot fix, what a better covariance model
lowers); ``run --pose-lag-scale A B …`` runs every case per value and ``calibrate`` then reports
per value (docs/BENCHMARKS.md "State-dependent covariance").
"""
from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
import json
import math
import os
import sys
import time
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray
from scipy import stats
import yaml

from lf_predictor_ros.benchmark.estimators import make_estimator, param_overrides, predictor_params
from lf_predictor_ros.benchmark.recordings import run_loop
from lf_predictor_ros.benchmark.scoring import fmt_number, interval
from lf_predictor_ros.benchmark.seen_truth import recording_seen_truth
from lf_predictor_ros.benchmark.stability import pose_offset
from lf_predictor_ros.benchmark.suite import (
    _loop_reference,
    make_recording,
    make_setup,
    run_closed_loops,
    schedule_shift_for_seed,
    scored_start,
)
from lf_predictor_ros.core.controller_gains import difference_velocity
from lf_predictor_ros.core.heading import wrap_angle
from lf_predictor_ros.core.lf_dynamics import body_velocity
from lf_predictor_ros.core.lf_state import LfStateEstimator
from lf_predictor_ros.core.math_threads import BLAS_THREAD_VARIABLES
from lf_predictor_ros.core.odometry import OdometryEstimate
from lf_predictor_ros.core.odometry_params import OdometryParams
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.retraining import first_training_samples
from sim_ros.control.pid import VELOCITY_FILTER_TIME, VELOCITY_SOURCES
from sim_ros.simulation import ClosedLoopRun, Scenario, SimRecord, load_scenario, simulate

FloatArray = NDArray[np.float64]
DOFS = ('north', 'east', 'yaw')
TWIST_DOFS = ('u', 'v', 'r')
DEFAULT_SCENARIOS = ('supply_closed_loop', 'rao_supply', 'onedof_feedback',
                     'threedof_open_loop')
DEFAULT_DURATION = 1800.0  # s, as the suite (benchmark.SUITE)
DROPOUT_LENGTH = 130.0  # s
DROPOUT_COUNT = 3
DRIFT_TIMES = (30.0, 60.0, 120.0)  # s after the last fix
TAU_WINDOW_C = 5.0  # Sokal's automatic window constant
CONFIDENCE = 0.95
LOOP_FD = 'adaptive'  # the predictor loop with the PID's finite-difference D term
LOOP_ODOM = 'adaptive_odom_d'  # the same with the D term from the odometry twist
LOOP_OBSERVER = 'observer'  # the tuned passive observer (PID finite-difference D term)
DROPOUT_LOOP_LENGTH = 60.0  # [s] dropouts of item 5 (within the 120 s timeout)
AFTER_DROPOUT = 120.0  # [s] scored after each dropout of item 5
# The seed's own random stream for the dropouts' delay (``--dropout-spread``), apart from the
# sea's, the noise's and the scenario schedule's draws.
DROPOUT_SHIFT_STREAM = 0xD809
# The seed's own stream for the delays of dropouts placed in setpoint moves (``--dropout-moves``)
MOVE_DELAY_STREAM = 0xD80A
MOVE_DROPOUT_GAP = 60.0  # [s] least tracking between two dropouts placed in moves


# ---------------------------------------------------------------- statistics

def integrated_autocorrelation_time(x: FloatArray, square: bool = False) -> float:
    """τ_int = 1/2 + Σ ρ(k) in samples (Sokal's automatic window; ρ² summed if ``square``)."""
    data = np.asarray(x, dtype=np.float64)
    n = data.size
    if n < 4:
        return math.nan
    centred = data - data.mean()
    size = 1 << (2 * n - 1).bit_length()
    spectrum = np.fft.rfft(centred, size)
    acov = np.fft.irfft(spectrum * np.conj(spectrum), size)[:n]
    if acov[0] <= 0.0:
        return 0.5
    rho = acov / acov[0]
    if square:
        rho = rho**2
    tau = 0.5 + np.cumsum(rho[1:])
    windows = np.arange(1, n)
    ok = windows >= TAU_WINDOW_C * tau
    m = int(np.argmax(ok)) if np.any(ok) else n - 2
    return float(max(tau[m], 0.5))


def chi2_mean_bounds(n_eff: float) -> tuple[float, float]:
    """95 % interval of the mean of n_eff independent χ²(1) samples."""
    if not (n_eff > 0.0 and math.isfinite(n_eff)):
        return math.nan, math.nan
    low = float(stats.chi2.ppf(0.5 - CONFIDENCE / 2.0, n_eff)) / n_eff
    high = float(stats.chi2.ppf(0.5 + CONFIDENCE / 2.0, n_eff)) / n_eff
    return low, high


def consistency(error: FloatArray, cov: FloatArray) -> dict[str, Any]:
    """NEES test of one run (module docstring): error (m, n), covariance (m, n, n)."""
    n = error.shape[1]
    samples = error.shape[0]
    per_dof: list[dict[str, Any]] = []
    n_eff_sum = 0.0
    n_eff2_sum = 0.0
    for j in range(n):
        x = error[:, j] / np.sqrt(cov[:, j, j])
        tau = integrated_autocorrelation_time(x)
        tau2 = integrated_autocorrelation_time(x, square=True)
        n_eff, n_eff2 = samples / (2.0 * tau), samples / (2.0 * tau2)
        n_eff_sum += n_eff
        n_eff2_sum += n_eff2
        mean = float(np.mean(x**2))
        low, high = chi2_mean_bounds(n_eff)
        low2, high2 = chi2_mean_bounds(n_eff2)
        per_dof.append({'mean_nees': mean, 'tau_int': tau, 'n_eff': n_eff, 'low': low,
                        'high': high, 'inside': bool(low <= mean <= high),
                        'inside_rho2': bool(low2 <= mean <= high2)})
    joint = np.einsum('ij,ij->i', error, np.linalg.solve(cov, error[..., None])[..., 0]) / n
    mean = float(np.mean(joint))
    low, high = chi2_mean_bounds(n_eff_sum)
    low2, high2 = chi2_mean_bounds(n_eff2_sum)
    return {'dof': per_dof, 'joint': {'mean_nees': mean, 'n_eff': n_eff_sum, 'low': low,
                                      'high': high, 'inside': bool(low <= mean <= high),
                                      'inside_rho2': bool(low2 <= mean <= high2)}}


def pid_velocity(poses: FloatArray, sample_time: float, ndof: int) -> FloatArray:
    """The PID's velocity from a pose series (module docstring, `pid_step`) → body (m, ndof).

    `controller_gains.difference_velocity` at the PID's ``VELOCITY_FILTER_TIME`` (tested equal
    to `pid_step`'s filtered finite difference) on the finite poses (m, 3) with the heading
    unwrapped, as `pid_step` wraps each step.
    """
    unwrapped = np.array(poses, dtype=np.float64)
    unwrapped[:, 2] = np.unwrap(unwrapped[:, 2])
    return difference_velocity(unwrapped, sample_time, VELOCITY_FILTER_TIME)[:, :ndof]


def default_dropouts(params: PredictorParams, duration: float,
                     count: int = DROPOUT_COUNT, length: float = DROPOUT_LENGTH,
                     shift: float = 0.0) -> tuple[tuple[float, float], ...]:
    """``count`` dropouts of ``length`` s, evenly spread after the scored start (≥ first training).

    ``shift`` [s] delays every dropout (``dropout_shift_for_seed``: the phase against the
    scenario's manoeuvres). Raises ValueError when they do not fit with at least 60 s of
    tracking between them, the shift included.
    """
    if not (math.isfinite(shift) and shift >= 0.0):
        raise ValueError(f'the dropout shift must be finite and >= 0 s, got {shift!r}')
    begin = scored_start(params, 10**9) * params.sample_time + 20.0
    spacing = (duration - begin) / count
    if spacing < length + 60.0 + shift:
        raise ValueError(f'{count} dropouts of {length:.0f} s (delayed {shift:.0f} s) do not fit '
                         f'after the first training ({begin:.0f} s) in {duration:.0f} s: lengthen '
                         'the run or narrow the spread')
    return tuple((float(round(begin + shift + i * spacing)), length) for i in range(count))


def dropout_shift_for_seed(seed: int, spread: float) -> float:
    """The dropouts' delay [s] for ``seed``: U(0, ``spread``) (``DROPOUT_SHIFT_STREAM``).

    With fixed dropout times every seed drops its poses at the same phase of the setpoint
    schedule: on rao_swell the first dropout always starts with the −45° turn and the other
    two while holding (docs/BENCHMARKS.md, forty-seventh session). A spread samples the phase.
    """
    return schedule_shift_for_seed(seed, spread, DROPOUT_SHIFT_STREAM)


def move_dropouts(scenario: Scenario, params: PredictorParams, seed: int, duration: float,
                  delay: tuple[float, float], length: float = DROPOUT_LOOP_LENGTH
                  ) -> tuple[tuple[float, float], ...]:
    """Pose dropouts that start inside the setpoint moves: one per ``setpoint_schedule`` row.

    Row i's dropout starts at its time plus a delay drawn U(``delay``) for ``seed`` from its own
    stream (``MOVE_DELAY_STREAM``; one draw per row, so skipping a row moves no other). A
    dropout early in a move is where lf_odom's dead reckoning fails worst (forty-eighth
    session); the spread schedule (`dropout_shift_for_seed`) rarely puts one there. A negative
    delay (down to, not including, −``length``) starts the dropout before the setpoint change,
    so that the move or turn begins inside it: no fix shows the vessel starting to move (fifty-
    fifth session). Rows are
    skipped whose dropout would start before the first training, end later than
    ``AFTER_DROPOUT`` before ``duration``, or start less than ``MOVE_DROPOUT_GAP`` after the
    previous dropout's end. Raises ValueError when the scenario has no schedule, the delay
    interval is invalid, or no row is left.
    """
    low, high = (float(v) for v in delay)
    if not (math.isfinite(low) and math.isfinite(high) and -length < low <= high):
        raise ValueError(f'the move delay must be two finite seconds -{length:g} < low <= high '
                         f'(a dropout must contain its setpoint change or follow it), got '
                         f'{delay!r}')
    rows = scenario.controller.setpoint_schedule
    if not rows:
        raise ValueError(f'scenario {scenario.name!r} has no setpoint schedule: place '
                         'its dropouts with --dropout-spread instead of --dropout-moves')
    draws = np.random.default_rng((seed, MOVE_DELAY_STREAM)).uniform(low, high, len(rows))
    first = first_training_samples(params) * params.sample_time
    out: list[tuple[float, float]] = []
    for row, draw in zip(rows, draws, strict=True):
        start = float(round(float(row[0]) + float(draw), 1))
        if start < first or start + length + AFTER_DROPOUT > duration:
            continue
        if out and start < out[-1][0] + out[-1][1] + MOVE_DROPOUT_GAP:
            continue
        out.append((start, length))
    if not out:
        raise ValueError(f'no setpoint move of {scenario.name!r} leaves room for a '
                         f'{length:.0f} s dropout after the first training ({first:.0f} s) in '
                         f'{duration:.0f} s: lengthen the run')
    return tuple(out)


def _wrap_error(estimate: FloatArray, truth: FloatArray, ndof: int) -> FloatArray:
    err = np.asarray(estimate[..., :ndof] - truth[..., :ndof], dtype=np.float64)
    if ndof == 3:
        err[..., 2] = wrap_angle(err[..., 2])
    return err


def true_twist(truth: FloatArray, sample_time: float, ndof: int) -> FloatArray:
    """The true LF body velocity of a true LF pose series (heading unwrapped; a new array)."""
    eta = truth[:, :ndof].copy()
    if ndof == 3:
        eta[:, 2] = np.unwrap(eta[:, 2])
    return body_velocity(eta, sample_time)


def _tracking_run(params: PredictorParams, odometry: OdometryParams,
                  data: dict[str, FloatArray], begin: int,
                  seen_truth: FloatArray | None = None) -> dict[str, Any]:
    """Items 1 and 2 of the module docstring; with ``seen_truth`` item 1 against it too."""
    n, h = params.ndof, params.sample_time
    est = LfStateEstimator(params, odometry, background=False)
    outs: list[OdometryEstimate | None] = []
    try:
        for k in range(len(data['t'])):
            outs.append(est.update(float(data['t'][k]), data['y'][k], data['u'][k])[1])
        reckoner = None if est.memory is None else est.memory.reckoner
    finally:
        est.close()
    truth = data['truth']
    keep = [k for k in range(max(begin - 1, 0), len(outs) - 1) if outs[k] is not None]
    odoms = [cast(OdometryEstimate, outs[k]) for k in keep]
    idx = np.array(keep) + 1  # estimate of update k is valid at t[k + 1]
    pose = np.array([o.pose for o in odoms])
    pose_cov = np.array([o.pose_cov[:n, :n] for o in odoms])
    twist = np.array([o.twist[:n] for o in odoms])
    twist_cov = np.array([o.twist_cov[:n, :n] for o in odoms])
    truth_twist = true_twist(truth, h, n)[idx]
    pose_err = _wrap_error(pose, truth[idx], n)
    twist_err = twist - truth_twist
    # PID's finite difference of the published pose, over the whole run (filter warmed up)
    all_pose = np.array([o.pose if o is not None else np.full(3, np.nan) for o in outs[:-1]])
    valid = np.all(np.isfinite(all_pose), axis=1)
    first = int(np.argmax(valid))
    fd = np.full((all_pose.shape[0], n), np.nan)
    fd[first:] = pid_velocity(all_pose[first:], h, n)
    fd_err = fd[np.array(keep)] - truth_twist

    def rms(values: FloatArray) -> list[float]:
        return [float(v) for v in np.sqrt(np.nanmean(values**2, axis=0))]

    seen: dict[str, Any] = {}
    if seen_truth is not None:
        seen_pose_err = _wrap_error(pose, seen_truth[idx], n)
        seen_twist_err = twist - true_twist(seen_truth, h, n)[idx]
        seen = {'pose_seen': consistency(seen_pose_err, pose_cov),
                'twist_seen': consistency(seen_twist_err, twist_cov),
                'pose_seen_rmse': rms(seen_pose_err), 'twist_seen_rmse': rms(seen_twist_err)}
    return {**seen, 'samples': len(keep), 'calibrated_fraction': float(np.mean([o.calibrated
                                                                          for o in odoms])),
            'reckoner': reckoner,
            'pose': consistency(pose_err, pose_cov), 'twist': consistency(twist_err, twist_cov),
            'pose_rmse': rms(pose_err), 'pose_std_published': rms(
                np.sqrt(np.diagonal(pose_cov, axis1=1, axis2=2))),
            'twist_rmse': rms(twist_err), 'twist_zero_rmse': rms(truth_twist),
            'twist_pid_fd_rmse': rms(fd_err),
            'twist_std_published': rms(np.sqrt(np.diagonal(twist_cov, axis1=1, axis2=2)))}


def _dropout_run(params: PredictorParams, odometry: OdometryParams,
                 data: dict[str, FloatArray], dropouts: Sequence[tuple[float, float]],
                 setup: Any, commands: bool = False) -> dict[str, Any]:
    """Item 3 of the module docstring.

    ``commands``: every sample's applied thrust also reaches the estimator as the DP
    controller's command for that instant (``LfStateEstimator.command``), a stand-in for a bag
    with ``thrust_command`` (the recording keeps no commands): the recording's controller acted
    on another estimator, and the controller read may still find a PD law on this one's
    estimates (the memory is then ``dp_controlled``), with the actuator lag in it.
    """
    n = params.ndof
    t, y, u, truth, omega = data['t'], data['y'], data['u'], data['truth'], data['omega']
    est = LfStateEstimator(params, odometry, background=False)
    oracle = make_estimator('oracle_kf', setup)
    chi2_95 = float(stats.chi2.ppf(CONFIDENCE, n))
    nan_pose = np.full(3, np.nan)
    records: list[dict[str, Any]] = []
    current: dict[str, Any] | None = None
    last_out: OdometryEstimate | None = None
    in_dropout_prev = False
    try:
        for k in range(len(t)):
            tk = float(t[k])
            drop = next(((a, length) for a, length in dropouts if a <= tk < a + length), None)
            if commands:
                est.command(tk, u[k])
            if drop is None:
                if in_dropout_prev:
                    est.restart_segment()
                    current = None
                _, out = est.update(tk, y[k], u[k])
                if out is not None:
                    last_out = out
                oracle.step(tk, y[k], u[k], float(omega[k]))
                in_dropout_prev = False
                continue
            oracle_pose = oracle.step(tk, nan_pose, u[k], float(omega[k]))
            oracle_std = np.asarray(oracle.estimator.lf_std, dtype=np.float64)[:n]
            if current is None:
                held = None if last_out is None else last_out.pose.copy()
                current = {'start': drop[0], 'length': drop[1], 'held': held, 'times': {}}
                records.append(current)
            in_dropout_prev = True
            odom = est.coast(tk, u[k])
            for when in DRIFT_TIMES:
                if abs(tk - drop[0] - when) > 0.5 * params.sample_time or \
                        str(when) in current['times']:
                    continue
                row: dict[str, Any] = {'published': odom is not None}
                if odom is not None:
                    err = _wrap_error(odom.pose, truth[k], n)
                    cov = odom.pose_cov[:n, :n]
                    row['error'] = [float(v) for v in np.abs(err)]
                    row['std'] = [float(v) for v in np.sqrt(np.diag(cov))]
                    row['inside_ellipse'] = bool(err @ np.linalg.solve(cov, err) <= chi2_95)
                    row['mode'] = odom.mode
                    row['elapsed'] = float(odom.dead_reckoning_time)
                oerr = np.abs(_wrap_error(oracle_pose, truth[k], n))
                row['oracle_error'] = [float(v) for v in oerr]
                row['oracle_inside_95'] = [bool(e <= 1.96 * s) for e, s in
                                           zip(oerr, oracle_std, strict=True)]
                if current['held'] is not None:
                    row['hold_error'] = [float(v) for v in
                                         np.abs(_wrap_error(current['held'], truth[k], n))]
                current['times'][str(when)] = row
        reckoner = None if est.memory is None else est.memory.reckoner
        counters = dict(est.odometry.counters)
    finally:
        est.close()
    for rec in records:
        rec.pop('held')
    return {'dropouts': records, 'reckoner_at_end': reckoner, 'counters': counters}


def _in_dropout(t: float, dropouts: Sequence[tuple[float, float]]) -> bool:
    return any(a <= t < a + length for a, length in dropouts)


def _odometry_loop(scenario: Scenario, seed: int, duration: float, params: PredictorParams,
                   odometry: OdometryParams,
                   dropouts: Sequence[tuple[float, float]] = (),
                   log: list[OdometryEstimate] | None = None,
                   velocity_source: str = 'odometry') -> ClosedLoopRun:
    """The predictor loop with the D term from the odometry twist (items 4 and 5).

    Without dropouts the PID takes the predictor's LF pose (= lf_odom's pose while tracking
    without a reacquisition blend). With dropouts it takes lf_odom's pose, as `dp_controller`
    with ``velocity_source: odometry``: dead-reckoned in a dropout (``coast``), blended after
    it; NaN when 'lost' (the PID holds its last estimate). The PID's commands reach the
    estimator as ``thrust_command`` does the node (``LfStateEstimator.command``). ``log``: every
    dead-reckoned estimate is appended to it. ``velocity_source`` (`pid.VELOCITY_SOURCES`, as
    `dp_controller`'s): 'difference', the PID takes its D term from its own filtered finite
    difference of the pose it is given (lf_odom's, dead-reckoned in a dropout, as the node's
    lf_pose is), a DP stack that takes only the position.
    """
    if velocity_source not in VELOCITY_SOURCES:
        raise ValueError(f'velocity_source must be one of {VELOCITY_SOURCES}, got '
                         f'{velocity_source!r}')
    est = LfStateEstimator(params, odometry, background=False)
    latest: list[FloatArray | None] = [None]
    dropped = [False]

    def step(t: float, pose: FloatArray, force: FloatArray, omega: float) -> FloatArray:
        if _in_dropout(t, dropouts):
            dropped[0] = True
            out = est.coast(t, force)
            lf_pose = np.full(3, np.nan) if out is None else out.pose
            if log is not None and out is not None:
                log.append(out)
        else:
            if dropped[0]:
                est.restart_segment()
                dropped[0] = False
            lf_pose, out = est.update(t, pose, force)
            if dropouts and out is not None:
                lf_pose = out.pose
        twist = None if out is None else np.asarray(out.twist, dtype=np.float64)
        latest[0] = twist if twist is not None and np.all(np.isfinite(twist)) else None
        return np.asarray(lf_pose, dtype=np.float64)

    try:
        velocity = (lambda: latest[0]) if velocity_source == 'odometry' else None
        return run_loop(scenario, seed, duration, params.sample_time, step,
                        velocity=velocity, command=est.command)
    finally:
        est.close()


def _observer_loop(scenario: Scenario, seed: int, duration: float, setup: Any,
                   dropouts: Sequence[tuple[float, float]]) -> ClosedLoopRun:
    """The tuned passive observer's loop; in a dropout its model alone (``coast``)."""
    stream = make_estimator(LOOP_OBSERVER, setup)

    def step(t: float, pose: FloatArray, force: FloatArray, omega: float) -> FloatArray:
        if _in_dropout(t, dropouts):
            return np.asarray(stream.estimator.coast(t, force), dtype=np.float64)
        return stream.step(t, pose, force, omega)

    return run_loop(scenario, seed, duration, setup.sample_time, step)


def dropout_deviation(run: ClosedLoopRun, reference: FloatArray, ndof: int,
                      dropouts: Sequence[tuple[float, float]],
                      after: float = AFTER_DROPOUT) -> list[dict[str, Any]]:
    """Item 5: per dropout, the largest distance of the true LF pose from ``reference``.

    ``reference``: per sample of ``run.record`` (n, 3). Returns per dropout the horizontal
    distance [m], (3 DOF) the heading difference [rad] and the applied thrust's horizontal
    magnitude [N] (1 DOF: |surge force|; ``_thrust``: what a quick correction costs) maxima
    during [a, a + L) and [a + L, a + L + after); NaN for a window the run did not reach
    (aborted).
    """
    rec = run.record
    offset = pose_offset(rec.truth_lf_pose, reference[:rec.t.size], ndof)
    distance = np.hypot(offset[:, 0], offset[:, 1]) if ndof == 3 else np.abs(offset[:, 0])
    thrust = (np.hypot(rec.thrust[:, 0], rec.thrust[:, 1]) if ndof == 3
              else np.abs(rec.thrust[:, 0]))
    out = []
    for start, length in dropouts:
        row: dict[str, Any] = {'start': start, 'length': length}
        for label, (a, b) in (('during', (start, start + length)),
                              ('after', (start + length, start + length + after))):
            keep = (rec.t >= a) & (rec.t < b)
            reached = bool(rec.t.size) and float(rec.t[-1]) >= b - 1.0
            row[label] = float(distance[keep].max()) if reached and keep.any() else math.nan
            row[f'{label}_thrust'] = (float(thrust[keep].max()) if reached and keep.any()
                                      else math.nan)
            if ndof == 3:
                row[f'{label}_heading'] = (float(np.abs(offset[keep, 2]).max())
                                           if reached and keep.any() else math.nan)
        out.append(row)
    return out


def dropout_coverage(log: Sequence[OdometryEstimate], run: ClosedLoopRun, ndof: int,
                     dropouts: Sequence[tuple[float, float]]) -> list[dict[str, Any]]:
    """Item 5, trust: per dropout, how often the published 95 % ellipse holds the truth.

    Returns per dropout the fraction of its dead-reckoned estimates (stamps in [a, a + L)) whose
    ellipse contains the loop's true LF pose at the stamp (NaN if none), and for the last one
    the published horizontal std √(P_NN + P_EE) [m] and the horizontal error [m].
    """
    rec = run.record
    chi2_95 = float(stats.chi2.ppf(CONFIDENCE, ndof))
    out = []
    for start, length in dropouts:
        inside: list[bool] = []
        last: tuple[float, float] | None = None
        for estimate in log:
            if not start <= estimate.stamp < start + length:
                continue
            k = int(np.searchsorted(rec.t, estimate.stamp - 1e-9))
            if k >= rec.t.size or abs(rec.t[k] - estimate.stamp) > 1e-6:
                continue  # beyond an aborted run's end
            err = _wrap_error(estimate.pose, rec.truth_lf_pose[k], ndof)
            cov = estimate.pose_cov[:ndof, :ndof]
            inside.append(bool(err @ np.linalg.solve(cov, err) <= chi2_95))
            horizontal = slice(0, min(ndof, 2))
            last = (float(np.sqrt(np.trace(cov[horizontal, horizontal]))),
                    float(np.linalg.norm(err[horizontal])))
        out.append({'start': start, 'inside': float(np.mean(inside)) if inside else math.nan,
                    'end_std': last[0] if last else math.nan,
                    'end_error': last[1] if last else math.nan})
    return out


def _dropout_loops(scenario: Scenario, seed: int, duration: float, params: PredictorParams,
                   odometry: OdometryParams, setup: Any, ideal: SimRecord,
                   odom_run: ClosedLoopRun, shift: float = 0.0,
                   move_delay: tuple[float, float] | None = None,
                   velocity_source: str = 'odometry') -> dict[str, Any]:
    """Item 5 of the module docstring (``odom_run``: item 4's loop without dropouts).

    ``move_delay``: the dropouts start in the setpoint moves (`move_dropouts`) instead of at the
    spread schedule's times. ``velocity_source`` (`pid.VELOCITY_SOURCES`): where lf_odom's
    loop takes its D term; with 'difference' its loop without dropouts is run the same way
    (``odom_run`` is not used).
    """
    if move_delay is None:
        dropouts = default_dropouts(params, duration, length=DROPOUT_LOOP_LENGTH, shift=shift)
    else:
        dropouts = move_dropouts(scenario, params, seed, duration, move_delay)
    log: list[OdometryEstimate] = []
    odom_with = _odometry_loop(scenario, seed, duration, params, odometry, dropouts, log,
                               velocity_source)
    if velocity_source != 'odometry':
        odom_run = _odometry_loop(scenario, seed, duration, params, odometry, (), None,
                                  velocity_source)
    runs = {'lf_odom': (odom_with, odom_run),
            'observer': (_observer_loop(scenario, seed, duration, setup, dropouts),
                         _observer_loop(scenario, seed, duration, setup, ()))}
    out: dict[str, Any] = {'dropouts': [list(d) for d in dropouts],
                           'velocity_source': velocity_source}
    for name, (with_dropouts, without) in runs.items():
        out[name] = {'with_dropouts': dropout_deviation(
                         with_dropouts, _loop_reference(scenario, with_dropouts.record, ideal),
                         params.ndof, dropouts),
                     'without': dropout_deviation(
                         without, _loop_reference(scenario, without.record, ideal),
                         params.ndof, dropouts),
                     'aborted_at': with_dropouts.aborted_at}
    out['lf_odom']['coverage'] = dropout_coverage(log, odom_with, params.ndof, dropouts)
    return out


def _loop_runs(scenario_name: str, seed: int, duration: float, params: PredictorParams,
               odometry: OdometryParams, setup: Any, warmup: float,
               dropout_loops: bool = False, dropout_shift: float = 0.0,
               move_delay: tuple[float, float] | None = None,
               dropout_velocity: str = 'odometry') -> dict[str, Any]:
    """Items 4 and (``dropout_loops``) 5 of the module docstring."""
    scenario = load_scenario(scenario_name)
    h = params.sample_time
    fd_stream = make_estimator(LOOP_FD, setup)
    fd_run = run_loop(scenario, seed, duration, h, fd_stream.step)
    odom_run = _odometry_loop(scenario, seed, duration, params, odometry)
    ideal = simulate(scenario, seed=seed, duration=duration, controller=True,
                     feedback='truth_lf')
    results, _ = run_closed_loops(scenario, seed, duration, setup, (LOOP_FD, LOOP_ODOM), ideal,
                                  warmup, {LOOP_FD: fd_run, LOOP_ODOM: odom_run})
    keys = ('position_rmse', 'heading_rmse', 'max_excursion', 'thrust_wave_band_power',
            'aborted_at')
    out: dict[str, Any] = {}
    for name, metrics in results.items():
        out[name] = {key: metrics.get(key) for key in keys}
        verdict = metrics.get('stability', {})
        out[name]['stable'] = verdict.get('stable')
        out[name]['stability_reason'] = verdict.get('reason')
    if dropout_loops:
        out['dropout_loops'] = _dropout_loops(scenario, seed, duration, params, odometry, setup,
                                              ideal, odom_run, dropout_shift, move_delay,
                                              dropout_velocity)
    return out


def run_odometry_case(scenario_name: str, seed: int, duration: float | None = DEFAULT_DURATION,
                      *, odometry: OdometryParams | None = None,
                      params_overrides: dict[str, Any] | None = None,
                      dropouts: Sequence[tuple[float, float]] | None = None,
                      loops: bool = True, dead_reckoning: bool = True,
                      tracking: bool = True, dropout_loops: bool = False,
                      dropout_spread: float = 0.0,
                      dropout_moves: tuple[float, float] | None = None,
                      dead_reckoning_commands: bool = False,
                      dropout_velocity: str = 'odometry') -> dict[str, Any]:
    """Every measurement of the module docstring on one (scenario, seed); JSON-ready.

    ``dropout_spread`` [s]: the default dropouts of items 3 and 5 are delayed by the seed's
    U(0, spread) draw (`dropout_shift_for_seed`; given ``dropouts`` of item 3 are not moved);
    0: at the same times in every seed. ``dropout_moves`` (low, high) [s]: item 5's dropouts
    start that long after each setpoint change instead (`move_dropouts`; item 3 unchanged).
    ``dead_reckoning_commands``: item 3 also feeds the thrust as the controller's commands
    (`_dropout_run`'s ``commands``). ``dropout_velocity``: where item 5's lf_odom loop takes its
    D term (`pid.VELOCITY_SOURCES`).
    """
    begin_time = time.monotonic()
    scenario = load_scenario(scenario_name)
    params = predictor_params(scenario, params_overrides)
    odometry = odometry or OdometryParams()
    setup = make_setup(scenario, seed, params)
    recording = make_recording(scenario, seed, duration, setup)
    data = recording.data()
    setup = replace(setup, wave_peak_freq=float(np.median(data['omega'])))
    total = float(data['t'][-1])
    begin = scored_start(params, len(data['t']))
    shift = dropout_shift_for_seed(seed, dropout_spread)
    if dropouts is None:
        dropouts = default_dropouts(params, total, shift=shift)
    first = first_training_samples(params) * params.sample_time
    if any(a < first for a, _ in dropouts):
        raise ValueError(f'dropouts must start after the first training ({first:.0f} s)')
    out: dict[str, Any] = {'scenario': scenario_name, 'seed': seed, 'ndof': params.ndof,
                           'duration': total, 'warmup': float(data['t'][begin]),
                           'pose_cov_scale': odometry.pose_cov_scale,
                           'pose_lag_scale': odometry.pose_lag_scale,
                           'pose_lag_prior': odometry.pose_lag_prior,
                           'pose_twin_gain': odometry.pose_twin_gain,
                           'pose_twin_fit': odometry.pose_twin_fit,
                           'pose_heading_speed_lag': odometry.pose_heading_speed_lag,
                           'twist_cov_scale': odometry.twist_cov_scale,
                           'twist_reference_cutoff': odometry.twist_reference_cutoff,
                           'pose_reference_cutoff': odometry.pose_reference_cutoff,
                           'twist_likelihood_fit': odometry.twist_likelihood_fit,
                           'twist_attenuation': odometry.twist_attenuation,
                           'twist_bandwidth': odometry.twist_bandwidth,
                           'dead_reckoning_timeout': odometry.dead_reckoning_timeout,
                           'dropout_shift': shift,
                           'dropout_moves': None if dropout_moves is None else list(dropout_moves),
                           'recording': recording.provenance.to_dict()}
    if tracking:
        seen = recording_seen_truth(recording, params.sample_time)
        out['tracking'] = _tracking_run(params, odometry, data, begin, seen)
    if dead_reckoning:
        out['dead_reckoning'] = _dropout_run(params, odometry, data, dropouts, setup,
                                             dead_reckoning_commands)
        out['dead_reckoning']['commands'] = dead_reckoning_commands
    if loops and scenario.controller.enabled:
        out['closed_loop'] = _loop_runs(scenario_name, seed, total, params, odometry, setup,
                                        float(data['t'][begin]), dropout_loops, shift,
                                        dropout_moves, dropout_velocity)
    out['seconds'] = round(time.monotonic() - begin_time, 1)
    return out


@dataclass(frozen=True)
class OdometrySpec:
    """One case (picklable)."""

    scenario: str
    seed: int
    duration: float | None = DEFAULT_DURATION
    pose_cov_scale: float | None = None  # None: the OdometryParams default
    twist_cov_scale: float | None = None
    twist_bandwidth: float | None = None
    pose_lag_scale: float | None = None
    loops: bool = True
    dead_reckoning: bool = True
    tracking: bool = True
    params_overrides: dict[str, Any] = field(default_factory=dict)
    dropout_loops: bool = False
    odometry_overrides: dict[str, Any] = field(default_factory=dict)
    dropout_spread: float = 0.0
    dropout_moves: tuple[float, float] | None = None
    dead_reckoning_commands: bool = False
    dropout_velocity: str = 'odometry'

    @property
    def key(self) -> str:
        """Unique, readable task key."""
        return f'odometry-{self.scenario}-seed{self.seed}-{abs(hash(self)) % 10**8:08d}'

    def __hash__(self) -> int:
        """Hash of the printable fields."""
        return hash((self.scenario, self.seed, self.duration, self.pose_cov_scale,
                     self.twist_cov_scale, self.twist_bandwidth, self.pose_lag_scale, self.loops,
                     self.dead_reckoning, self.tracking,
                     tuple(sorted(self.params_overrides.items())), self.dropout_loops,
                     tuple(sorted(self.odometry_overrides.items())), self.dropout_spread,
                     self.dropout_moves, self.dead_reckoning_commands, self.dropout_velocity))


def run_spec(spec: OdometrySpec) -> dict[str, Any]:
    """One case, deterministic wherever it runs (torch on one thread)."""
    import torch

    torch.set_num_threads(1)
    values: dict[str, Any] = dict(spec.odometry_overrides)
    if spec.pose_cov_scale is not None:
        values['pose_cov_scale'] = spec.pose_cov_scale
    if spec.twist_cov_scale is not None:
        values['twist_cov_scale'] = spec.twist_cov_scale
    if spec.twist_bandwidth is not None:
        values['twist_bandwidth'] = spec.twist_bandwidth
    if spec.pose_lag_scale is not None:
        values['pose_lag_scale'] = spec.pose_lag_scale
    return run_odometry_case(spec.scenario, spec.seed, spec.duration,
                             odometry=OdometryParams(**values),
                             params_overrides=dict(spec.params_overrides) or None,
                             loops=spec.loops, dead_reckoning=spec.dead_reckoning,
                             tracking=spec.tracking, dropout_loops=spec.dropout_loops,
                             dropout_spread=spec.dropout_spread,
                             dropout_moves=spec.dropout_moves,
                             dead_reckoning_commands=spec.dead_reckoning_commands,
                             dropout_velocity=spec.dropout_velocity)


def run_specs(specs: Sequence[OdometrySpec], scheduler: str | None = None,
              workers: int | None = 2, progress: bool = True) -> list[dict[str, Any]]:
    """Every spec on Dask (``benchmark.distributed.run_cases``); results in spec order."""
    from lf_predictor_ros.benchmark import distributed
    from lf_predictor_ros.benchmark.suite import CaseResult

    task = cast(Callable[[distributed.CaseSpec], CaseResult], run_spec)
    cases = cast(Sequence[distributed.CaseSpec], specs)
    results = distributed.run_cases(cases, scheduler, workers, progress, task=task)
    return cast(list[dict[str, Any]], results)


# ---------------------------------------------------------------- summaries

def calibrate(cases: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Scales making the mean NEES 1: the old scale × geometric mean of the runs' per-DOF NEES.

    The pose also reports ``pose_log_spread``: the standard deviation over runs and DOFs of
    log(per-DOF mean NEES) (unchanged by the scale: what a better covariance model lowers).
    Cases of several ``pose_lag_scale`` values: one such result per value, keyed by it. The NEES
    is the one against the seen LF truth (``pose_seen``, ``twist_seen``) where a case has it
    (seventeenth session on), else against the twin.
    """
    lags = sorted({case.get('pose_lag_scale', 0.0) for case in cases})
    if len(lags) > 1:
        return {f'pose_lag_scale {lag:g}': calibrate([case for case in cases
                                                      if case.get('pose_lag_scale', 0.0) == lag])
                for lag in lags}
    out: dict[str, Any] = {}
    for kind in ('pose', 'twist'):
        logs = [math.log(dof['mean_nees']) + math.log(case[f'{kind}_cov_scale'])
                for case in cases if 'tracking' in case
                for dof in case['tracking'].get(f'{kind}_seen', case['tracking'][kind])['dof']]
        out[f'{kind}_cov_scale'] = math.exp(float(np.mean(logs)))
        out[f'{kind}_log_spread'] = float(np.std(logs))
    return out


def _by_scenario(cases: Sequence[dict[str, Any]], key: str | None = None,
                 ) -> dict[str, list[dict[str, Any]]]:
    """Cases by scenario (those with ``key`` only, if given).

    Cases of several ``twist_bandwidth`` (``pose_lag_scale``) values are grouped per scenario
    and value.
    """
    several = len({case.get('twist_bandwidth') for case in cases}) > 1
    several_lags = len({case.get('pose_lag_scale') for case in cases}) > 1
    groups: dict[str, list[dict[str, Any]]] = {}
    for case in cases:
        if key is None or key in case:
            label = case['scenario']
            if several:
                label += f' (twist_bandwidth {case.get("twist_bandwidth")})'
            if several_lags:
                label += f' (pose_lag_scale {case.get("pose_lag_scale")})'
            groups.setdefault(label, []).append(case)
    return groups


def _fmt(value: float) -> str:
    return fmt_number(value)


def nees_table(cases: Sequence[dict[str, Any]]) -> str:
    """Markdown: mean NEES [95 % interval over runs], fraction of runs inside their bounds."""
    lines = ['| scenario | runs | quantity | DOF | mean NEES [95 % CI over runs] | runs inside '
             'bounds (ρ) | runs inside (ρ²) | median bounds |',
             '|---|---|---|---|---|---|---|---|']
    for scenario, group in _by_scenario(cases, 'tracking').items():
        n = group[0]['ndof']
        kinds = [k for k in ('pose', 'twist', 'pose_seen', 'twist_seen')
                 if all(k in c['tracking'] for c in group)]
        for kind in kinds:
            names = (DOFS if kind.startswith('pose') else TWIST_DOFS)[:n]
            for j, name in enumerate([*names, 'joint']):
                rows = [c['tracking'][kind]['dof'][j] if name != 'joint'
                        else c['tracking'][kind]['joint'] for c in group]
                inside = sum(r['inside'] for r in rows)
                inside2 = sum(r['inside_rho2'] for r in rows)
                low = float(np.median([r['low'] for r in rows]))
                high = float(np.median([r['high'] for r in rows]))
                cell = interval([r['mean_nees'] for r in rows]).cell(_fmt)
                lines.append(f'| {scenario} | {len(group)} | {kind} | {name} | {cell} | '
                             f'{inside}/{len(group)} | {inside2}/{len(group)} | '
                             f'[{_fmt(low)}, {_fmt(high)}] |')
    return '\n'.join(lines)


def twist_table(cases: Sequence[dict[str, Any]]) -> str:
    """Markdown: twist RMSE of lf_odom, the zero estimate and the PID finite difference."""
    lines = ['| scenario | runs | DOF | lf_odom twist RMSE | zero estimate (RMS true) | '
             'PID finite difference (T_v = 1 s) | lf_odom / zero |',
             '|---|---|---|---|---|---|---|']
    for scenario, group in _by_scenario(cases, 'tracking').items():
        n = group[0]['ndof']
        for j, name in enumerate(TWIST_DOFS[:n]):
            odo = [c['tracking']['twist_rmse'][j] for c in group]
            zero = [c['tracking']['twist_zero_rmse'][j] for c in group]
            fd = [c['tracking']['twist_pid_fd_rmse'][j] for c in group]
            ratio = [a / b for a, b in zip(odo, zero, strict=True)]
            lines.append(f'| {scenario} | {len(group)} | {name} | {interval(odo).cell(_fmt)} | '
                         f'{interval(zero).cell(_fmt)} | {interval(fd).cell(_fmt)} | '
                         f'{interval(ratio).cell(_fmt)} |')
    return '\n'.join(lines)


def drift_table(cases: Sequence[dict[str, Any]]) -> str:
    """Markdown: drift at 30/60/120 s per DOF, lf_odom vs oracle (predict only) vs hold."""
    lines = ['| scenario | DOF | after | lf_odom drift | in 95 % ellipse | published | oracle '
             'KF predict-only drift | oracle in 95 % | hold last drift |',
             '|---|---|---|---|---|---|---|---|---|']
    for scenario, group in _by_scenario(cases, 'dead_reckoning').items():
        n = group[0]['ndof']
        for j, name in enumerate(DOFS[:n]):
            for when in DRIFT_TIMES:
                key = str(when)
                rows = [(c['seed'], d['times'][key]) for c in group
                        if 'dead_reckoning' in c
                        for d in c['dead_reckoning']['dropouts'] if key in d['times']]
                if not rows:
                    continue
                # per seed: mean over its dropouts, then the interval over seeds
                seeds = sorted({s for s, _ in rows})

                def per_seed(field_name: str, rows: list[tuple[int, dict[str, Any]]] = rows,
                             seeds: list[int] = seeds, j: int = j) -> list[float]:
                    vals = []
                    for s in seeds:
                        got = [r[field_name][j] for ss, r in rows if ss == s and field_name in r]
                        vals.append(float(np.mean(got)) if got else math.nan)
                    return vals

                published = sum(r['published'] for _, r in rows)
                inside = sum(r.get('inside_ellipse', False) for _, r in rows)
                oracle_in = sum(r['oracle_inside_95'][j] for _, r in rows)
                drift = interval(per_seed('error')).cell(_fmt)
                oracle = interval(per_seed('oracle_error')).cell(_fmt)
                hold = interval(per_seed('hold_error')).cell(_fmt)
                lines.append(f'| {scenario} | {name} | {when:.0f} s | {drift} | '
                             f'{inside}/{published} | {published}/{len(rows)} | {oracle} | '
                             f'{oracle_in}/{len(rows)} | {hold} |')
    return '\n'.join(lines)


def loop_table(cases: Sequence[dict[str, Any]]) -> str:
    """Markdown: the predictor loop with the finite-difference vs the lf_odom D term."""
    lines = ['| scenario | runs | D term | position RMSE [m] | heading RMSE [rad] | thrust '
             'wave-band power / FD loop (per DOF) | position RMSE / FD loop | stable runs |',
             '|---|---|---|---|---|---|---|---|']
    for scenario, group in _by_scenario(cases, 'closed_loop').items():
        n = group[0]['ndof']
        for loop, label in ((LOOP_FD, 'finite difference'), (LOOP_ODOM, 'lf_odom twist')):
            pos = [c['closed_loop'][loop]['position_rmse'] for c in group]
            head = [c['closed_loop'][loop].get('heading_rmse') or math.nan for c in group]
            power = []
            for dof in ('north', 'east', 'yaw')[:n]:
                values = [c['closed_loop'][loop]['thrust_wave_band_power'][dof]
                          / c['closed_loop'][LOOP_FD]['thrust_wave_band_power'][dof]
                          for c in group]
                power.append(interval(values).cell(_fmt))
            ratio = [c['closed_loop'][loop]['position_rmse']
                     / c['closed_loop'][LOOP_FD]['position_rmse'] for c in group]
            stable = sum(c['closed_loop'][loop]['stable'] is True for c in group)
            lines.append(f'| {scenario} | {len(group)} | {label} | {interval(pos).cell(_fmt)} | '
                         f'{interval(head).cell(_fmt) if n == 3 else "–"} | '
                         f'{" / ".join(power)} | {interval(ratio).cell(_fmt)} | '
                         f'{stable}/{len(group)} |')
    return '\n'.join(lines)


def _dropout_loop_runs(cases: Sequence[dict[str, Any]]
                       ) -> dict[str, tuple[int, list[dict[str, Any]]]]:
    """(ndof, item 5 results) per scenario; runs without dropout loops, empty groups left out."""
    out: dict[str, tuple[int, list[dict[str, Any]]]] = {}
    for scenario, group in _by_scenario(cases, 'closed_loop').items():
        rows = [c['closed_loop']['dropout_loops'] for c in group
                if 'dropout_loops' in c['closed_loop']]
        if rows:
            out[scenario] = (int(group[0]['ndof']), rows)
    return out


def dropout_loop_table(cases: Sequence[dict[str, Any]]) -> str:
    """Markdown: item 5, worst distance from the reference during and after the dropouts."""
    lines = ['| scenario | runs | estimator | dropouts | worst during [m] (without dropout) | '
             'worst in the 120 s after [m] (without) | heading during / after [rad] | '
             'aborted |', '|---|---|---|---|---|---|---|---|']
    for scenario, (n, rows) in _dropout_loop_runs(cases).items():
        for name in ('lf_odom', 'observer'):
            def worst(key: str, part: str, rows_: Sequence[dict[str, Any]] = rows,
                      name_: str = name) -> list[float]:
                return [float(np.max([d[key] for d in r[name_][part]])) for r in rows_]

            def cell(values: list[float]) -> str:
                if not all(math.isfinite(v) for v in values):
                    return 'n/a'
                return interval(values).cell(_fmt)

            heading = (f"{cell(worst('during_heading', 'with_dropouts'))} / "
                       f"{cell(worst('after_heading', 'with_dropouts'))}" if n == 3 else '–')
            aborted = sum(r[name]['aborted_at'] is not None for r in rows)
            lines.append(
                f"| {scenario} | {len(rows)} | {name} | {len(rows[0]['dropouts'])} × "
                f"{rows[0]['dropouts'][0][1]:.0f} s | {cell(worst('during', 'with_dropouts'))} "
                f"({cell(worst('during', 'without'))}) | {cell(worst('after', 'with_dropouts'))} "
                f"({cell(worst('after', 'without'))}) | {heading} | {aborted}/{len(rows)} |")
    return '\n'.join(lines)


def dropout_trust_table(cases: Sequence[dict[str, Any]]) -> str:
    """Markdown: item 5, trust: the published covariance against the loop's truth."""
    lines = ['| scenario | dropouts | truth inside the published 95 % ellipse (mean fraction of '
             'the dead-reckoned estimates per dropout) | horizontal std published at the end '
             '[m] | horizontal error at the end [m] | dropouts with error > 2 × std |',
             '|---|---|---|---|---|---|']
    for scenario, (_, runs) in _dropout_loop_runs(cases).items():
        rows = [d for r in runs for d in r['lf_odom'].get('coverage', [])
                if math.isfinite(d['inside'])]
        if not rows:
            continue

        def cell(key: str, rows_: list[dict[str, Any]] = rows) -> str:
            return interval([float(d[key]) for d in rows_]).cell(_fmt)

        wide = sum(d['end_error'] > 2.0 * d['end_std'] for d in rows)
        lines.append(f"| {scenario} | {len(rows)} | {cell('inside')} | {cell('end_std')} | "
                     f"{cell('end_error')} | {wide}/{len(rows)} |")
    return '\n'.join(lines)


def _per_run_mean(runs: Sequence[dict[str, Any]], name: str, key: str) -> FloatArray:
    """Per run the mean of ``key`` over the dropouts of estimator ``name``."""
    return np.array([np.mean([d[key] for d in r[name]['with_dropouts']]) for r in runs])


def _heading_cell(runs: Sequence[dict[str, Any]], name: str) -> str:
    """Mean / max over all dropouts of the larger heading difference of during and after."""
    values = [max(d.get('during_heading', math.nan), d.get('after_heading', math.nan))
              for r in runs for d in r[name]['with_dropouts']]
    if not all(math.isfinite(v) for v in values):
        return '–'
    return f'{np.mean(values):.3f} / {np.max(values):.2f}'


def _finite_cell(values: FloatArray) -> str:
    return interval(list(values)).cell(_fmt) if np.all(np.isfinite(values)) else 'n/a'


def dropout_mean_table(cases: Sequence[dict[str, Any]]) -> str:
    """Markdown: item 5 per run as the mean over its dropouts, lf_odom against the observer.

    Per run the mean distance during (after) its dropouts, then mean [95 % interval] over runs,
    and the per-run ratio lf_odom / observer of the same seed; heading: the larger of during
    and after per dropout, mean / max over all dropouts; how many dropouts lf_odom stayed
    closer than the observer in.
    """
    lines = ['| scenario | lf_odom during [m] | observer during [m] | ratio per run | '
             'lf_odom after [m] | observer after [m] | heading lf_odom [rad] | '
             'heading observer [rad] | lf_odom closer |', '|---|---|---|---|---|---|---|---|---|']
    for scenario, (_, runs) in _dropout_loop_runs(cases).items():
        during = {name: _per_run_mean(runs, name, 'during') for name in ('lf_odom', 'observer')}
        after = {name: _per_run_mean(runs, name, 'after') for name in ('lf_odom', 'observer')}
        pairs = [(a['during'], b['during']) for r in runs
                 for a, b in zip(r['lf_odom']['with_dropouts'], r['observer']['with_dropouts'],
                                 strict=True)]
        closer = sum(a < b for a, b in pairs)
        lines.append(f"| {scenario} | {_finite_cell(during['lf_odom'])} | "
                     f"{_finite_cell(during['observer'])} | "
                     f"{_finite_cell(during['lf_odom'] / during['observer'])} | "
                     f"{_finite_cell(after['lf_odom'])} | {_finite_cell(after['observer'])} | "
                     f"{_heading_cell(runs, 'lf_odom')} | {_heading_cell(runs, 'observer')} | "
                     f"{closer}/{len(pairs)} |")
    return '\n'.join(lines)


def report(cases: Sequence[dict[str, Any]]) -> str:
    """Every table."""
    seconds = sum(c.get('seconds', 0.0) for c in cases)
    sources = sorted({c.get('closed_loop', {}).get('dropout_loops', {}).get('velocity_source',
                                                                           'odometry')
                      for c in cases if c.get('closed_loop', {}).get('dropout_loops')})
    return '\n\n'.join([
        f'{len(cases)} runs, seeds {sorted({c["seed"] for c in cases})}, pose_cov_scale '
        f'{cases[0]["pose_cov_scale"]:.4g}, pose_lag_scale {cases[0].get("pose_lag_scale", "–")}, '
        f'twist_cov_scale {cases[0]["twist_cov_scale"]:.4g}, '
        + (f"dropout loops' D term from {' and '.join(sources)}, " if sources else '')
        + f'{seconds / 60:.1f} worker-min',
        '**Covariance consistency (NEES)**', nees_table(cases), '**Twist accuracy**',
        twist_table(cases), '**Dead-reckoning drift**', drift_table(cases),
        '**Closed loop, D term**', loop_table(cases),
        '**Closed loop through pose dropouts**', dropout_loop_table(cases),
        '**The same, per run the mean over its dropouts**', dropout_mean_table(cases),
        '**Trust in the loop through pose dropouts (lf_odom)**', dropout_trust_table(cases)])


# ---------------------------------------------------------------- CLI

def _odometry_overrides(items: Sequence[str]) -> dict[str, Any] | None:
    """FIELD=VALUE strings → a dict that makes a valid OdometryParams, or None."""
    out: dict[str, Any] = {}
    for item in items:
        name, sep, text = item.partition('=')
        if not sep:
            return None
        value = yaml.safe_load(text)
        out[name] = tuple(value) if isinstance(value, list) else value
    try:
        OdometryParams(**out)
    except (TypeError, ValueError):
        return None
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point (module docstring)."""
    parser = argparse.ArgumentParser(prog='odometry_bench', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest='command', required=True)
    run = sub.add_parser('run', help='run cases, write JSON')
    run.add_argument('--scenarios', nargs='*', default=list(DEFAULT_SCENARIOS))
    run.add_argument('--seeds', nargs='*', type=int, default=[1, 2])
    run.add_argument('--duration', type=float, default=DEFAULT_DURATION, help='simulated s')
    run.add_argument('--pose-cov-scale', type=float, default=None)
    run.add_argument('--twist-cov-scale', type=float, default=None)
    run.add_argument('--twist-bandwidth', nargs='+', type=float, default=[None],
                     help='twist Kalman filter bandwidth(s) [rad/s] (default: the '
                     'OdometryParams default); several: every case once per value')
    run.add_argument('--pose-lag-scale', nargs='+', type=float, default=[None],
                     help='OdometryParams.pose_lag_scale value(s) (default: its default); '
                     'several: every case once per value')
    run.add_argument('--no-loops', action='store_true', help='skip the closed loops (item 4)')
    run.add_argument('--loop-seeds', nargs='*', type=int, default=None,
                     help='run the closed loops only for these seeds (default: every seed)')
    run.add_argument('--no-tracking', action='store_true',
                     help='skip the run without dropouts (items 1 and 2)')
    run.add_argument('--no-dead-reckoning', action='store_true',
                     help='skip the dropout run (item 3)')
    run.add_argument('--dead-reckoning-commands', action='store_true',
                     help="item 3 also feeds the recorded (applied) thrust as the DP "
                     "controller's commands, a stand-in for a replayed bag's thrust_command (the "
                     'controller read may then mark the memory dp_controlled)')
    run.add_argument('--dropout-loops', action='store_true',
                     help='also the closed loops through pose dropouts (item 5; with the loops)')
    run.add_argument('--dropout-loop-velocity', choices=VELOCITY_SOURCES,
                     default='odometry',
                     help="where item 5's lf_odom loop takes its D term: lf_odom's twist "
                     "(default) or the PID's own finite difference of the pose, as "
                     "dp_controller's velocity_source")
    run.add_argument('--dropout-spread', type=float, default=0.0, metavar='SECONDS',
                     help="delay each seed's dropouts (items 3 and 5) by its own U(0, SECONDS) "
                     'draw, so the seeds sample their phase against the setpoint schedule '
                     '(default 0: the same times in every seed, as before the forty-seventh '
                     'session)')
    run.add_argument('--dropout-moves', nargs=2, type=float, default=None,
                     metavar=('LOW', 'HIGH'),
                     help="item 5's dropouts start U(LOW, HIGH) s after each setpoint change "
                     '(scenarios with a setpoint schedule; the seed draws the delays) instead '
                     'of at the spread schedule: the dead reckoning in moves; -60 < LOW <= HIGH '
                     '(a negative LOW: the move begins inside the dropout)')
    run.add_argument('--odometry', nargs='*', default=[], metavar='FIELD=VALUE',
                     help='OdometryParams overrides, e.g. dead_reckoner=model (YAML values)')
    run.add_argument('--param', action='append', default=[], metavar='FIELD=VALUE',
                     help='run the predictor with this PredictorParams value instead of the '
                     "scenario's default (YAML value; repeatable), e.g. "
                     'north_east_decoupled=false, as `benchmark --param`')
    run.add_argument('--scheduler', default=None, help="Dask address, or 'none' (in process)")
    run.add_argument('--workers', type=int, default=2)
    run.add_argument('-o', '--output', required=True, help='JSON file')
    cal = sub.add_parser('calibrate', help='covariance scales from tuning-seed JSON')
    cal.add_argument('files', nargs='+')
    rep = sub.add_parser('report', help='markdown tables from JSON')
    rep.add_argument('files', nargs='+')
    args = parser.parse_args(argv)
    if args.command == 'run':
        for name in BLAS_THREAD_VARIABLES:
            os.environ.setdefault(name, '1')
        loop_seeds = set(args.seeds if args.loop_seeds is None else args.loop_seeds)
        if not (math.isfinite(args.dropout_spread) and args.dropout_spread >= 0.0):
            parser.error(f'--dropout-spread must be a finite number >= 0 [s], got '
                         f'{args.dropout_spread}')
        moves: tuple[float, float] | None = None if args.dropout_moves is None else \
            (float(args.dropout_moves[0]), float(args.dropout_moves[1]))
        if moves is not None:  # every scenario's schedule checked before any run
            try:
                for name in args.scenarios:
                    scenario = load_scenario(name)
                    move_dropouts(scenario, predictor_params(scenario, None),
                                  args.seeds[0] if args.seeds else 0, args.duration, moves)
            except ValueError as exc:
                parser.error(f'--dropout-moves LOW HIGH: {exc}')
        overrides = _odometry_overrides(args.odometry)
        if overrides is None:
            parser.error(f'--odometry takes FIELD=VALUE with FIELD an OdometryParams field and '
                         f'a valid value, got {args.odometry}')
        try:
            params = param_overrides(args.param)
        except ValueError as exc:
            parser.error(str(exc))
        specs = [OdometrySpec(s, seed, args.duration, args.pose_cov_scale, args.twist_cov_scale,
                              bandwidth, lag, not args.no_loops and seed in loop_seeds,
                              not args.no_dead_reckoning, not args.no_tracking,
                              params_overrides=params, dropout_loops=args.dropout_loops,
                              odometry_overrides=overrides, dropout_spread=args.dropout_spread,
                              dropout_moves=moves,
                              dead_reckoning_commands=args.dead_reckoning_commands,
                              dropout_velocity=args.dropout_loop_velocity)
                 for bandwidth in args.twist_bandwidth for lag in args.pose_lag_scale
                 for s in args.scenarios for seed in args.seeds]
        results = run_specs(specs, args.scheduler, args.workers)
        with open(args.output, 'w', encoding='utf-8') as stream:
            json.dump(results, stream, indent=1)
        print(report(results))
        return 0
    cases: list[dict[str, Any]] = []
    for name in args.files:
        with open(name, encoding='utf-8') as stream:
            cases.extend(json.load(stream))
    if args.command == 'calibrate':
        print(json.dumps(calibrate(cases)))
    else:
        print(report(cases))
    return 0


if __name__ == '__main__':
    sys.exit(main())
