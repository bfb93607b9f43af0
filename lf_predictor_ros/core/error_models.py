"""Error models of the LF odometry: its pose and twist errors against the targets (issue 14).

The covariances `core.odometry.LfOdometry` publishes are calibrated empirically: every retraining
brings new zero-phase targets (an LF pose series of the past, thesis §4.2.2), and the pose and
twist actually published are compared with them (`calibrate`). The error of each DOF is a
holding part plus a part that grows with a regressor w (pose: the LF rate; twist: its low-passed
change per second), E[e eᵀ] = Σ_hold + diag(T² w²) (`ErrorModel`, fitted by `fit_error_model`
or `fit_error_model_likelihood`), with the motion gate's untaken twin offset
(`fit_twin_gain`) and the horizontal speed's share of the heading error (`fit_speed_gain`) as
options; `reference_velocity`, `low_passed` and `attenuated_variance` make the calibration's
reference, `normalized_error_squared` is the consistency test (NEES). What each term means and
which parameter switches it: `core.odometry`'s module docstring and `OdometryParams`.

Pure functions of numpy arrays (they run on a worker or in the child process).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import signal

from lf_predictor_ros.core.filters import frequency_response, zero_phase
from lf_predictor_ros.core.finite import all_finite
from lf_predictor_ros.core.heading import wrap_angle
from lf_predictor_ros.core.lf_dynamics import body_velocity
from lf_predictor_ros.core.published_columns import SOURCES, Published

FloatArray = NDArray[np.float64]
# (pose error model, twist error model) per source ('network', 'fallback', 'all')
Covariances = tuple[dict[str, 'ErrorModel'], dict[str, 'ErrorModel']]
# The holding variance σ²_hold of the pose error model is at least this fraction of the mean
# squared error of the window [-] (a lag fit must not claim that a still vessel is exact; on the
# tuning seeds 0.05–0.5 change the calibrated NEES by < 10 %).
HOLD_FLOOR_FRACTION = 0.1
# ``pose_reference_cutoff``, ``twist_reference_cutoff``: Butterworth order of the zero-phase
# low-pass on the calibration reference (forward and backward: the magnitude response squared).
REFERENCE_LOW_PASS_ORDER = 4
# ``twist_attenuation``: frequencies where the targets' zero-phase filter keeps less than this
# share of the power are left out of the attenuated variance (there the reference holds too
# little of the LF motion to say what was taken; the ×(1 − G)/G correction is at most 4).
ATTENUATION_MIN_POWER = 0.2  # [-]


@dataclass(frozen=True)
class ErrorModel:
    """Pose or twist error of one source against the targets (see the module docstring).

    E[e eᵀ] = hold + diag(gain ∘ w²) for the regressor w: for the pose the LF rates of
    `LfOdometry._lag_regressor`, for the twist the low-passed change of the twist
    ``twist_accel_time``.

    Attributes:
        moment: mean e eᵀ over the window, ndof × ndof (pose [m², m·rad, rad²]: the Kalman
            filter's measurement covariance; twist [m²/s², m·rad/s², rad²/s²]).
        hold: holding part Σ_hold, ndof × ndof (the correlation of ``moment``, diagonal σ²_hold).
        gain: T_i² per DOF [s²]: variance added per squared regressor w_i² (pose: N/E
            earth-frame velocity [m/s], yaw rate [rad/s]; twist: acceleration [m/s², rad/s²]).
        twin_gain: C_i per DOF (pose, ``pose_twin_fit``): variance added per unit of the
            untaken twin offset's excess (`fit_twin_gain`); None: not fitted.
        speed_gain: K_ψ [rad²·s²/m²] (3-DOF pose, ``pose_heading_speed_lag``): heading
            variance added per squared horizontal LF speed w_N² + w_E²; 0: none.
    """

    moment: FloatArray
    hold: FloatArray
    gain: FloatArray
    twin_gain: FloatArray | None = None
    speed_gain: float = 0.0

    def covariance(self, rates: FloatArray, lag_scale: float) -> FloatArray:
        """Σ_hold + lag_scale · diag(T_i² w_i²), + K_ψ (w_N² + w_E²) on the heading.

        For the regressor w (ndof,); the heading term (not scaled by ``lag_scale``) only with
        3 DOF and ``speed_gain`` > 0.
        """
        cov = self.hold.copy()
        cov.flat[::cov.shape[0] + 1] += lag_scale * self.gain * rates * rates
        if self.speed_gain > 0.0 and cov.shape[0] == 3:
            speed2 = float(rates[0]) ** 2 + float(rates[1]) ** 2
            cov[2, 2] += self.speed_gain * speed2
        return cov


def calibrate(history: Sequence[Published], times: ArrayLike, targets: ArrayLike, ndof: int,
              sample_time: float, min_samples: int, lag_prior: float = 0.0,
              twin_fit: bool = False, twist_cutoff: float = 0.0, pose_cutoff: float = 0.0,
              twist_likelihood: bool = False,
              reference_filter: FloatArray | None = None,
              heading_speed: bool = False) -> Covariances | None:
    """Pose error models and twist covariances against the targets (module docstring).

    Every published estimate whose stamp is a target instant (not the first or last) is
    compared with the target and with the targets' differentiated body velocity (with
    ``twist_cutoff`` > 0 [rad/s] low-passed below it, `reference_velocity`; the pose with
    ``pose_cutoff`` > 0 [rad/s] against the targets low-passed below it, `low_passed`; with
    ``twist_likelihood`` the twist model by `fit_error_model_likelihood`; with
    ``reference_filter``, the SOS of the zero-phase filter that made the targets, and
    ``twist_cutoff`` > 0, every twist model's holding part adds `attenuated_variance` below
    ``twist_cutoff``): per source
    ('network', 'fallback': only with ``min_samples`` matches) and over all, the pose error
    model (`fit_error_model` on each estimate's regressor ``Published.lag``, prior lag time
    ``lag_prior`` [s]) and the twist error's second moment (bias included); with ``twin_fit``
    also the untaken twin offset's coefficient C of every DOF (`fit_twin_gain` on the matches
    that carry ``Published.twin_excess``, pooled over the sources); with ``heading_speed``
    (3 DOF) the heading's speed term K_ψ (`fit_error_model`), from every source like T_i.
    None when nothing matches. Pure: runs on a worker.
    """
    stamps = np.asarray(times, dtype=np.float64)
    values = np.array(targets, dtype=np.float64).reshape(stamps.shape[0], -1)
    if values.shape[1] != ndof or values.shape[0] < 3 or not all_finite(values, stamps):
        raise ValueError(f'targets must be finite with shape (m >= 3, {ndof}), got '
                         f'{values.shape}')
    if not history:
        return None
    velocity = reference_velocity(values, sample_time, twist_cutoff)
    pub_t = np.array([p.stamp for p in history])
    index = np.round((pub_t - stamps[0]) / sample_time).astype(np.int64)
    ok = (index >= 1) & (index < stamps.shape[0] - 1)
    ok &= np.abs(stamps[np.clip(index, 0, stamps.shape[0] - 1)] - pub_t) < 0.5 * sample_time
    if not np.any(ok):
        return None
    rows = [p for p, good in zip(history, ok, strict=True) if good]
    idx = index[ok]
    pose_err = np.array([p.pose for p in rows]) - low_passed(values, sample_time, pose_cutoff)[idx]
    if ndof == 3:
        pose_err[:, 2] = wrap_angle(pose_err[:, 2])
    twists = np.array([p.twist for p in rows])
    twist_err = twists - velocity[idx]
    rates = np.array([p.lag for p in rows])
    sources = np.array([p.source for p in rows])
    pooled = fit_error_model(pose_err, rates, lag_prior, heading_speed=heading_speed)
    if twin_fit:
        with_excess = [k for k, p in enumerate(rows) if p.twin_excess is not None]
        excess = np.array([rows[k].twin_excess for k in with_excess]).reshape(-1, ndof)
        pooled = replace(pooled, twin_gain=fit_twin_gain(pose_err[with_excess], excess,
                                                         min_samples))
    pose_cov: dict[str, ErrorModel] = {'all': pooled}
    accel = np.array([p.accel for p in rows])
    fit_twist = fit_error_model_likelihood if twist_likelihood else fit_error_model
    twist_cov: dict[str, ErrorModel] = {'all': fit_twist(twist_err, accel)}
    for source in SOURCES:
        mask = sources == source
        if np.count_nonzero(mask) >= min_samples:
            # the lag time from every source (more motion to fit it), the holding part per source
            pose_cov[source] = replace(
                fit_error_model(pose_err[mask], rates[mask], gain=pooled.gain,
                                heading_speed=heading_speed, speed_gain=pooled.speed_gain),
                twin_gain=pooled.twin_gain)
            twist_cov[source] = fit_twist(twist_err[mask], accel[mask])
    if reference_filter is not None and twist_cutoff > 0.0:
        taken = np.diag(attenuated_variance(body_velocity(values, sample_time), sample_time,
                                            reference_filter, twist_cutoff))
        twist_cov = {key: replace(model, hold=model.hold + taken)
                     for key, model in twist_cov.items()}
    return pose_cov, twist_cov


def attenuated_variance(velocity: ArrayLike, sample_time: float, reference_filter: FloatArray,
                        edge: float) -> FloatArray:
    """Variance per column of what a zero-phase filter took from a series below ``edge`` [rad/s].

    ``velocity`` (m, n) is the filtered series (the targets' LF velocity), ``reference_filter``
    the SOS applied forward and backward (power response G = |H|², `filters.frequency_response`).
    Where G < 1 the filter removed (1 − G) X of the true content X, and the series holds G X, so
    the removed part is (1 − G)/G times the series' content. Its mean square, over the
    frequencies below ``edge`` with G ≥ ``ATTENUATION_MIN_POWER``, from the series minus its
    least-squares line, Hann-windowed (the window's power divided out). (n,) zeros for fewer
    than 16 samples. The input is not modified.
    """
    values = np.array(velocity, dtype=np.float64)
    if values.ndim != 2 or not np.all(np.isfinite(values)):
        raise ValueError(f'velocity must be a finite (m, n) array, got shape {values.shape}')
    if not (math.isfinite(edge) and edge >= 0.0):
        raise ValueError(f'edge must be a finite number >= 0 rad/s, got {edge}')
    m = values.shape[0]
    if m < 16:
        return np.zeros(values.shape[1])
    steps = np.arange(m, dtype=np.float64)
    design = np.column_stack([np.ones_like(steps), steps])
    detrended = values - design @ np.linalg.lstsq(design, values, rcond=None)[0]
    window = np.hanning(m)
    omega = 2.0 * np.pi * np.fft.rfftfreq(m, sample_time)  # [rad/s]
    power = np.abs(frequency_response(reference_filter, omega, sample_time)) ** 2
    kept = (omega < edge) & (power >= ATTENUATION_MIN_POWER)
    factor = np.where(kept, (1.0 - np.minimum(power, 1.0)) / np.maximum(power, 1e-12), 0.0)
    taken = np.fft.irfft(np.fft.rfft(detrended * window[:, None], axis=0) * factor[:, None],
                         n=m, axis=0)
    return np.asarray(np.mean(taken ** 2, axis=0) / np.mean(window ** 2), dtype=np.float64)


def reference_velocity(targets: ArrayLike, sample_time: float, cutoff: float = 0.0
                       ) -> FloatArray:
    """The targets' LF body velocity (`body_velocity`), low-passed below ``cutoff`` [rad/s].

    The twist calibration's reference (``OdometryParams.twist_reference_cutoff``): the zero-phase
    targets keep some wave motion, which differentiation amplifies by ω; the twist filter does
    not share it, so against the raw velocity the twist looks worse than it is, by a share that
    depends on the vessel and the sea. The low-pass is `low_passed` (zero-phase: the reference
    may look ahead). ``cutoff`` 0, or at or above the Nyquist frequency: the velocity as it is.
    The input is not modified.
    """
    return low_passed(body_velocity(targets, sample_time), sample_time, cutoff)


def low_passed(series: ArrayLike, sample_time: float, cutoff: float) -> FloatArray:
    """A series (m, n) low-passed below ``cutoff`` [rad/s], zero-phase (a new array).

    Butterworth of order ``REFERENCE_LOW_PASS_ORDER``, forward and backward (`filters.zero_phase`),
    on the series minus its least-squares line per column, the line added back: a zero-phase
    low-pass keeps a line, and without the detrend Gustafsson's initial conditions err by up to
    0.8 m at the ends of a 0.3 m/s ramp (test_odometry.py); ``cutoff`` 0, or at or above the
    Nyquist frequency: a copy of the series as it is. The calibration references of
    ``pose_reference_cutoff`` and ``twist_reference_cutoff``.
    """
    values = np.array(series, dtype=np.float64)
    if not (math.isfinite(cutoff) and cutoff >= 0.0):
        raise ValueError(f'cutoff must be a finite number >= 0 rad/s (0: no low-pass), got '
                         f'{cutoff}')
    normalized = cutoff * sample_time / math.pi  # × the Nyquist frequency
    if cutoff == 0.0 or normalized >= 1.0 or values.shape[0] < 2:
        return values
    sos = signal.butter(REFERENCE_LOW_PASS_ORDER, normalized, btype='low', output='sos')
    steps = np.arange(values.shape[0], dtype=np.float64)
    design = np.column_stack([np.ones_like(steps), steps])
    coef = np.linalg.lstsq(design, values, rcond=None)[0]
    line = design @ coef
    return np.asarray(zero_phase(values - line, np.asarray(sos, dtype=np.float64)) + line,
                      dtype=np.float64)


def fit_error_model(errors: ArrayLike, rates: ArrayLike, lag_prior: float = 0.0,
                    gain: FloatArray | None = None, heading_speed: bool = False,
                    speed_gain: float | None = None) -> ErrorModel:
    """Fit E[e_i²] = σ²_hold,i + T_i² w_i² per DOF (module docstring); errors, regressor (m, n).

    T_i² = the least-squares slope of e_i² on w_i² (clipped at 0), shrunk towards the prior
    T₀² = ``lag_prior``² with a prior standard deviation of T₀²: the slope's own variance is
    2 σ⁴_hold / Σ (w_i² − mean)² (Gaussian errors), so a window without motion (w² constant)
    gives the prior and a window with motion its own fit. σ²_hold,i = mean e_i² − T_i² mean w_i²,
    at least ``HOLD_FLOOR_FRACTION`` · mean e_i². Σ_hold keeps the correlations of the mean e eᵀ.
    A given ``gain`` (T_i² [s²], e.g. fitted on every source) is used as it is: only σ²_hold is
    fitted. With ``heading_speed`` and 3 DOF the heading also gets K_ψ (`fit_speed_gain`;
    a given ``speed_gain`` is used as it is) and its σ²_hold nets out K_ψ · mean (w_N² + w_E²).
    """
    e = np.asarray(errors, dtype=np.float64)
    w = np.asarray(rates, dtype=np.float64)
    if e.ndim != 2 or w.shape != e.shape or e.shape[0] < 1:
        raise ValueError(f'errors and rates must be (m >= 1, n), got {e.shape} and {w.shape}')
    moment = _second_moment(e)
    e2, w2 = e ** 2, w ** 2
    mean_e2, mean_w2 = e2.mean(axis=0), w2.mean(axis=0)
    dw2 = w2 - mean_w2
    sxx = np.sum(dw2 ** 2, axis=0)
    sxy = np.sum(dw2 * (e2 - mean_e2), axis=0)
    prior = lag_prior ** 2
    n = e.shape[1]
    given = gain is not None
    gains = np.zeros(n) if gain is None else np.array(gain, dtype=np.float64).reshape(n)
    hold = np.zeros(n)
    for i in range(n):
        floor = HOLD_FLOOR_FRACTION * float(mean_e2[i])
        if not given:
            gains[i] = _lag_gain(float(sxx[i]), float(sxy[i]), float(mean_e2[i]),
                                 float(mean_w2[i]), floor, prior,
                                 still=bool(sxx[i] <= 1e-12 * e.shape[0] *
                                            float(np.mean(w2[:, i] ** 2))))
        hold[i] = max(float(mean_e2[i]) - gains[i] * float(mean_w2[i]), floor)
    speed = 0.0
    if heading_speed and n == 3:
        speed2 = w2[:, 0] + w2[:, 1]
        left = e2[:, 2] - gains[2] * w2[:, 2]  # what the yaw-rate model leaves of e_ψ²
        speed = fit_speed_gain(left, speed2) if speed_gain is None else float(speed_gain)
        hold[2] = max(float(np.mean(left)) - speed * float(np.mean(speed2)),
                      HOLD_FLOOR_FRACTION * float(mean_e2[2]))
    return ErrorModel(moment=moment, hold=_hold_matrix(moment, hold), gain=gains,
                      speed_gain=speed)


def fit_speed_gain(left: ArrayLike, speed2: ArrayLike) -> float:
    """K_ψ ≥ 0: the least-squares slope of ``left`` (m,) on ``speed2`` (m,), clipped at 0.

    ``left``: the squared heading error less the yaw-rate lag part T_ψ² r² [rad²]; ``speed2``:
    the squared horizontal LF speed w_N² + w_E² [m²/s²]. No spread of ``speed2`` (a window
    without a move): 0. `_lag_gain` without a prior, as `fit_error_model` fits T_i². The inputs
    are not modified.
    """
    y = np.asarray(left, dtype=np.float64)
    x = np.asarray(speed2, dtype=np.float64)
    if y.ndim != 1 or x.shape != y.shape:
        raise ValueError(f'left and speed2 must be (m,) arrays of one length, got {y.shape} '
                         f'and {x.shape}')
    if y.shape[0] < 2:
        return 0.0
    dx = x - float(np.mean(x))
    sxx = float(np.sum(dx * dx))
    sxy = float(np.sum(dx * (y - float(np.mean(y)))))
    still = sxx <= 1e-12 * y.shape[0] * float(np.mean(x * x))
    return _lag_gain(sxx, sxy, float(np.mean(y)), float(np.mean(x)), 0.0, 0.0, still=still)


def _hold_matrix(moment: FloatArray, hold: FloatArray) -> FloatArray:
    """Σ_hold: the correlations of the mean e eᵀ ``moment`` with the variances ``hold``."""
    diag = np.sqrt(np.diag(moment))
    with np.errstate(divide='ignore', invalid='ignore'):
        corr = np.where(np.outer(diag, diag) > 0.0, moment / np.outer(diag, diag), 0.0)
    np.fill_diagonal(corr, 1.0)
    std = np.sqrt(hold)
    return np.asarray(corr * np.outer(std, std), dtype=np.float64)


LIKELIHOOD_ITERATIONS = 50  # most reweightings of `fit_error_model_likelihood` [-]
LIKELIHOOD_TOLERANCE = 1e-9  # relative change of σ² that ends them [-]


def fit_error_model_likelihood(errors: ArrayLike, rates: ArrayLike) -> ErrorModel:
    """`fit_error_model` (no prior) refined to the Gaussian maximum likelihood per DOF.

    σ²_i(w) = σ²_hold,i + T_i² w_i² maximizes Σ −log σ² − e²/σ² over the window: iteratively
    reweighted least squares of e² on [1, w²] with weights 1/σ⁴ (Var e² = 2σ⁴), whose fixed
    point solves the likelihood's score equations, so the window's mean e²/σ² is 1 wherever
    the constraints (T² ≥ 0, σ²_hold ≥ ``HOLD_FLOOR_FRACTION`` · mean e²) do not bind. Starts
    from the least-squares fit; Σ_hold keeps the correlations of the mean e eᵀ. The inputs are
    not modified.
    """
    base = fit_error_model(errors, rates)
    e2 = np.asarray(errors, dtype=np.float64) ** 2
    w2 = np.asarray(rates, dtype=np.float64) ** 2
    n = e2.shape[1]
    hold = np.diag(base.hold).copy()
    gain = base.gain.copy()
    for i in range(n):
        floor = HOLD_FLOOR_FRACTION * float(np.mean(e2[:, i]))
        hold[i], gain[i] = _likelihood_refit(e2[:, i], w2[:, i], float(hold[i]),
                                             float(gain[i]), floor)
    return ErrorModel(moment=base.moment, hold=_hold_matrix(base.moment, hold), gain=gain)


def _likelihood_refit(e2: FloatArray, x: FloatArray, hold: float, gain: float,
                      floor: float) -> tuple[float, float]:
    """(σ²_hold, T²) of one DOF: weighted least squares of e² on [1, x], weights 1/σ⁴, repeated."""
    if floor <= 0.0:
        return hold, gain
    for _ in range(LIKELIHOOD_ITERATIONS):
        sigma2 = hold + gain * x
        w = 1.0 / (sigma2 * sigma2)
        sw, swx, swxx = float(np.sum(w)), float(np.sum(w * x)), float(np.sum(w * x * x))
        swy, swxy = float(np.sum(w * e2)), float(np.sum(w * x * e2))
        det = sw * swxx - swx * swx
        new_gain = (sw * swxy - swx * swy) / det if det > 1e-12 * sw * swxx else 0.0
        new_hold = (swy - new_gain * swx) / sw
        if new_gain < 0.0:  # the constraint T² ≥ 0 binds
            new_gain, new_hold = 0.0, swy / sw
        if new_hold < floor:  # the floor binds: T² alone
            new_hold = floor
            new_gain = max(0.0, float(np.sum(w * x * (e2 - floor))) / swxx) if swxx > 0.0 \
                else 0.0
        change = abs(new_hold - hold) / hold + (abs(new_gain - gain) / gain if gain > 0 else
                                                 abs(new_gain) * float(np.max(x)) / hold)
        hold, gain = new_hold, new_gain
        if change < LIKELIHOOD_TOLERANCE:
            break
    return hold, gain


def fit_twin_gain(errors: ArrayLike, excess: ArrayLike, min_samples: int) -> FloatArray:
    """C_i per DOF: the least-squares slope of e_i² on the twin offset's excess x_i, ≥ 0.

    errors and excess (m, n) of the same estimates (e against the calibration reference, x from
    `LfOdometry._twin_excess`): `fit_error_model`'s clipped slope with no prior, the excess as
    its squared regressor. A DOF with fewer than ``min_samples`` samples of x_i > 0 gets 0: no
    evidence that the untaken offset explains its error (``pose_twin_fit``).
    """
    e = np.asarray(errors, dtype=np.float64)
    x = np.asarray(excess, dtype=np.float64)
    if e.ndim != 2 or x.shape != e.shape:
        raise ValueError(f'errors and excess must have the same shape (m, n), got {e.shape} '
                         f'and {x.shape}')
    if e.shape[0] == 0:
        return np.zeros(e.shape[1])
    gains = fit_error_model(e, np.sqrt(np.maximum(x, 0.0))).gain
    return np.where(np.count_nonzero(x > 0.0, axis=0) >= min_samples, gains, 0.0)


def _lag_gain(sxx: float, sxy: float, mean_e2: float, mean_w2: float, floor: float,
              prior: float, still: bool) -> float:
    """T² of one DOF: the clipped least-squares slope shrunk towards ``prior`` (fit_error_model).

    ``still``: no motion to fit (w² constant up to rounding): the prior.
    """
    slope = 0.0 if still else max(sxy / sxx, 0.0)
    if prior <= 0.0:
        return slope
    if still:
        return prior
    hold_ref = max(mean_e2 - slope * mean_w2, floor)
    if hold_ref <= 0.0:  # error-free window: the fit is exact
        return slope
    # precision of the slope, Σ (w² − mean)² / (2 σ⁴_hold) (Gaussian errors), against the
    # prior's 1 / T₀⁴ (standard deviation of T² equal to T₀²)
    weight = sxx / (2.0 * hold_ref ** 2) * prior ** 2
    return (weight * slope + prior) / (weight + 1.0)


def normalized_error_squared(error: ArrayLike, covariance: ArrayLike) -> FloatArray:
    """NEES eᵀ P⁻¹ e of each row: error (m, n), covariance (m, n, n) → (m,)."""
    e = np.asarray(error, dtype=np.float64)
    p = np.asarray(covariance, dtype=np.float64)
    if e.ndim != 2 or p.shape != (e.shape[0], e.shape[1], e.shape[1]):
        raise ValueError(f'error must be (m, n) and covariance (m, n, n), got {e.shape} and '
                         f'{p.shape}')
    return np.asarray(np.einsum('ij,ij->i', e, np.linalg.solve(p, e[..., None])[..., 0]),
                      dtype=np.float64)


def _second_moment(errors: FloatArray) -> FloatArray:
    """Mean of e eᵀ (bias included: a biased estimate must not look confident)."""
    return np.asarray(errors.T @ errors / errors.shape[0], dtype=np.float64)
