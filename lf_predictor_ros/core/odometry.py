"""LF odometry: velocity, honest covariances and dead reckoning around the LF pose estimate.

What a DP stack needs besides the LF pose (issue 14): the LF velocity for the D term, how far to
trust both, and an estimate that survives a position-reference dropout. ``LfOdometry`` consumes
the LF pose the predictor publishes (any source: network or cascade fallback) and the applied
thrust, and gives an ``OdometryEstimate``:

- **pose**: the predictor's LF pose itself while tracking (``lf_odom`` and ``lf_pose`` agree);
- **twist**: the body-frame LF velocity ν = [u, v, r] of a Kalman filter on state [η, ν] whose
  measurement is the LF pose and whose process model is the learned vessel memory
  (``core.lf_dynamics``) when the data chose it, else constant velocity; its bandwidth is
  ``twist_bandwidth`` (a D term needs a timely velocity more than a smooth one);
- **covariances, calibrated empirically and state-dependent**: every retraining brings new
  zero-phase targets (an LF pose series of the past, thesis §4.2.2). The pose and twist actually
  published are compared with them (twist: with the targets' differentiated body velocity),
  separately for samples from the network and from the fallback (`core.error_models`, where
  the fits below live). Pose: the error of each DOF i
  is a holding part plus a lag part proportional to the LF rate w_i the odometry publishes (N/E:
  the earth-frame velocity R(ψ)[u, v], yaw: r), E[e_i²] = σ²_hold,i + T_i² w_i²; σ²_hold,i and
  T_i² are fitted by least squares of e_i² on w_i² over the window (with ``pose_lag_memory`` > 0
  w_i² is held at its recent peak, decaying over that time: errors outlast the motion that made
  them; 0: the current rate) (``fit_error_model``: T_i² ≥
  0, shrunk towards ``pose_lag_prior`` by the evidence the window has, σ²_hold,i ≥
  ``HOLD_FLOOR_FRACTION`` of the mean e_i²; T_i from every source of the window, which has more
  motion to fit it, σ²_hold,i per source). The published pose covariance is
  ``pose_cov_scale`` · (Σ_hold + ``pose_lag_scale`` · diag(T_i² w_i²)) with w the current
  twist (Σ_hold: the correlation of the mean e eᵀ with the σ²_hold diagonal; O(n²) per sample),
  plus, with ``pose_twin_gain`` > 0 (1 by default), that gain · diag(C ∘ max(0, m² − 2 L))
  outside the scale: m the motion gate twin's offset the gate left out of the output (what the
  holding network lags a move or a turn by), L its running level (``TWIN_LEVEL_TIME``), C per
  DOF the least-squares slope of e² on that excess against the targets (``pose_twin_fit``, on
  by default: 0 where the offset has not explained the error; off: C = 1). With
  ``pose_heading_speed_lag`` (3 DOF) the heading's lag part also adds K_ψ (w_N² + w_E²), the
  horizontal LF speed's share of the heading error (`fit_speed_gain`).
  Twist: the same model with the twist's change per second, low-passed over
  ``twist_accel_time``, as regressor (no prior), times ``twist_cov_scale``. The scales are
  calibrated on simulations against the truth (the targets are not the truth). Before the
  first targets, ``prior_pose_std`` and the Kalman filter's velocity covariance stand in and
  ``calibrated`` is False;
- **dead reckoning**: when poses stop or are rejected while thrust keeps coming (``coast``), the
  state is integrated with the dead reckoner ``dead_reckoner`` names (default: the one the vessel
  memory chose — learned model, constant velocity or hold) and the applied thrust, starting from
  the twist low-passed over ``dead_reckoning_velocity_time`` (a DP loop acts against the velocity
  it is shown, so a frozen wave-band twist would push the vessel away). The pose continues from the
  last published pose (no step); its covariance is the last tracking covariance + the drift
  variance measured by the vessel memory's own dead-reckoning tests at the elapsed time + the
  velocity uncertainty propagated (elapsed² · R Σ_ν Rᵀ); with ``dead_reckoning_excursion_std``
  k > 0 (2 by default) also k² times the square of the displacement the model dead-reckons
  since the dropout began, and the square of what the reckoner in use misses of it
  (`excursion_covariance`: the drift curve is learned holding station and is too small in a
  manoeuvre); with ``dead_reckoning_excursion_band`` > 0 (2 by default) that model is driven
  only by a DP controller's thrust beyond its station-keeping band (`band_excess`), and
  without a read DP controller there is no such term. After ``dead_reckoning_timeout`` nothing
  is published (mode 'lost'): no guesses;
- **reacquisition gated by plausibility**: a fix whose squared Mahalanobis distance to the
  dead-reckoned pose is within ``reacquire_gate`` is accepted at once; a fix far from it is
  accepted only after ``reacquire_time`` seconds of consecutive fixes (the position reference
  checks upstream reject inconsistent ones), meanwhile dead reckoning (or silence) continues.

Conventions: poses [north m, east m, heading rad] (heading wrapped in outputs, unwrapped inside),
forces and twists in ``base_link_fsd``. For ``ndof`` 1 only north/surge are estimated; the other
pose entries are passed through from the input and their variances are ``UNESTIMATED_VARIANCE``.
The settings named here are fields of `core.odometry_params.OdometryParams`.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass
import math
from typing import Literal, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lf_predictor_ros.core.error_models import Covariances, ErrorModel, calibrate
from lf_predictor_ros.core.filters import low_pass_step
from lf_predictor_ros.core.finite import all_finite
from lf_predictor_ros.core.heading import wrap_angle
from lf_predictor_ros.core.lf_dynamics import (
    DeadReckoner,
    LfDynamics,
    VesselMemory,
    balanced_at,
    dead_reckon_step,
    heading_basis,
)
from lf_predictor_ros.core.odometry_params import (
    MOVING_TWIST_CLAMP_DOFS,
    OdometryParams,
)
from lf_predictor_ros.core.published_columns import (
    SOURCES,
    EstimateSource,
    Published,
    PublishedColumns,
    PublishedLog,
)
from lf_predictor_ros.core.span_mean import SpanMean

FloatArray = NDArray[np.float64]
OdometryMode = Literal['tracking', 'dead_reckoning', 'lost']

# Variance published for a pose/twist entry that is not estimated (ndof 1: east, yaw) [m², rad²].
UNESTIMATED_VARIANCE = 1e6
# Correlation time assumed for the unmodelled LF acceleration in the Kalman process noise [s].
ACCELERATION_CORRELATION_TIME = 1.0
# Published samples kept for the covariance calibration (at most this many) [-].
HISTORY_SAMPLES = 20000
# `LfOdometry._embed`'s 3×3 before the estimated block is written in (read-only).
_EMBED_TEMPLATE = np.diag(np.full(3, UNESTIMATED_VARIANCE))
_EMBED_TEMPLATE.setflags(write=False)
# ``pose_twin_gain``: only the untaken twin offset's square in excess of this factor times its
# own running level counts; the level is m² low-passed over TWIN_LEVEL_TIME from the first
# calibrated estimate on. While the vessel holds station the twin's offset is its extra wave
# motion, and a vessel that always moves (threedof_open_loop) always has an offset: neither is
# a lag. Chosen on development seeds 101–102 from 2 and 4 (docs/BENCHMARKS.md, thirty-second
# session), the values of the twenty-fifth session's innovation excess.
TWIN_LEVEL_TIME = 600.0  # [s]
TWIN_LEVEL_FACTOR = 2.0  # [-]
# ``dead_reckoning_motion_balance``: a DOF is balanced against its motion only when its twist
# through one low-pass exceeds this many holding standard deviations of the twist (a two-sided
# 95 % test of "at rest") [-].
MOTION_BALANCE_SIGMAS = 2.0
# `excursion_covariance` takes displacements and twists up to this size per DOF (larger ones: an
# absurd, finite thrust the dead reckoning has followed), so that the covariance stays finite
# [m, m, rad; m/s, m/s, rad/s].
MAX_EXCURSION = 1e6
# ``dead_reckoning_excursion_band``: the time constant of the thrust's running mean and
# variance (first-order, per DOF) that the band is centred on and scaled by; a few LF periods
# of a DP loop, so that the variance holds the station-keeping thrust's own fluctuation [s].
EXCURSION_FORCE_TIME = 60.0
# Holding samples kept beyond dead_reckoning_holding_lead (dead_reckoning_holding_balance) [s].
HOLDING_MARGIN = 10.0


@dataclass(frozen=True)
class OdometryEstimate:
    """One LF odometry output (pose and twist with covariances; see the module docstring).

    Attributes:
        stamp: time the estimate is valid for [s].
        pose: [north m, east m, heading rad], heading wrapped to (−π, π].
        pose_cov: 3×3 covariance of pose [m², m·rad, rad²].
        twist: body velocity [u m/s, v m/s, r rad/s].
        twist_cov: 3×3 covariance of twist.
        mode: 'tracking' or 'dead_reckoning' ('lost' is never published).
        dead_reckoning_time: time since the last accepted fix [s] (0 while tracking).
        calibrated: the covariances come from a target comparison (False: priors).
        reckoner: the dead reckoner in use (``LfOdometry.reckoner``).
    """

    stamp: float
    pose: FloatArray
    pose_cov: FloatArray
    twist: FloatArray
    twist_cov: FloatArray
    mode: OdometryMode
    dead_reckoning_time: float
    calibrated: bool
    reckoner: DeadReckoner


class LfOdometry:
    """LF velocity, calibrated covariances and dead reckoning (see the module docstring)."""

    def __init__(self, ndof: int, sample_time: float, params: OdometryParams | None = None
                 ) -> None:
        """Create for ``ndof`` (1 or 3) at the predictor's sample time h [s]."""
        if ndof not in (1, 3):
            raise ValueError(f'ndof must be 1 or 3, got {ndof}')
        if not (math.isfinite(sample_time) and sample_time > 0.0):
            raise ValueError(f'sample_time must be positive, got {sample_time}')
        self.ndof = ndof
        self.sample_time = sample_time
        self.params = params or OdometryParams()
        self._wave_peak_freq: float | None = None  # [rad/s] dead_reckoning_twist_average_periods
        self.reset()

    # ---- public ---------------------------------------------------------------------------

    def reset(self) -> None:
        """Forget the state, the calibration and the vessel memory."""
        n = self.ndof
        self._memory: VesselMemory | None = None
        self._pose_cov: dict[str, ErrorModel] = {}
        self._twist_cov: dict[str, ErrorModel] = {}
        self._accel: tuple[float, FloatArray, FloatArray] | None = None  # (t, twist, accel)
        self._lag_peak: tuple[float, FloatArray] | None = None  # (t, held w²), pose_lag_memory
        self._twin_level: FloatArray | None = None  # running level of m² (pose_twin_gain)
        # the published history twice: the records for a calibration on this thread (no copy
        # to make), the same as columns for a job in the child (no packing on this thread)
        self._history: deque[Published] = deque(maxlen=HISTORY_SAMPLES)
        self._history_columns = PublishedLog(HISTORY_SAMPLES)
        # the published twist over dead_reckoning_twist_average_periods wave periods, and
        # (the 'extrapolated' start, dead_reckoning_moving_twist_clamp) over twice as many
        self._wave_twist = SpanMean(self.sample_time)
        self._wave_twist_double = SpanMean(self.sample_time)
        self._x: FloatArray | None = None
        self._p = np.zeros((2 * n, 2 * n))
        self._t: float | None = None
        self._mode: OdometryMode = 'tracking'
        self._last_fix: float | None = None
        self._last_output: OdometryEstimate | None = None
        self._dr_anchor: FloatArray | None = None  # published pose at the start of a DR
        self._dr_eta0: FloatArray | None = None
        self._pending_since: float | None = None
        self._blend: tuple[float, FloatArray] | None = None  # (start time, DR pose − fix)
        self._slow_twist: FloatArray | None = None  # low-passed twist, start of dead reckoning
        self._slow_force: FloatArray | None = None  # thrust low-passed per DOF (force time)
        # dead_reckoning_motion_balance: the twist through one low-pass (force time; the
        # thrust's is _slow_force), and [thrust, twist] through two; None until the first fix
        self._twist_once: FloatArray | None = None
        self._balance_twice: FloatArray | None = None
        # the memory's model balanced at the DR start, and the memory it was made from
        self._dr_model: tuple[VesselMemory, LfDynamics | None] | None = None
        # dead_reckoning_excursion_std: the model's own dead reckoning [η, ν] since the DR
        # started, beside a reckoner that is not the model (None: the option is off, there is
        # no model, or the reckoner is the model)
        self._dr_shadow: FloatArray | None = None
        # dead_reckoning_excursion_band: the thrust's running (mean, variance) while tracking
        # (EXCURSION_FORCE_TIME), and at the DR start (centre, half-width) of the band and the
        # model balanced at rest against the centre (None: no DP controller or no model)
        self._thrust_stats: tuple[FloatArray, FloatArray] | None = None
        self._dr_band: tuple[FloatArray, FloatArray, LfDynamics] | None = None
        # dead_reckoning_holding_balance: (t, low-passed thrust, heading [rad]) while holding
        # station, per group ('horizontal': earth-fixed [N, E] [N]; 'yaw' [N·m]; 1 DOF:
        # 'horizontal' surge)
        self._holding: dict[str, deque[tuple[float, FloatArray, float]]] = {
            'horizontal': deque(), 'yaw': deque()}
        self.counters = {'dead_reckoning_episodes': 0, 'lost': 0, 'reacquired': 0,
                         'reacquired_outside_gate': 0, 'fixes_held_back': 0, 'calibrations': 0,
                         'memory_updates': 0, 'numeric_failures': 0,
                         'implausible_thrust': 0, 'memories_kept': 0}
        # per-sample values that depend only on the parameters, the calibration, the memory
        # (and h): (the objects they were made from, the read-only value)
        self._r_cache: tuple[OdometryParams, dict[str, ErrorModel], FloatArray] | None = None
        self._q_cache: tuple[float, OdometryParams, dict[str, ErrorModel],
                             VesselMemory | None, FloatArray] | None = None
        self._beta_cache: tuple[OdometryParams, FloatArray] | None = None
        # (the twist calibration, twist_cov_scale, its holding std): see _holding_twist_std
        self._holding_std_cache: tuple[dict[str, ErrorModel], float, FloatArray] | None = None

    @property
    def mode(self) -> OdometryMode:
        """'tracking', 'dead_reckoning' or 'lost'."""
        return self._mode

    @property
    def memory(self) -> VesselMemory | None:
        """The vessel memory learned from the newest targets (None before the first)."""
        return self._memory

    @property
    def calibrated(self) -> bool:
        """True once the covariances come from a target comparison."""
        return bool(self._pose_cov)

    @property
    def wave_peak_freq(self) -> float | None:
        """The newest wave peak frequency ω0 [rad/s] the owner gave (None: none yet)."""
        return self._wave_peak_freq

    def set_wave_peak_freq(self, wave_peak_freq: float | None) -> None:
        """The newest ω0 estimate [rad/s] (``dead_reckoning_twist_average_periods``; None: none).

        Raises:
            ValueError: not None and not a finite number > 0.
        """
        if wave_peak_freq is not None and not (math.isfinite(wave_peak_freq) and
                                               wave_peak_freq > 0.0):
            raise ValueError('wave_peak_freq must be None or a finite frequency > 0 [rad/s], '
                             f'got {wave_peak_freq}')
        self._wave_peak_freq = None if wave_peak_freq is None else float(wave_peak_freq)

    def is_late(self, t: float) -> bool:
        """True if an estimate for t would be older than one already given (``track`` refuses)."""
        return self._t is not None and t <= self._t - 0.5 * self.sample_time

    def dead_reckoning_time(self, t: float) -> float:
        """Seconds since the last accepted fix (0 if tracking or never fixed)."""
        if self._mode == 'tracking' or self._last_fix is None:
            return 0.0
        return max(0.0, t - self._last_fix)

    def track(self, t: float, lf_pose: ArrayLike, force: ArrayLike,
              source: EstimateSource = 'network',
              twin_offset: ArrayLike | None = None) -> OdometryEstimate | None:
        """A new LF pose (valid at t) with the thrust applied; returns the estimate for t.

        While dead reckoning, a fix is first checked for plausibility (module docstring); a fix
        held back returns the dead-reckoned estimate (or None once lost). ``twin_offset``: the
        predictor's untaken twin offset m for this estimate (ndof; used with ``pose_twin_gain``
        > 0), None: no term.
        """
        pose = _vector(lf_pose, 3, 'lf_pose')
        tau = _vector(force, 3, 'force')
        if not math.isfinite(t):
            raise ValueError(f'stamp must be finite, got {t}')
        if source not in SOURCES:
            raise ValueError(f'source must be one of {SOURCES}, got {source!r}')
        if self.is_late(t):
            raise ValueError(f'stamp {t} is older than the last one {self._t}: restart() first')
        z = self._measurement(pose)
        offset = None if twin_offset is None else _vector(twin_offset, self.ndof, 'twin_offset')
        memory = self._memory  # the thrust clipped to what it has seen, once per sample
        clipped = tau if memory is None else memory.plausible_force(tau)
        if self._x is None:
            self._initialize(t, z)
        elif self._mode != 'tracking':
            if not self._accept_fix(t, z, tau):
                self.counters['fixes_held_back'] += 1
                return self.coast(t, force)
            self._start_blend(t, pose)
        else:
            self._predict_to(t, tau, clipped)
            self._correct(z)
        self._mode = 'tracking'
        self._last_fix = t
        self._pending_since = None
        self._dr_model = None
        self._dr_shadow = None
        self._dr_band = None
        x = self._require_state()
        twist = x[self.ndof:].copy()
        accel = self._twist_change(t, twist)
        lag = self._lag_regressor(t, z, twist)
        excess = None
        if offset is not None and self.params.pose_twin_gain > 0.0 and self.calibrated:
            excess = self._twin_excess(offset)
        record = Published(t, z.copy(), twist, source, accel, lag, excess)
        self._history.append(record)
        self._history_columns.append(record)
        span = self._wave_span()
        self._wave_twist.add(t, twist, span)
        self._wave_twist_double.add(
            t, twist, 2.0 * span if span is not None and self._uses_double_span() else None)
        alpha = min(1.0, self.sample_time / self.params.dead_reckoning_velocity_time)
        self._slow_twist = twist.copy() if self._slow_twist is None else \
            low_pass_step(self._slow_twist, twist, alpha)
        applied = clipped[:self.ndof]
        self._slow_force = applied.copy() if self._slow_force is None else \
            low_pass_step(self._slow_force, applied, self._force_rate())
        if self.params.dead_reckoning_motion_balance or self.params.dead_reckoning_moving_twist \
                or self.params.dead_reckoning_holding_balance:
            self._track_balance(twist)
        if self.params.dead_reckoning_excursion_band > 0.0:
            self._thrust_stats = thrust_statistics_step(
                self._thrust_stats, applied, min(1.0, self.sample_time / EXCURSION_FORCE_TIME))
        if self.params.dead_reckoning_holding_balance:
            self._track_holding(t, float(x[2]) if self.ndof == 3 else 0.0)
        published, pose_cov = self._blended(t, np.array(pose[:3], dtype=np.float64),
                                            self._pose_covariance(source, lag, excess))
        out = OdometryEstimate(
            stamp=t, pose=published, pose_cov=pose_cov, twist=self._full(twist),
            twist_cov=self._twist_covariance(source, accel), mode='tracking',
            dead_reckoning_time=0.0,
            calibrated=self.calibrated, reckoner=self.reckoner)
        out.pose[2] = wrap_angle(float(out.pose[2]))
        self._last_output = out
        return out

    def coast(self, t: float, force: ArrayLike) -> OdometryEstimate | None:
        """No (accepted) pose at t, thrust still applied: the dead-reckoned estimate, or None.

        None before the first fix and once ``dead_reckoning_timeout`` has passed since the last
        accepted fix (mode 'lost').
        """
        tau = _vector(force, 3, 'force')
        if not math.isfinite(t):
            raise ValueError(f'stamp must be finite, got {t}')
        if self._x is None or self._last_fix is None or self._last_output is None:
            return None
        if self._t is not None and t <= self._t:
            return self._last_output if self._mode == 'dead_reckoning' else None
        if self._mode == 'tracking':
            self._mode = 'dead_reckoning'
            self.counters['dead_reckoning_episodes'] += 1
            self._dr_anchor = self._last_output.pose.copy()
            self._dr_eta0 = self._require_state()[:self.ndof].copy()
            self._dr_cov0 = (self._last_output.pose_cov.copy(), self._last_output.twist_cov.copy())
            if self._slow_twist is not None and self._x is not None:
                self._x = np.concatenate([self._x[:self.ndof], self._start_twist(self._x)])
            self._dr_shadow = None
            self._dr_band = self._excess_band()
        elapsed = t - self._last_fix
        if elapsed > self.params.dead_reckoning_timeout:
            if self._mode != 'lost':
                self.counters['lost'] += 1
            self._mode = 'lost'
            self._dead_reckon_to(t, tau)
            return None
        self._dead_reckon_to(t, tau)
        out = self._dead_reckoned(t, elapsed)
        self._last_output = out
        return out

    def restart(self) -> None:
        """A new data segment (time jump, bag loop): keep the calibration and the memory."""
        memory, pose_cov, twist_cov = self._memory, self._pose_cov, self._twist_cov
        counters, twin_level = self.counters, self._twin_level
        self.reset()
        self._memory, self._pose_cov, self._twist_cov = memory, pose_cov, twist_cov
        self.counters, self._twin_level = counters, twin_level

    def learn(self, times: ArrayLike, targets: ArrayLike, memory: VesselMemory | None,
              wave_peak_freq: float | None = None,
              reference_filter: FloatArray | None = None) -> None:
        """New zero-phase targets (times [s] (m,), LF poses (m, ndof)) → calibrate covariances.

        ``memory`` is the vessel memory learned from the same window (``learn_vessel_memory``);
        None keeps the previous one. ``wave_peak_freq`` [rad/s] scales the reference cutoffs
        (``twist_reference_cutoff``, ``pose_reference_cutoff``; None: no ω0 yet, the targets as
        they are) and ``reference_filter`` is the SOS the targets were filtered with
        (``twist_attenuation``; None: none). The same as ``apply_learned(memory,
        calibrate(...))`` on this odometry's published history with every calibration setting
        of ``params`` (``LfStateEstimator`` runs `calibrate` on a worker).
        """
        params = self.params
        scale = 0.0 if wave_peak_freq is None else wave_peak_freq
        self.apply_learned(memory, calibrate(
            self.published(), times, targets, self.ndof, self.sample_time,
            params.min_calibration_samples, params.pose_lag_prior, params.pose_twin_fit,
            params.twist_reference_cutoff * scale, params.pose_reference_cutoff * scale,
            params.twist_likelihood_fit,
            reference_filter if params.twist_attenuation else None,
            params.pose_heading_speed_lag))

    def published(self) -> list[Published]:
        """A copy of the published history the covariances are calibrated on (oldest first)."""
        return list(self._history)

    def published_columns(self) -> PublishedColumns:
        """The published history as columns: a snapshot, taken without a copy (`PublishedLog`)."""
        return self._history_columns.columns()

    def apply_learned(self, memory: VesselMemory | None, covariances: Covariances | None) -> None:
        """Put a vessel memory and a calibration in use (None: keep the previous one).

        With ``dead_reckoning_keep_model`` a memory without a model keeps the one in use if
        that has a model (counted in ``memories_kept``).
        """
        if memory is not None and memory.model is None and self._memory is not None and \
                self._memory.model is not None and self.params.dead_reckoning_keep_model:
            self.counters['memories_kept'] += 1
        elif memory is not None:
            self._memory = memory
            self.counters['memory_updates'] += 1
        if covariances is not None:
            self._pose_cov, self._twist_cov = covariances
            self.counters['calibrations'] += 1

    # ---- Kalman filter -------------------------------------------------------------------

    def _initialize(self, t: float, z: FloatArray) -> None:
        n = self.ndof
        self._x = np.concatenate([z, np.zeros(n)])
        r = self._measurement_cov()
        q_vel = np.array(self.params.prior_accel_std[:n]) ** 2 * ACCELERATION_CORRELATION_TIME
        self._p = np.block([[r, np.zeros((n, n))],
                            [np.zeros((n, n)), np.diag(q_vel * 100.0)]])
        self._t = t

    def _force_rate(self) -> FloatArray:
        """Per-sample weight of the thrust low-pass (``dead_reckoning_force_time``; cached)."""
        params = self.params
        cached = self._beta_cache
        if cached is not None and cached[0] is params:
            return cached[1]
        times = np.array(params.dead_reckoning_force_time[:self.ndof])
        beta = np.where(times > 0.0, np.minimum(1.0, self.sample_time / np.maximum(times, 1e-9)),
                        1.0)
        beta.setflags(write=False)
        self._beta_cache = (params, beta)
        return beta

    def _plausible(self, tau: FloatArray, clipped: FloatArray | None = None) -> FloatArray:
        """The thrust clipped to what the vessel memory has seen (counted when clipped).

        ``clipped``: ``plausible_force(tau)`` of the memory in use, when already computed.
        """
        if self._memory is None:
            return tau
        if clipped is None:
            clipped = self._memory.plausible_force(tau)
        if clipped.shape != tau.shape or clipped.tolist() != tau.tolist():  # np.array_equal
            self.counters['implausible_thrust'] += 1
        return clipped

    def _predict_to(self, t: float, tau: FloatArray, clipped: FloatArray | None = None) -> None:
        tau = self._plausible(tau, clipped)
        x = self._require_state()
        t_last = self._t if self._t is not None else t
        steps = max(1, int(round((t - t_last) / self.sample_time)))
        h = (t - t_last) / steps if t > t_last else 0.0
        n = self.ndof
        start, p_start = x, self._p
        with np.errstate(over='ignore', invalid='ignore'):  # checked below
            for _ in range(steps):
                a, b = self._transition(x, tau[:n], h)
                x = a @ x + b
                self._p = a @ self._p @ a.T + self._process_noise(h)
        if not all_finite(x, self._p):
            self.counters['numeric_failures'] += 1  # absurd thrust: predict without it
            x, self._p = start, p_start + self._process_noise(t - t_last)
        self._x, self._t = x, t

    def _correct(self, z: FloatArray) -> None:
        x = self._require_state()
        n = self.ndof
        innovation = z - x[:n]
        if n == 3:
            innovation[2] = wrap_angle(float(innovation[2]))
        s = self._p[:n, :n] + self._measurement_cov()
        gain = np.linalg.solve(s, self._p[:n, :]).T
        self._x = x + gain @ innovation
        self._p = self._p - gain @ self._p[:n, :]
        self._p = 0.5 * (self._p + self._p.T)

    def _transition(self, x: FloatArray, tau: FloatArray, h: float) -> tuple[
            FloatArray, FloatArray]:
        n = self.ndof
        if not self._twist_uses_model():
            return _kinematic_transition(float(x[2]) if n == 3 else 0.0, h, n)
        rot = _rotation_block(float(x[2]) if n == 3 else 0.0, n)
        memory = self._memory
        damping = np.zeros((n, n))
        drive = np.zeros(n)
        if self._twist_uses_model():
            assert memory is not None and memory.model is not None
            model = memory.model
            damping = model.damping
            heading = float(x[2]) if n == 3 else 0.0
            drive = model.input_gain @ tau + model.bias @ heading_basis(heading, n)
        a = np.eye(2 * n)
        a[:n, n:] = h * rot
        a[n:, n:] += h * damping
        b = np.zeros(2 * n)
        b[n:] = h * drive
        return a, b

    def _twist_uses_model(self) -> bool:
        """The twist filter predicts with the memory's model (transition and process noise)."""
        memory = self._memory
        if memory is None or memory.model is None:
            return False
        return memory.reckoner == 'model' or (self.params.twist_model and bool(memory.known_gain))

    def _process_noise(self, h: float) -> FloatArray:
        """Q over a step of h [s] (cached per h, parameters, calibration and memory)."""
        cached = self._q_cache
        if cached is not None and cached[0] == h and cached[1] is self.params and \
                cached[2] is self._pose_cov and cached[3] is self._memory:
            return cached[4]
        q = self._new_process_noise(h)
        q.setflags(write=False)
        self._q_cache = (h, self.params, self._pose_cov, self._memory, q)
        return q

    def _new_process_noise(self, h: float) -> FloatArray:
        n = self.ndof
        memory = self._memory
        bandwidth = self.params.twist_bandwidth
        if bandwidth > 0.0:  # steady-state KF of a double integrator: ω_n = (q / r)^(1/4)
            accel_var = np.diag(self._measurement_cov()) * bandwidth ** 4
            q = np.zeros((2 * n, 2 * n))
            q[n:, n:] = np.diag(accel_var * h)
            return q
        if self._twist_uses_model():
            assert memory is not None and memory.model is not None
            accel_var = memory.model.residual_std ** 2 + 1e-12
        elif memory is not None:
            accel_var = memory.accel_std ** 2 + 1e-12
        else:
            accel_var = np.array(self.params.prior_accel_std[:n]) ** 2
        q = np.zeros((2 * n, 2 * n))
        q[n:, n:] = np.diag(accel_var * ACCELERATION_CORRELATION_TIME * h)
        return q

    def _measurement_cov(self) -> FloatArray:
        """R of the LF pose (cached per parameters and calibration; read-only)."""
        cached = self._r_cache
        if cached is not None and cached[0] is self.params and cached[1] is self._pose_cov:
            return cached[2]
        if 'all' in self._pose_cov:
            r = self._pose_cov['all'].moment + 1e-12 * np.eye(self.ndof)
        else:
            r = np.diag(np.array(self.params.prior_pose_std[:self.ndof]) ** 2)
        r.setflags(write=False)
        self._r_cache = (self.params, self._pose_cov, r)
        return r

    # ---- dead reckoning --------------------------------------------------------------------

    @property
    def reckoner(self) -> DeadReckoner:
        """The dead reckoner a dropout would use now (``dead_reckoner`` and the memory)."""
        memory = self._memory
        if memory is None:
            return 'constant_velocity'
        choice = self.params.dead_reckoner
        if choice == 'auto' and memory.known_gain and memory.model is not None:
            return 'model'  # the thrust gain is given or implied by the controller
        if choice == 'auto' or (choice == 'model' and memory.model is None):
            return memory.reckoner
        return cast(DeadReckoner, choice)

    def _balanced_model(self) -> LfDynamics | None:
        """The memory's model for a dead reckoning starting now (None: none).

        Under a DP controller (``memory.dp_controlled``) the LF thrust balances the environment,
        so the environment acting when the fixes stopped is the one the low-passed thrust held,
        not the window's mean (`lf_dynamics.balanced_at`, at rest: station keeping). Otherwise
        (an excited or open-loop vessel, whose thrust accelerates it) the fitted model: balanced
        there, the open-loop dead reckoning of threedof_open_loop drifted 18 m in 120 s instead
        of 6 m (tuning seeds, docs/BENCHMARKS.md).
        """
        memory = self._memory
        x = self._x
        if memory is None or memory.model is None:
            return None
        if not memory.dp_controlled or x is None or self._slow_force is None:
            return memory.model
        heading = float(x[2]) if self.ndof == 3 else 0.0
        times = np.array(self.params.dead_reckoning_force_time[:self.ndof])
        dofs = times > 0.0
        moving = self._moving_dofs(dofs) if self.params.dead_reckoning_motion_balance else None
        if moving is not None and self._twist_once is not None and \
                self._balance_twice is not None:
            n = self.ndof
            force, nu = self._balance_twice[:n], self._balance_twice[n:]
            # the second low-pass's derivative: (once − twice) / T, the twist change through
            # both low-passes, as the thrust and the twist went through them
            accel = (self._twist_once - nu) / np.where(dofs, times, 1.0)
            return balanced_at(memory.model, heading, np.where(moving, nu, 0.0),
                               np.where(moving, force, self._slow_force), dofs,
                               np.where(moving, accel, 0.0))
        force = self._slow_force
        if self.params.dead_reckoning_holding_balance:
            force = self._holding_force(heading, dofs)
        return balanced_at(memory.model, heading, np.zeros(self.ndof), force, dofs)

    def _excess_band(self) -> tuple[FloatArray, FloatArray, LfDynamics] | None:
        """At a DR start (``dead_reckoning_excursion_band``): centre, half-width, model; or None.

        None when the band is off, without a model, without a DP controller's thrust
        (``memory.dp_controlled``) or before the first fix. The centre is the thrust's running
        mean, the half-width the band × its running std, and the model the memory's, balanced
        at rest against the centre in every DOF (`lf_dynamics.balanced_at`): it does not move
        while the thrust stays in the band.
        """
        memory, x, stats = self._memory, self._x, self._thrust_stats
        if self.params.dead_reckoning_excursion_band <= 0.0 or memory is None or \
                memory.model is None or not memory.dp_controlled or stats is None or x is None:
            return None
        n = self.ndof
        mean, var = stats
        heading = float(x[2]) if n == 3 else 0.0
        model = balanced_at(memory.model, heading, np.zeros(n), mean)
        return (mean.copy(), self.params.dead_reckoning_excursion_band * np.sqrt(var),
                model)

    def _track_holding(self, t: float, heading: float) -> None:
        """Remember the low-passed thrust of the DOF groups that are holding station now.

        Each group keeps its holding samples of the last ``dead_reckoning_holding_lead`` +
        ``HOLDING_MARGIN`` seconds (`_holding_force` takes the one that lead before the newest);
        with ``dead_reckoning_holding_still`` a group's sample only while no DOF is moving.
        """
        assert self._slow_force is not None
        n = self.ndof
        moving = self._moving_dofs(np.ones(n, dtype=bool))
        force = self._slow_force
        groups = [('horizontal', 0, force[:1].copy() if n == 1 else
                   _rotation_block(heading, 3)[:2, :2] @ force[:2])]  # R(ψ) f
        if n == 3:
            groups.append(('yaw', 2, force[2:].copy()))
        keep = self.params.dead_reckoning_holding_lead + HOLDING_MARGIN
        still_only = self.params.dead_reckoning_holding_still
        for name, dof, value in groups:
            if moving is not None and (moving[dof] or still_only and bool(np.any(moving))):
                continue
            history = self._holding[name]
            history.append((t, value, heading))
            while history and history[0][0] < t - keep:
                history.popleft()

    def _holding_force(self, heading: float, dofs: NDArray[np.bool_]) -> FloatArray:
        """The thrust a dead reckoning balances: in the moving groups, the held one (new array).

        The held value is the newest holding sample at least ``dead_reckoning_holding_lead``
        seconds older than the group's newest (else its oldest); surge/sway turned from the
        earth frame into the body frame at ``heading``. A group whose heading has turned by more
        than ``dead_reckoning_holding_max_turn`` since that sample, or whose newest holding
        sample is more than ``dead_reckoning_holding_max_age`` seconds old, keeps the current
        thrust.
        """
        assert self._slow_force is not None
        n = self.ndof
        force = self._slow_force.copy()
        moving = self._moving_dofs(dofs)
        if moving is None:
            return force
        lead = self.params.dead_reckoning_holding_lead
        for name, dof in (('horizontal', 0), ('yaw', 2))[:1 if n == 1 else 2]:
            history = self._holding[name]
            if not moving[dof] or not history:
                continue
            newest = history[-1][0]
            max_age = self.params.dead_reckoning_holding_max_age
            if self._t is not None and self._t - newest > max_age:
                continue  # the move is no longer young: the current thrust
            _, held, then = history[0]
            for stamp, value, at in reversed(history):
                if stamp <= newest - lead:
                    held, then = value, at
                    break
            if abs(wrap_angle(heading - then)) > self.params.dead_reckoning_holding_max_turn:
                continue  # held against another environment: the current thrust
            if name == 'yaw':
                force[2] = held[0]
            elif n == 1:
                force[0] = held[0]
            else:
                force[:2] = _rotation_block(heading, 3)[:2, :2].T @ held  # R(ψ)ᵀ f
        return force

    def _moving_dofs(self, dofs: NDArray[np.bool_]) -> NDArray[np.bool_] | None:
        """The DOFs moving now (the motion balance's and the moving twist's gate), or None.

        A DOF is moving when its twist through one low-pass exceeds ``MOTION_BALANCE_SIGMAS``
        of the twist's holding standard deviation (the calibrated twist covariance without its
        acceleration part, which grows in a move: against the published std the gate stayed
        shut 20 s into one; before a calibration the published std), or with
        ``dead_reckoning_moving_gate`` > 0 when the current twist (the last published) exceeds
        that many and, with ``dead_reckoning_moving_gate_slow`` > 0, the low-passed twist that
        many (the move has begun), or with ``dead_reckoning_moving_gate_averaged`` > 0 when the
        twist averaged over whole wave periods exceeds that many; surge and sway go together
        (one earth-fixed force).
        Holding station the slow twist is mostly the estimate's own error, and balancing against
        it cost 3–10 % in dropouts (docs/BENCHMARKS.md, forty-eighth session); in a setpoint
        move the move's acceleration must not pass for environment.
        (Plain floats and bools: it runs at every sample, and holding station builds no array.)
        """
        if self._twist_once is None or self._last_output is None:
            return None
        n = self.ndof
        std = self._holding_twist_std().tolist()
        once = self._twist_once.tolist()
        moving = [abs(v) > MOTION_BALANCE_SIGMAS * s for v, s in zip(once, std, strict=True)]
        gate = self.params.dead_reckoning_moving_gate
        if gate > 0.0:  # the current twist, the last one published
            slow_gate = self.params.dead_reckoning_moving_gate_slow
            begun = [abs(v) > slow_gate * s for v, s in zip(once, std, strict=True)] \
                if slow_gate > 0.0 else [True] * n
            fast = _grouped([abs(v) > gate * s for v, s in zip(
                self._last_output.twist[:n].tolist(), std, strict=True)])
            moving = [m or (f and b) for m, f, b in zip(moving, fast, _grouped(begun),
                                                        strict=True)]
        averaged_gate = self.params.dead_reckoning_moving_gate_averaged
        averaged = self._wave_averaged_twist() if averaged_gate > 0.0 else None
        if averaged is not None:  # the twist over whole wave periods
            wide = _grouped([abs(v) > averaged_gate * s
                             for v, s in zip(averaged.tolist(), std, strict=True)])
            moving = [m or w for m, w in zip(moving, wide, strict=True)]
        moving = _grouped([m and bool(d) for m, d in zip(moving, dofs.tolist(), strict=True)])
        return np.array(moving, dtype=bool) if any(moving) else None

    def _holding_twist_std(self) -> FloatArray:
        """The twist's holding standard deviation per DOF (the motion gate's unit).

        The calibrated twist covariance without its acceleration part (it grows in a move);
        before a calibration the last published std.
        """
        assert self._last_output is not None
        n = self.ndof
        if not self._twist_cov:
            variance = np.diag(self._last_output.twist_cov)[:n]
            return np.sqrt(np.maximum(variance, 0.0))
        # the holding part (the published std grows with a move's rate): one number per
        # calibration and scale, computed once (read-only)
        scale, cached = self.params.twist_cov_scale, self._holding_std_cache
        if cached is not None and cached[0] is self._twist_cov and cached[1] == scale:
            return cached[2]
        model = self._twist_cov['all']
        std = np.sqrt(np.maximum(scale * np.diag(model.covariance(np.zeros(n), 1.0)), 0.0))
        std.setflags(write=False)
        self._holding_std_cache = (self._twist_cov, scale, std)
        return std

    def _uses_double_span(self) -> bool:
        """Whether the average over twice the span is kept (extrapolated start, the clamp)."""
        start = self.params.dead_reckoning_moving_twist_start
        return start == 'extrapolated' or \
            (start == 'current' and self.params.dead_reckoning_moving_twist_clamp > 0.0)

    def _clamped_current(self, current: FloatArray) -> FloatArray:
        """``dead_reckoning_moving_twist_clamp``: the current twist kept near the averages.

        Within k holding std of the span between the wave-averaged twist mean(T) and its
        extrapolation 2 mean(T) − mean(2T) (on a ramp the current twist lies between or on
        them, so an accelerating move keeps its start); the average alone while mean(2T) is
        unknown; unchanged while the average is, and in the DOFs outside
        ``dead_reckoning_moving_twist_clamp_dofs`` (a new array either way).
        """
        clamp = self.params.dead_reckoning_moving_twist_clamp
        one = self._wave_averaged_twist() if clamp > 0.0 else None
        if one is None:
            return current.copy()
        two = self._wave_twist_double.mean()
        ahead = one if two is None else 2.0 * one - two
        margin = clamp * self._holding_twist_std()
        clamped = np.clip(current, np.minimum(one, ahead) - margin,
                          np.maximum(one, ahead) + margin)
        dofs = MOVING_TWIST_CLAMP_DOFS[self.params.dead_reckoning_moving_twist_clamp_dofs]
        return np.where(np.array(dofs[:self.ndof]), clamped, current)

    def _start_twist(self, state: FloatArray) -> FloatArray:
        """The twist a dead reckoning starts from (a new array).

        The low-passed twist; with ``dead_reckoning_moving_twist`` the current one of ``state``
        in the DOFs that are moving (`_moving_dofs`; kept near the wave-averaged one with
        ``dead_reckoning_moving_twist_clamp``, `_clamped_current`), or the wave-averaged one
        (``dead_reckoning_moving_twist_start``, `_averaged_start`).
        """
        assert self._slow_twist is not None
        n = self.ndof
        moving = self._moving_dofs(np.ones(n, dtype=bool)) \
            if self.params.dead_reckoning_moving_twist else None
        if moving is None:
            return self._slow_twist.copy()
        averaged = self._averaged_start()
        current = self._clamped_current(state[n:]) if averaged is None else averaged
        return np.where(moving, current, self._slow_twist)

    def _averaged_start(self) -> FloatArray | None:
        """The wave-averaged start twist of ``dead_reckoning_moving_twist_start`` (None: current).

        'extrapolated': 2 mean(T) − mean(2T), the mean over the last span T carried over its
        lag of T/2 by the slope between the last two spans ((mean(T) − mean(T before)) / T ·
        T/2, with mean(T before) = 2 mean(2T) − mean(T)).
        """
        choice = self.params.dead_reckoning_moving_twist_start
        if choice == 'current':
            return None
        one = self._wave_averaged_twist()
        if choice == 'average' or one is None:
            return one
        two = self._wave_twist_double.mean()
        return None if two is None else 2.0 * one - two

    def _wave_span(self) -> float | None:
        """``dead_reckoning_twist_average_periods`` · 2π/ω0 [s] (None: off or no ω0 yet)."""
        periods = self.params.dead_reckoning_twist_average_periods
        freq = self._wave_peak_freq
        if periods <= 0.0 or freq is None:
            return None
        return periods * 2.0 * math.pi / freq

    def _wave_averaged_twist(self) -> FloatArray | None:
        """The published twist's mean over ``dead_reckoning_twist_average_periods`` · 2π/ω0.

        The boxcar over the samples stamped within that span of the newest (`SpanMean`; one
        period of ω0 has a zero there). None: the option is off, no ω0 is known, or the
        published twists since the last reset do not reach back over the whole span.
        """
        return self._wave_twist.mean()

    def _track_balance(self, twist: FloatArray) -> None:
        """The twist through one low-pass (the motion gate); with the balance, two passes.

        With ``dead_reckoning_motion_balance``, [thrust, twist] also go through a second pass.

        For a linear model ν̇ = F ν + G τ + b with b constant, the same linear filter on both
        sides keeps the equation: LP(ν̇) = F LP(ν) + G LP(τ) + b. With a first-order low-pass
        of time constant T applied twice, LP₂(ν̇) = d/dt LP₂(ν) = (LP₁(ν) − LP₂(ν)) / T, so b
        follows from filtered quantities only, whatever the vessel was doing (a setpoint move's
        acceleration included); the second pass keeps the wave-band twist out of the rate.
        The thrust's first pass is ``_slow_force``, updated before this call.
        """
        assert self._slow_force is not None  # set by track() just before
        rate = self._force_rate()
        self._twist_once = twist.copy() if self._twist_once is None else \
            low_pass_step(self._twist_once, twist, rate)
        if not self.params.dead_reckoning_motion_balance:
            return  # the moving twist's gate needs the first pass only
        once = np.concatenate([self._slow_force, self._twist_once])
        self._balance_twice = once if self._balance_twice is None else \
            low_pass_step(self._balance_twice, once, np.concatenate([rate, rate]))

    def _dead_reckon_to(self, t: float, tau: FloatArray) -> None:
        tau = self._plausible(tau)
        x = self._require_state()
        t_last = self._t if self._t is not None else t
        steps = max(1, int(round((t - t_last) / self.sample_time)))
        h = (t - t_last) / steps
        n = self.ndof
        memory = self._memory
        if memory is not None and (self._dr_model is None or self._dr_model[0] is not memory):
            self._dr_model = (memory, self._balanced_model())  # a new memory: balanced anew
        model = None if self._dr_model is None else self._dr_model[1]
        eta, nu = x[:n], x[n:]
        reckoner = self.reckoner
        # the model's own dead reckoning beside another reckoner, or (the band) its answer to
        # the thrust beyond the station-keeping band: the displacement the excursion term scales
        band = self._dr_band  # None unless the band is on and a DP controller was read
        band_off = self.params.dead_reckoning_excursion_band <= 0.0
        shadow = None
        if self.params.dead_reckoning_excursion_std > 0.0 and (
                band is not None or band_off and model is not None and reckoner != 'model'):
            shadow = x.copy() if self._dr_shadow is None else self._dr_shadow
        shadow_model, shadow_force = (model, tau[:n]) if band is None else \
            (band[2], band_excess(tau[:n], band[0], band[1]))
        with np.errstate(over='ignore', invalid='ignore'):  # checked below
            for _ in range(steps):
                a, _b = self._transition(x, tau[:n], h)
                self._p = a @ self._p @ a.T + self._process_noise(h)
                eta, nu = dead_reckon_step(model, reckoner, eta, nu, tau[:n], h)
                if shadow is not None:
                    shadow = np.concatenate(dead_reckon_step(shadow_model, 'model', shadow[:n],
                                                             shadow[n:], shadow_force, h))
        if not all_finite(eta, nu):
            # an absurd (finite) thrust overflowed the model: hold the last finite pose
            self.counters['numeric_failures'] += 1
            eta, nu = x[:n], np.zeros(n)
        self._x, self._t = np.concatenate([eta, nu]), t
        self._dr_shadow = shadow if shadow is not None and all_finite(shadow) else None

    def _dead_reckoned(self, t: float, elapsed: float) -> OdometryEstimate:
        n = self.ndof
        x = self._require_state()
        anchor = self._dr_anchor if self._dr_anchor is not None else np.zeros(3)
        eta0 = self._dr_eta0 if self._dr_eta0 is not None else x[:n]
        pose = anchor.copy()
        pose[:n] = anchor[:n] + (x[:n] - eta0)
        if n == 3:
            pose[2] = wrap_angle(float(pose[2]))
        pose_cov0, twist_cov0 = self._dr_cov0
        pose_cov = pose_cov0.copy()
        twist_cov = twist_cov0.copy()
        memory = self._memory
        reckoner = self.reckoner
        if memory is not None and memory.curve(reckoner).starts > 0:
            drift = memory.curve(reckoner)
            pose_cov[:n, :n] += np.diag(drift.variance(elapsed))
            twist_cov[:n, :n] += np.diag(drift.velocity_variance(elapsed))
            if reckoner != 'hold':
                rot = _rotation_block(float(x[2]) if n == 3 else 0.0, n)
                pose_cov[:n, :n] += elapsed ** 2 * rot @ twist_cov0[:n, :n] @ rot.T
        else:  # no vessel memory yet: the constant-velocity Kalman propagation
            pose_cov[:n, :n] = np.maximum(pose_cov[:n, :n], self._p[:n, :n])
            twist_cov[:n, :n] = np.maximum(twist_cov[:n, :n], self._p[n:, n:])
        band_off = self.params.dead_reckoning_excursion_band <= 0.0
        if self.params.dead_reckoning_excursion_std > 0.0 and (
                band_off or self._dr_shadow is not None):
            # the model's dead reckoning: the state itself unless another reckoner is in use
            # (the band: always the shadow; none without a DP controller, no term)
            modelled = x if self._dr_shadow is None else self._dr_shadow
            pose_part, twist_part = excursion_covariance(
                x[:n] - eta0, modelled[:n] - eta0, x[n:], modelled[n:],
                self.params.dead_reckoning_excursion_std)
            pose_cov[:n, :n] += pose_part
            twist_cov[:n, :n] += twist_part
        twist = self._full(x[n:])
        return OdometryEstimate(stamp=t, pose=pose, pose_cov=pose_cov, twist=twist,
                                twist_cov=twist_cov, mode='dead_reckoning',
                                dead_reckoning_time=elapsed, calibrated=self.calibrated,
                                reckoner=reckoner)

    def _start_blend(self, t: float, pose: FloatArray) -> None:
        """Reacquired: remember how far the dead-reckoned pose is from the new estimate."""
        last = self._last_output
        if last is None or self.params.reacquire_blend_time <= 0.0 or last.mode == 'tracking':
            self._blend = None
            return
        offset = last.pose - pose[:3]
        offset[2] = wrap_angle(float(offset[2]))
        offset[self.ndof:] = 0.0
        self._blend = (t, offset)

    def _blended(self, t: float, pose: FloatArray, cov: FloatArray) -> tuple[
            FloatArray, FloatArray]:
        """Pose + the fading reacquisition offset (smoothstep weight).

        The offset's square is added to the variance while it lasts.
        """
        if self._blend is None:
            return pose, cov
        start, offset = self._blend
        phase = (t - start) / self.params.reacquire_blend_time
        if phase >= 1.0:
            self._blend = None
            return pose, cov
        weight = 1.0 - (3.0 * phase ** 2 - 2.0 * phase ** 3) if phase > 0.0 else 1.0
        shifted = weight * offset
        return pose + shifted, cov + np.diag(shifted ** 2)

    def _accept_fix(self, t: float, z: FloatArray, tau: FloatArray) -> bool:
        n = self.ndof
        self.coast(t, tau)  # bring the dead-reckoned state to t
        x = self._require_state()
        innovation = z - x[:n]
        if n == 3:
            innovation[2] = wrap_angle(float(innovation[2]))
        out = self._last_output
        cov = (out.pose_cov[:n, :n] if out is not None and self._mode == 'dead_reckoning'
               else self._p[:n, :n]) + self._measurement_cov()
        distance = float(innovation @ np.linalg.solve(cov, innovation))
        if self._pending_since is None:
            self._pending_since = t
        inside = distance <= self.params.reacquire_gate
        consistent = t - self._pending_since >= self.params.reacquire_time
        if not (inside or consistent):
            return False
        self.counters['reacquired'] += 1
        if not inside:
            self.counters['reacquired_outside_gate'] += 1
        # restart the filter at the fix, keeping the dead-reckoned velocity and its uncertainty
        p_vel = self._p[n:, n:].copy()
        self._x = np.concatenate([z, x[n:]])
        self._p = np.block([[self._measurement_cov(), np.zeros((n, n))],
                            [np.zeros((n, n)), p_vel]])
        self._t = t
        return True

    # ---- covariance calibration ------------------------------------------------------------

    def _lag_regressor(self, t: float, pose: FloatArray, twist: FloatArray) -> FloatArray:
        """The pose error model's regressor at the published pose and twist (ndof each).

        The LF rates w: for 3 DOF the earth-frame velocity R(ψ) [u, v] [m/s] and the yaw rate r
        [rad/s], for 1 DOF u; with ``pose_lag_memory`` T > 0 the square held at its peak,
        decaying by exp(−Δt / T) (O(n)).
        """
        if self.ndof == 3:  # plain floats: one sample, without the array overhead
            c, s = math.cos(float(pose[2])), math.sin(float(pose[2]))
            u, v = float(twist[0]), float(twist[1])
            rates = np.array([c * u - s * v, s * u + c * v, float(twist[2])])
        else:
            rates = twist.copy()
        memory = self.params.pose_lag_memory
        if memory <= 0.0:
            return rates
        square = rates * rates
        last = self._lag_peak
        if last is not None and t > last[0]:
            square = np.maximum(square, last[1] * math.exp(-(t - last[0]) / memory))
        self._lag_peak = (t, square)
        return np.asarray(np.sqrt(square), dtype=np.float64)

    def _pose_covariance(self, source: EstimateSource, lag: FloatArray,
                         twin_excess: FloatArray | None = None) -> FloatArray:
        """The pose error model of ``source`` at the regressor ``lag`` (`_lag_regressor`).

        Plus ``pose_twin_gain`` · diag(C ∘ x), x = ``twin_excess`` (`_twin_excess`), C = 1 or,
        with ``pose_twin_fit``, the model's fitted ``twin_gain`` (none fitted: 0).
        """
        n = self.ndof
        if self._pose_cov:
            model = self._pose_cov.get(source, self._pose_cov['all'])
            inner = self.params.pose_cov_scale * model.covariance(lag, self.params.pose_lag_scale)
            if twin_excess is not None:
                added = self.params.pose_twin_gain * twin_excess
                if self.params.pose_twin_fit:
                    added = added * (0.0 if model.twin_gain is None else model.twin_gain)
                inner.flat[::n + 1] += added
        else:
            inner = np.diag(np.array(self.params.prior_pose_std[:n]) ** 2)
        return self._embed(inner)

    def _twin_excess(self, twin_offset: FloatArray) -> FloatArray:
        """max(0, m² − TWIN_LEVEL_FACTOR · L) per DOF, then L ← LP(L, m²) (one sample).

        L starts at the first m² (that sample adds nothing).
        """
        square = twin_offset * twin_offset
        level = self._twin_level
        if level is None:
            self._twin_level = square.copy()
            return np.zeros_like(square)
        excess = np.maximum(square - TWIN_LEVEL_FACTOR * level, 0.0)
        self._twin_level = low_pass_step(level, square,
                                         min(1.0, self.sample_time / TWIN_LEVEL_TIME))
        return excess

    def _twist_change(self, t: float, twist: FloatArray) -> FloatArray:
        """The twist's change per second low-passed over ``twist_accel_time`` (O(n))."""
        last = self._accel
        if last is None or t <= last[0]:
            accel = np.zeros(self.ndof) if last is None else last[2]
        else:
            dt = t - last[0]
            alpha = min(1.0, dt / self.params.twist_accel_time)
            rate = [(b - c) / dt for b, c in zip(twist.tolist(), last[1].tolist(), strict=True)]
            accel = low_pass_step(last[2], rate, alpha)
        self._accel = (t, twist, accel)
        return accel

    def _twist_covariance(self, source: EstimateSource, accel: FloatArray) -> FloatArray:
        n = self.ndof
        if self._twist_cov:
            model = self._twist_cov.get(source, self._twist_cov['all'])
            inner = self.params.twist_cov_scale * model.covariance(accel, 1.0)
        else:
            inner = self._p[n:, n:].copy()
        return self._embed(inner)

    # ---- helpers ---------------------------------------------------------------------------

    def _embed(self, inner: FloatArray) -> FloatArray:
        full = _EMBED_TEMPLATE.copy()
        n = self.ndof
        full[:n, :n] = inner
        return full

    def _full(self, values: FloatArray) -> FloatArray:
        full = np.zeros(3)
        full[:self.ndof] = values
        return full

    def _measurement(self, pose: FloatArray) -> FloatArray:
        """The LF pose as a state measurement: ndof entries, heading unwrapped near the state."""
        z = np.array(pose[:self.ndof], dtype=np.float64)
        if self.ndof == 3 and self._x is not None:
            z[2] = float(self._x[2]) + wrap_angle(float(z[2] - self._x[2]))
        return z

    def _require_state(self) -> FloatArray:
        if self._x is None:
            raise RuntimeError('LfOdometry has no state yet: call track() first')
        return self._x


def thrust_statistics_step(stats: tuple[FloatArray, FloatArray] | None, force: ArrayLike,
                           weight: float) -> tuple[FloatArray, FloatArray]:
    """One step of the thrust's exponentially weighted running mean and variance; new arrays.

    ``stats`` (mean, variance) per DOF, None: the first sample (its mean, variance 0);
    ``weight`` in (0, 1] the new sample's weight. With d = f − mean: mean + w d and
    (1 − w)(variance + w d²), the incremental form of the weighted variance (Finch 2009,
    "Incremental calculation of weighted mean and variance", §9). A sample that would make
    them non-finite (an absurd thrust) leaves them as they were (a finite absurd one widens
    the band until it decays: the excursion term then adds nothing, the covariance of k = 0).
    """
    f = np.asarray(force, dtype=np.float64).tolist()  # plain floats: on the tracking path
    if stats is None:
        finite = all(math.isfinite(v) for v in f)
        return np.array(f if finite else [0.0] * len(f)), np.zeros(len(f))
    mean, var = stats[0].tolist(), stats[1].tolist()
    new_var = [(1.0 - weight) * (v + weight * (x - m) * (x - m))
               for m, v, x in zip(mean, var, f, strict=True)]
    new_mean = low_pass_step(mean, f, weight)  # mean + w d
    if not (all(math.isfinite(v) for v in new_var) and
            all(math.isfinite(v) for v in new_mean.tolist())):
        return np.array(mean), np.array(var)
    return new_mean, np.array(new_var)


def band_excess(force: ArrayLike, centre: ArrayLike, half_width: ArrayLike) -> FloatArray:
    """The centre plus the part of ``force`` − ``centre`` beyond ± ``half_width`` (per DOF).

    A dead zone: a force inside the band gives the centre, one outside it the centre plus its
    distance beyond the band's edge (continuous). New array; the inputs are not modified.
    """
    f = np.asarray(force, dtype=np.float64)
    c = np.asarray(centre, dtype=np.float64)
    d = f - c
    beyond = np.maximum(np.abs(d) - np.asarray(half_width, dtype=np.float64), 0.0)
    out: FloatArray = c + np.sign(d) * beyond
    return out


def excursion_covariance(displacement: ArrayLike, model_displacement: ArrayLike,
                         twist: ArrayLike, model_twist: ArrayLike, relative_std: float
                         ) -> tuple[FloatArray, FloatArray]:
    """The dead reckoning's manoeuvre covariance (``dead_reckoning_excursion_std``).

    ``displacement`` and ``model_displacement``: the pose change since the dropout began of the
    reckoner in use and of the memory's model (n,) [m, m, rad]; ``twist``, ``model_twist``:
    their body-frame twists (n,). The model is believed to within ``relative_std`` of what it
    dead-reckons (its thrust gain and damping come from station keeping, which hardly excites
    them): k² |d_NE|² on north and east alike (rotation invariant) and k² d_ψ² on heading; what
    the reckoner in use misses of the model's displacement, m = d_reckoner − d_model, is a known
    offset and adds m mᵀ. The same for the twist. Returns (pose part, twist part), each (n, n),
    positive semi-definite; both are 0 for a reckoner that is the model and does not move.
    Entries beyond ``MAX_EXCURSION`` count as that much (the covariance stays finite).
    """
    parts = []
    for own, model in ((displacement, model_displacement), (twist, model_twist)):
        d = np.clip(np.asarray(model, dtype=np.float64), -MAX_EXCURSION, MAX_EXCURSION)
        miss = np.clip(np.asarray(own, dtype=np.float64), -MAX_EXCURSION, MAX_EXCURSION) - d
        spread = relative_std ** 2 * d ** 2
        if d.size == 3:
            spread[:2] = relative_std ** 2 * float(d[0] ** 2 + d[1] ** 2)
        parts.append(np.outer(miss, miss) + np.diag(spread))
    return parts[0], parts[1]


def _kinematic_transition(heading: float, h: float, ndof: int) -> tuple[FloatArray, FloatArray]:
    """`LfOdometry._transition` without the memory's model: (A, 0), A = [[I, h R], [0, I]].

    The entries h·R(ψ) as ``h * _rotation_block(ψ)`` computes them (h ≥ 0: its zeros are +0).
    """
    a = np.eye(2 * ndof)
    if ndof == 1:
        a[0, 1] = h * 1.0
    else:
        c, s = math.cos(heading), math.sin(heading)
        a[0, 3], a[0, 4] = h * c, h * -s
        a[1, 3], a[1, 4] = h * s, h * c
        a[0, 5] = a[1, 5] = a[2, 3] = a[2, 4] = h * 0.0
        a[2, 5] = h * 1.0
    return a, np.zeros(2 * ndof)


def _grouped(flags: list[bool]) -> list[bool]:
    """Per DOF flags with surge and sway joined (3 DOF: either one sets both; a new list).

    Surge and sway share one earth-fixed environment force, so they move or rest together.
    """
    if len(flags) == 3:
        both = flags[0] or flags[1]
        return [both, both, flags[2]]
    return list(flags)


def _rotation_block(heading: float, ndof: int) -> FloatArray:
    """R(ψ) of the planar pose (Fossen 2011 eq. 2.18, 3 DOF); 1 DOF: [[1]]."""
    if ndof == 1:
        return np.eye(1)
    c, s = math.cos(heading), math.sin(heading)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _vector(values: ArrayLike, size: int, name: str) -> FloatArray:
    array = np.asarray(values, dtype=np.float64)
    if array.shape != (size,) or not all_finite(array):
        raise ValueError(f'{name} must be a finite array of shape ({size},), got {array!r}')
    return array
