"""Offline evaluation: run an `LfEstimator` over recorded arrays and score it against truth.

Metrics (anchors §6), per DOF:

- rmse: √mean(e²), e = estimate − truth (heading error wrapped to (−π, π]).
- derivative_rmse: RMSE of the finite-difference rates Δx/Δt of estimate vs truth (heading
  unwrapped first). Wrong-signed LF rates drove the thesis's PID loop unstable (§5.4.2).
- wave_band_power: power of e inside the wave band [ω_lo, ω_hi] rad/s: the one-sided Welch PSD
  (Hann, 50 % overlap, segments of about 200 s) integrated over the band [m² or rad²]. For a
  sinusoidal error of amplitude A in the band it is A²/2.
- lag: the shift d [s] maximizing the correlation coefficient between a fixed window of the
  truth and the estimate shifted by d (|d| <= max_lag, the window leaves max_lag at both ends so
  every shift compares equally long, fully overlapping series), refined by a parabola through
  the peak; positive when the estimate lags the truth. The fixed window avoids the bias toward
  zero shift that a plain full cross-correlation has on non-stationary LF motion (DP moves).
- largest_step_ratio: the largest one-sample change of the estimate over the largest one-sample
  change of the truth (heading unwrapped) [-]: an LF estimate should never move much faster than
  the LF motion it estimates (issue 13: no output step larger than 3× the true LF motion over
  the same interval). inf if the truth never moves and the estimate does.

Closed-loop metrics (`loop_metrics`, anchors §6), of one DP loop over t ≥ start, from the true LF
pose and the applied thrust: ``position_rmse`` = √mean(Δn² + Δe²) [m] from the setpoint,
``heading_rmse`` [rad] (3 DOF, wrapped), ``max_excursion`` = max √(Δn² + Δe²) [m] (1 DOF: the
north offset |Δn| in both), ``thrust_wave_band_power`` per DOF (`band_power` of the thrust [N²,
N², (N·m)²]) and ``thrust_total_variation`` per DOF = Σ|τ[k+1] − τ[k]| [N, N, N·m] (actuator
wear).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import signal

from lf_predictor_ros.core.estimator import LfEstimator, check_ndof
from lf_predictor_ros.core.heading import wrap_angle

FloatArray = NDArray[np.float64]
DOF_NAMES = ('north', 'east', 'yaw')
DEFAULT_WAVE_BAND = (0.3, 1.3)  # [rad/s], the ω0 range of thesis eq. 3.9
DEFAULT_MAX_LAG = 60.0  # [s] search range of the cross-correlation lag
WELCH_SEGMENT = 200.0  # [s] Welch segment length: 0.03 rad/s resolution
_YAW = 2


@dataclass(frozen=True)
class Metrics:
    """Per-DOF scores of one estimate (tuples of length ndof, in DOF_NAMES order)."""

    ndof: int
    samples: int
    rmse: tuple[float, ...]
    derivative_rmse: tuple[float, ...]
    wave_band_power: tuple[float, ...]
    lag: tuple[float, ...]
    largest_step_ratio: tuple[float, ...] = ()

    def to_dict(self) -> dict[str, object]:
        """JSON-ready dict: {'ndof', 'samples', 'north': {'rmse': …, …}, …}."""
        out: dict[str, object] = {'ndof': self.ndof, 'samples': self.samples}
        for i, name in enumerate(DOF_NAMES[: self.ndof]):
            dof: dict[str, float] = {
                'rmse': self.rmse[i],
                'derivative_rmse': self.derivative_rmse[i],
                'wave_band_power': self.wave_band_power[i],
                'lag': self.lag[i],
            }
            if self.largest_step_ratio:
                dof['largest_step_ratio'] = self.largest_step_ratio[i]
            out[name] = dof
        return out


def run_estimator(
    estimator: LfEstimator,
    t: ArrayLike,
    pose: ArrayLike,
    force: ArrayLike,
    *,
    steps_ahead: int = 0,
) -> FloatArray:
    """Feed the estimator every sample; return its estimates (n, 3) aligned to t.

    Args:
        estimator: any `LfEstimator` (not reset here).
        t: sample times (n,) [s].
        pose: measured poses (n, 3).
        force: applied generalized forces (n, 3).
        steps_ahead: samples ahead the output is valid for (1 for the predictor, whose output
            at t is valid at t + sample_time); row k + steps_ahead receives the output of
            update(t[k]); the first rows repeat the first output.
    """
    times = np.asarray(t, dtype=np.float64)
    poses = np.asarray(pose, dtype=np.float64)
    forces = np.asarray(force, dtype=np.float64)
    n = times.size
    if poses.shape != (n, 3) or forces.shape != (n, 3):
        raise ValueError(
            f'pose and force must have shape (n, 3) with n = len(t) = {n}, got '
            f'{poses.shape} and {forces.shape}'
        )
    if steps_ahead < 0:
        raise ValueError(f'steps_ahead must be >= 0, got {steps_ahead}')
    raw = np.array([estimator.update(float(times[k]), poses[k], forces[k]) for k in range(n)])
    if n == 0:
        return np.zeros((0, 3))
    out = np.empty((n, 3))
    out[:steps_ahead] = raw[0]
    out[steps_ahead:] = raw[: n - steps_ahead]
    return out


def _errors(estimate: FloatArray, truth: FloatArray, ndof: int) -> FloatArray:
    """Return estimate − truth on the first ndof columns, heading wrapped."""
    err = estimate[:, :ndof] - truth[:, :ndof]
    if ndof == 3:
        err[:, _YAW] = wrap_angle(err[:, _YAW])
    return err


def _continuous(series: FloatArray, ndof: int) -> FloatArray:
    """First ndof columns with the heading unwrapped."""
    out = series[:, :ndof].copy()
    if ndof == 3:
        out[:, _YAW] = np.unwrap(out[:, _YAW])
    return out


def band_power(
    x: FloatArray, sample_time: float, band: tuple[float, float]
) -> float:
    """Power of x within band [rad/s]: Welch PSD integrated over the band (trapezoid)."""
    n = x.size
    nperseg = min(n, max(16, int(round(WELCH_SEGMENT / sample_time))))
    freq, psd = signal.welch(x, fs=1.0 / sample_time, nperseg=nperseg, detrend='constant')
    omega = 2.0 * np.pi * freq  # [rad/s]
    inside = (omega >= band[0]) & (omega <= band[1])
    if np.count_nonzero(inside) < 2:
        return 0.0
    return float(np.trapezoid(psd[inside], freq[inside]))


def band_rms(x: FloatArray, sample_time: float, band: tuple[float, float]) -> float:
    """RMS of x within band [rad/s]: √ of `band_power`, plus the mean² when the band starts at 0.

    `band_power` detrends the mean; a band from 0 (a control band) must count a constant offset,
    which moves a DP loop's vessel as much as any slow error.
    """
    power = band_power(x, sample_time, band)
    if band[0] <= 0.0:
        power += float(np.mean(x)) ** 2
    return math.sqrt(power)


def estimate_lag(
    estimate: FloatArray, truth: FloatArray, sample_time: float, max_lag: float = DEFAULT_MAX_LAG
) -> float:
    """Delay [s] of estimate behind truth by windowed cross-correlation (positive = lags).

    With K = max shift in samples and g = truth[K : n−K], c[k] is the correlation coefficient
    of estimate[K+k : n−K+k] with g for k = −K..K; estimate[n] = truth[n − d] peaks at k = d.
    """
    n = estimate.size
    max_k = min(int(round(max_lag / sample_time)), (n - 3) // 4)
    if max_k < 1:
        return float('nan')
    g = truth[max_k : n - max_k]
    g = g - np.mean(g)
    width = g.size
    windows = np.lib.stride_tricks.sliding_window_view(estimate, width)  # (2K+1, width)
    sums = windows @ np.ones(width)
    centered_dot = windows @ g  # Σ e·g; the mean of e drops out because Σ g = 0
    energy = np.einsum('ij,ij->i', windows, windows) - sums**2 / width
    norm = np.sqrt(np.maximum(energy, 0.0) * float(g @ g))
    if not np.all(norm > 0.0):
        return float('nan')
    corr = centered_dot / norm
    peak = int(np.argmax(corr))
    shift = float(peak - max_k)
    if 0 < peak < corr.size - 1:
        left, mid, right = corr[peak - 1], corr[peak], corr[peak + 1]
        curvature = left - 2.0 * mid + right
        if curvature < 0.0:
            shift += 0.5 * (left - right) / curvature  # vertex of the parabola through 3 points
    return shift * sample_time


def score(
    t: ArrayLike,
    estimate: ArrayLike,
    truth: ArrayLike,
    ndof: int,
    wave_band: tuple[float, float] = DEFAULT_WAVE_BAND,
    *,
    max_lag: float = DEFAULT_MAX_LAG,
) -> Metrics:
    """Score an LF estimate (n, 3) against the true LF pose (n, 3) sampled at t (n,) [s]."""
    check_ndof(ndof)
    times = np.asarray(t, dtype=np.float64)
    est = np.asarray(estimate, dtype=np.float64)
    tru = np.asarray(truth, dtype=np.float64)
    n = times.size
    if n < 3 or est.shape != (n, 3) or tru.shape != (n, 3):
        raise ValueError(
            f'need t (n,) with n >= 3 and estimate, truth (n, 3); got {times.shape}, '
            f'{est.shape}, {tru.shape}'
        )
    steps = np.diff(times)
    if np.any(steps <= 0.0):
        raise ValueError('t must be strictly increasing')
    if not wave_band[0] < wave_band[1]:
        raise ValueError(f'wave_band must be (low, high) rad/s with low < high, got {wave_band}')
    sample_time = float(np.median(steps))
    err = _errors(est, tru, ndof)
    est_c, tru_c = _continuous(est, ndof), _continuous(tru, ndof)
    rate_err = (np.diff(est_c, axis=0) - np.diff(tru_c, axis=0)) / steps[:, None]
    return Metrics(
        ndof=ndof,
        samples=n,
        rmse=tuple(float(v) for v in np.sqrt(np.mean(err**2, axis=0))),
        derivative_rmse=tuple(float(v) for v in np.sqrt(np.mean(rate_err**2, axis=0))),
        wave_band_power=tuple(band_power(err[:, i], sample_time, wave_band) for i in range(ndof)),
        lag=tuple(
            estimate_lag(est_c[:, i], tru_c[:, i], sample_time, max_lag) for i in range(ndof)
        ),
        largest_step_ratio=tuple(_step_ratio(est_c[:, i], tru_c[:, i]) for i in range(ndof)),
    )


def _step_ratio(estimate: FloatArray, truth: FloatArray) -> float:
    """Largest |Δ estimate| over largest |Δ truth| of one DOF (module docstring)."""
    own = float(np.max(np.abs(np.diff(estimate))))
    true = float(np.max(np.abs(np.diff(truth))))
    if true > 0.0:
        return own / true
    return 0.0 if own == 0.0 else float('inf')


@dataclass(frozen=True)
class LoopRun:
    """One closed loop: true LF pose and applied thrust (n, 3) on a common time grid t (n,)."""

    t: FloatArray
    truth_lf_pose: FloatArray
    thrust: FloatArray


def loop_metrics(loop: LoopRun, ndof: int, setpoint: Sequence[float] | FloatArray,
                 wave_band: tuple[float, float], start: float) -> dict[str, Any]:
    """Station-keeping and thrust metrics of one loop over t ≥ start (module docstring)."""
    keep = loop.t >= start
    t, pose, thrust = loop.t[keep], loop.truth_lf_pose[keep], loop.thrust[keep]
    if t.size < 3:
        raise ValueError(f'a closed loop needs >= 3 samples after the warm-up ({start} s) to be '
                         f'scored, got {t.size}: run longer or shorten the warm-up')
    target = np.asarray(setpoint, dtype=np.float64)
    if target.ndim == 2:  # one setpoint per sample of the loop (a setpoint schedule)
        if target.shape != loop.truth_lf_pose.shape:
            raise ValueError(f'a per-sample setpoint must have the shape of the poses '
                             f'{loop.truth_lf_pose.shape}, got {target.shape}')
        target = target[keep]
    offset = pose - target
    horizontal = np.hypot(offset[:, 0], offset[:, 1]) if ndof == 3 else np.abs(offset[:, 0])
    sample_time = float(np.median(np.diff(t)))
    out: dict[str, Any] = {
        'samples': int(t.size),
        'position_rmse': float(np.sqrt(np.mean(horizontal**2))),
        'max_excursion': float(np.max(horizontal)),
        'thrust_wave_band_power': {
            DOF_NAMES[i]: band_power(thrust[:, i], sample_time, wave_band) for i in range(ndof)},
        'thrust_total_variation': {
            DOF_NAMES[i]: float(np.sum(np.abs(np.diff(thrust[:, i])))) for i in range(ndof)},
    }
    if ndof == 3:
        heading_error = np.angle(np.exp(1j * offset[:, _YAW]))  # wrapped to (−π, π]
        out['heading_rmse'] = float(np.sqrt(np.mean(heading_error**2)))
    return out


def format_table(results: dict[str, Metrics]) -> str:
    """Aligned text table, one row per estimator and DOF (units: m or rad, s)."""
    header = ('estimator', 'dof', 'rmse', 'rate rmse', 'wave power', 'lag [s]')
    rows = [header]
    for name, metrics in results.items():
        for i, dof in enumerate(DOF_NAMES[: metrics.ndof]):
            rows.append((
                name,
                dof,
                f'{metrics.rmse[i]:.4g}',
                f'{metrics.derivative_rmse[i]:.4g}',
                f'{metrics.wave_band_power[i]:.3e}',
                f'{metrics.lag[i]:.2f}',
            ))
    widths = [max(len(row[c]) for row in rows) for c in range(len(header))]
    lines = []
    for row in rows:
        cells = [row[0].ljust(widths[0]), row[1].ljust(widths[1])]
        cells += [cell.rjust(width) for cell, width in zip(row[2:], widths[2:], strict=True)]
        lines.append('  '.join(cells).rstrip())
    lines.insert(1, '-' * len(lines[0]))
    return '\n'.join(lines)
