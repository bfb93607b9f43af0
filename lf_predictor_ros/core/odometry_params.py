"""Settings of the LF odometry (`core.odometry.LfOdometry`, `core.lf_state.LfStateEstimator`).

One frozen, validated dataclass, as `core.params.PredictorParams` is for the predictor: every
field carries its documentation and unit (`core.field_meta.field_doc`), which the nodes declare
as ROS parameters and `config/predictor.yaml` and the README list. What the settings do: the
module docstring of `core.odometry`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math

from lf_predictor_ros.core.controller_gains import STIFFNESS_FRAMES
from lf_predictor_ros.core.field_meta import field_doc
from lf_predictor_ros.core.lf_dynamics import DEAD_RECKONERS, FORCE_MARGIN, check_force_margin

# ``reacquire_gate``'s default: the χ²(3) 99.9 % quantile [-].
CHI2_3DOF_999 = 16.27  # χ²(3) 99.9 % quantile [-]
# ``dead_reckoning_moving_twist_start``: the twist a moving DOF's dead reckoning starts from.
MOVING_TWIST_STARTS = ('current', 'average', 'extrapolated')
# ``dead_reckoning_moving_twist_clamp_dofs``: the DOFs (surge, sway, yaw) the clamp acts on.
MOVING_TWIST_CLAMP_DOFS: dict[str, tuple[bool, bool, bool]] = {
    'horizontal': (True, True, False), 'all': (True, True, True)}
# ``dead_reckoning_damping_memory``: the DOFs (surge, sway, yaw) whose damping rate the vessel
# memory keeps across windows, per choice.
DAMPING_MEMORY_DOFS: dict[str, tuple[bool, bool, bool]] = {
    'off': (False, False, False), 'yaw': (False, False, True), 'all': (True, True, True)}
# ``controller_read_fitted_damping_dofs``: the DOFs (surge, sway, yaw) whose read inertia
# ``controller_read_fitted_damping`` corrects, per choice.
FITTED_DAMPING_DOFS: dict[str, tuple[bool, bool, bool]] = {
    'yaw': (False, False, True), 'all': (True, True, True)}

# The settings that must be finite numbers >= 0, with what their message adds after ">= 0" (the
# unit and what 0 means), in the order they are checked.
NON_NEGATIVE: tuple[tuple[str, str], ...] = (
    ('pose_lag_scale', ''),
    ('pose_lag_memory', ' s (0: no memory)'),
    ('pose_lag_prior', ' s'),
    ('pose_twin_gain', ' (0: off)'),
    ('pose_reference_cutoff', ' (× ω0; 0: the targets as they are)'),
    ('twist_reference_cutoff', ' (× ω0; 0: the reference velocity as it is)'),
    ('dead_reckoning_moving_gate', ' (holding std; 0: off)'),
    ('dead_reckoning_moving_gate_slow',
     ' (holding std of the low-passed twist; 0: the current twist alone)'),
    ('dead_reckoning_twist_average_periods', ' (wave periods; 0: none)'),
    ('dead_reckoning_moving_twist_clamp', ' (holding std; 0: off)'),
    ('dead_reckoning_moving_gate_averaged', ' (holding std; 0: off)'),
    ('dead_reckoning_excursion_std', ' (a fraction of the dead-reckoned displacement; 0: off)'),
    ('dead_reckoning_excursion_band', ' (thrust stds; 0: the whole thrust)'),
    ('reacquire_time', ' s'),
    ('reacquire_blend_time', ' s'),
    ('twist_bandwidth', " rad/s (0: process noise from the targets' LF acceleration)"),
    ('dead_reckoning_holding_lead', ' s'),
    ('controller_read_block_time', ' [s] (0: one pooled read)'),
)


@dataclass(frozen=True)
class OdometryParams:
    """Settings of the LF odometry (see the module docstring)."""

    dead_reckoning_timeout: float = field(default=120.0, metadata=field_doc(
        'longest dead reckoning through a pose dropout; afterwards lf_odom/lf_pose stop', 's'))
    pose_cov_scale: float = field(default=0.60, metadata=field_doc(
        'published pose covariance = this × (Σ_hold + pose_lag_scale · diag(T_i² w_i²)), the '
        'pose error model fitted against the targets (calibrated against the truth on the '
        'calibration seeds 1, 2 and 231–236 of four vessels so that the geometric mean of the '
        'per-DOF mean NEES is 1: 0.599; on tuning seeds 1–2 alone it was 0.50, and put 10 of 32 '
        'development runs inside their NEES bounds against 18 now; docs/BENCHMARKS.md '
        '"State-dependent covariance" and "Twenty-fifth session", issue 14)', ''))
    pose_lag_scale: float = field(default=8.0, metadata=field_doc(
        'the lag part T_i² w_i² of the pose error model (fitted against the targets) is '
        'multiplied by this inside pose_cov_scale (the errors against the targets show less lag '
        'than against the truth; chosen on tuning seeds 1–2 where the spread of the per-DOF NEES '
        'stops falling, docs/BENCHMARKS.md "State-dependent covariance")', ''))
    pose_lag_memory: float = field(default=0.0, metadata=field_doc(
        'the lag part of the pose error model grows with the largest recent LF rate, not only '
        'the current one: w_i² is held at its peak and decays by exp(−Δt / this time) (errors '
        'outlast the motion that made them: the settling after a turn or a setpoint move); '
        '0 = the current rate (issue 14)', 's'))
    pose_lag_prior: float = field(default=1.2, metadata=field_doc(
        'lag time T assumed for every DOF where a calibration window has no motion to fit it '
        '(prior of the least-squares fit, with a standard deviation of T² equal to T²; '
        '0 = no prior)', 's'))
    pose_twin_gain: float = field(default=1.0, metadata=field_doc(
        'with the motion gate: the published pose covariance adds this × diag(max(0, m² − '
        "2 L)) (× C_i with pose_twin_fit), outside pose_cov_scale, m the part of the moving "
        "twin's offset the gate left "
        'out of the output ((1 − g) · LP(twin − holding), '
        'AdaptivePredictor.untaken_twin_offset: the holding filter lags a move or a turn that '
        'the twin follows, so m is what the estimate probably lags by, against the truth), L '
        'the running level of m² (TWIN_LEVEL_TIME); 0 = off (issue 14; 1 with pose_twin_fit '
        'since the thirty-third session: docs/BENCHMARKS.md)', ''))
    pose_twin_fit: bool = field(default=True, metadata=field_doc(
        'with pose_twin_gain > 0: the term is pose_twin_gain · C_i · max(0, m_i² − 2 L_i) with '
        'C_i fitted per DOF at every calibration against the reference (the least-squares slope '
        'of the squared pose error on that excess, clipped at 0; 0 while the window has fewer '
        'than min_calibration_samples samples with an excess): the term acts only on a vessel '
        "and DOF where the twin's untaken offset has explained the error (false: C_i = 1; "
        'adopted on fresh development seeds 373–380, runs inside their pose NEES bounds 16 → '
        '19 of 32, docs/BENCHMARKS.md "Thirty-third session")', ''))
    pose_heading_speed_lag: bool = field(default=False, metadata=field_doc(
        "3 DOF: the heading's lag part also grows with the horizontal LF speed, E[e_ψ²] = "
        'σ²_hold + T_ψ² r² + K_ψ (w_N² + w_E²), K_ψ the clipped least-squares slope of what the '
        "yaw-rate model leaves of e_ψ² on the squared speed, fitted with T_ψ at every "
        "calibration: the heading row of the network reads every regressor, so a setpoint move "
        "moves its heading too (docs/BENCHMARKS.md, forty-fifth session: on rao_supply seed 755 "
        'most of the heading NEES came from a 15 m north move); inside pose_cov_scale, not '
        'pose_lag_scale (on development seeds 755–758 × 8 made the heading too cautious: '
        'rao_supply heading NEES 1.73 → 0.49, × 1: 1.11, docs/BENCHMARKS.md forty-sixth '
        'session); off by default: on fresh seeds 787–794 it brought rao_supply to 1.06 but made '
        "threedof_open_loop's heading too cautious (NEES 0.73 → 0.37); false: the yaw rate "
        'alone', ''))
    twist_cov_scale: float = field(default=0.61, metadata=field_doc(
        'published twist covariance = this × (holding part + K² a²) of the twist error model '
        'fitted against the target velocity (a: the twist change, twist_accel_time; '
        'calibrated as pose_cov_scale on tuning seeds 1–2; the eight calibration seeds give '
        '0.68, which the DDS consistency test on the supply vessel refuses: docs/BENCHMARKS.md '
        '"Twenty-fifth session")', ''))
    pose_reference_cutoff: float = field(default=0.0, metadata=field_doc(
        'the pose error models (and the twin term, pose_twin_fit) are fitted against the '
        'targets low-passed (zero-phase Butterworth, order REFERENCE_LOW_PASS_ORDER) below this × '
        "the estimated ω0: the targets' residual wave motion is an error of the reference, not "
        'of the pose (probe on calibration seed 231: the truth / reference ratio of the pose '
        'error 0.77–1.44 against the targets as they are, 0.99–1.28 low-passed at 0.5 ω0, '
        'docs/BENCHMARKS.md "Thirty-fourth session"); 0 = the targets as they are, no ω0 yet: '
        'as they are (0 by default: on the calibration seeds it raised every vessel alike, '
        'ninth rule)', '× ω0'))
    twist_reference_cutoff: float = field(default=0.0, metadata=field_doc(
        "the twist error model is fitted against the targets' body velocity low-passed "
        '(zero-phase Butterworth, order REFERENCE_LOW_PASS_ORDER) below this × the estimated wave '
        "peak frequency ω0: the targets' residual wave motion, differentiated, is an error of "
        'the reference, not of the twist, and its share differs by vessel and sea (probe on '
        'calibration seed 231: the truth / reference ratio of the twist error 0.5–1.0 against '
        'the velocity as it is, 0.85–1.18 against it low-passed at 0.5 ω0, docs/BENCHMARKS.md '
        '"Thirty-fourth session"); 0 = the velocity as it is, no ω0 yet: as it is (0 by '
        'default: on the calibration seeds rao_supply became overconfident, seventh rule)',
        '× ω0'))
    twist_likelihood_fit: bool = field(default=False, metadata=field_doc(
        'fit the twist error model (holding and acceleration parts) by Gaussian maximum '
        'likelihood (iteratively reweighted least squares on e², weights 1/σ⁴) instead of '
        'least squares on e²: least squares lets the manoeuvres, whose e² is thousands of times '
        "the calm samples', set the holding part; the likelihood makes the window's mean e²/σ² "
        '1 (thirty-fourth session, tenth rule); false: least squares', ''))
    twist_attenuation: bool = field(default=False, metadata=field_doc(
        "with twist_reference_cutoff > 0: the twist error model's holding part adds, per DOF, "
        "the variance of the LF velocity the targets' zero-phase filter took away below that "
        "cutoff (`attenuated_variance`: the reference velocity's content where the filter's "
        'power response G is at least ATTENUATION_MIN_POWER, times (1 − G)/G). The reference '
        "shares that error with the twist (the notch's skirt takes 14–19 % of rao_supply's LF "
        'velocity between 0.1 rad/s and 0.5 ω0 and the twist misses the same part), so the fit '
        'cannot see it (thirty-fifth session, eleventh rule); false: off', ''))
    twist_accel_time: float = field(default=10.0, metadata=field_doc(
        'the twist error model grows with the change of the published twist per second, '
        'low-passed over this time (chosen from 2 / 5 / 10 / 20 s on tuning seeds 1–2, '
        'docs/BENCHMARKS.md "State-dependent covariance")', 's'))
    prior_pose_std: tuple[float, ...] = field(default=(0.5, 0.5, 0.01), metadata=field_doc(
        'pose error std assumed before the first targets (north, east, yaw)', 'm, m, rad'))
    prior_accel_std: tuple[float, ...] = field(default=(0.005, 0.005, 5e-5), metadata=field_doc(
        'LF acceleration std of the constant-velocity Kalman model (before a vessel model)',
        'm/s², m/s², rad/s²'))
    twist_bandwidth: float = field(default=1.0, metadata=field_doc(
        'bandwidth ω of the twist Kalman filter: velocity process noise q = r ω⁴ per DOF (r the '
        'pose error variance), a 2nd-order velocity estimate with ω_n = ω, ζ = 0.71; keep it '
        'well above the DP control bandwidth (a slow twist delays the D term; 1.0 chosen from '
        '0.3 / 0.5 / 1.0 by the D-term loops on tuning seeds 1–2, docs/BENCHMARKS.md); 0 = '
        'process noise from the LF acceleration of the targets', 'rad/s'))
    dead_reckoning_velocity_time: float = field(default=30.0, metadata=field_doc(
        'dead reckoning starts from the twist averaged over this time (first-order low-pass), '
        'not from the last twist: a DP loop acts against any velocity it sees, so a frozen '
        'wave-band twist would drive the vessel away while the poses are missing', 's'))
    dead_reckoning_force_time: tuple[float, ...] = field(default=(30.0, 30.0, 0.0),
                                                         metadata=field_doc(
        'the model dead-reckons from the environment force the thrust balanced before the '
        'fixes stopped: the thrust low-passed over this time per DOF (surge, sway, yaw; '
        'lf_dynamics.balanced_at); 0: that DOF keeps the environment fitted over the window '
        '(yaw: the heading oscillation of a DP loop leaks into a 30 s mean; chosen from '
        '30 / 120 / 300 / 0 s on tuning seeds 1–2, docs/BENCHMARKS.md)', 's, s, s'))
    dead_reckoning_motion_balance: bool = field(default=False, metadata=field_doc(
        'the environment force a dead reckoning starts from is balanced against the motion too, '
        'in the DOFs that are moving (low-passed twist > 2 holding std): the thrust, the twist '
        'and the twist change through the same two cascaded low-passes '
        '(dead_reckoning_force_time), so the force that accelerated a setpoint move is not taken '
        'for environment (lf_dynamics.balanced_at with accel); false: balanced at rest', ''))
    dead_reckoning_holding_balance: bool = field(default=True, metadata=field_doc(
        'in the DOFs that are moving when a dead reckoning starts (as dead_reckoning_moving_'
        'twist), the environment force is the thrust low-passed over dead_reckoning_force_time '
        'as it was while the vessel last held station there, dead_reckoning_holding_lead '
        'seconds before the move was seen (surge/sway as one earth-fixed force), instead of its '
        'current value, which has taken in the thrust that drives the move (the model then '
        'brakes the dead-reckoned move while the vessel goes on: docs/BENCHMARKS.md, fiftieth '
        'session; the default with its limits since the fifty-fourth, rule J); false: the '
        'current value', ''))
    dead_reckoning_holding_lead: float = field(default=10.0, metadata=field_doc(
        'with dead_reckoning_holding_balance: how long before the motion gate opened the held '
        'thrust is taken (the gate sees a move only after its low-pass has taken in some of '
        'it)', 's'))
    dead_reckoning_holding_max_turn: float = field(default=0.9, metadata=field_doc(
        'with dead_reckoning_holding_balance: the held thrust is used only if the heading has '
        'turned by at most this much since it was held (the environment a vessel holds against '
        'depends on its heading to wind, current and waves: after a turn the thrust held before '
        'it balanced another environment); else the current low-passed thrust; inf = always',
        'rad'))
    dead_reckoning_holding_max_age: float = field(default=60.0, metadata=field_doc(
        'with dead_reckoning_holding_balance: the held thrust is used only if the group last '
        'held station at most this long before the balance (a move seen that long ago is no '
        'longer young: its thrust has become the environment the vessel holds against, and the '
        'held thrust may belong to another place or sea); else the current low-passed thrust; '
        'inf = any age', 's'))
    dead_reckoning_holding_still: bool = field(default=True, metadata=field_doc(
        "with dead_reckoning_holding_balance: a DOF group's thrust counts as held only while "
        'every DOF holds station (no turn while the position holds, no move while the heading '
        'holds): the surge/sway thrust at the end of a turn, while the vessel still swings, '
        'is not the thrust it held station with (a spread dropout at the end of a turn, '
        'docs/BENCHMARKS.md, fifty-fourth session); false: each group on its own', ''))
    dead_reckoning_force_margin: float = field(default=FORCE_MARGIN, metadata=field_doc(
        'the thrust the odometry believes (dead reckoning, twist prediction, environment '
        'balance) is clipped per DOF to this multiple of the largest thrust in the vessel '
        "memory's window (against corrupt thrust messages); 0: no clip. A DP turn commands up "
        'to 26x the yaw moment of the station keeping before it: clipped at 2x, the dead '
        'reckoning lagged the turn and loops were lost (docs/BENCHMARKS.md, forty-ninth '
        'session); an absurd thrust still cannot make the state non-finite', '-'))
    dead_reckoning_moving_twist: bool = field(default=True, metadata=field_doc(
        'in the DOFs that are moving when a dead reckoning starts (low-passed twist > 2 holding '
        'std, as dead_reckoning_motion_balance), it starts from the current twist instead of '
        'the one low-passed over dead_reckoning_velocity_time: in a setpoint move that average '
        'lags the speed; false: the low-passed twist in every DOF (docs/BENCHMARKS.md, '
        'forty-ninth session)', ''))
    dead_reckoning_moving_gate: float = field(default=0.0, metadata=field_doc(
        'a DOF also counts as moving (the holding balance, the moving twist) when its current '
        'twist exceeds this many holding std, not only its low-passed twist 2 std: the '
        'low-pass lags the start of a move (rao_swell 1051, 28 s into a move at 1.1 m/s: '
        "low-passed 0.10 / 0.16 m/s against 2 std of 0.21 / 0.17, current 0.71; the move's "
        'thrust was balanced as environment and the loop was lost; docs/BENCHMARKS.md, '
        'fifty-sixth session); 0: off', ''))
    dead_reckoning_moving_gate_slow: float = field(default=0.0, metadata=field_doc(
        'with dead_reckoning_moving_gate: the current twist opens the gate only where the '
        'low-passed twist also exceeds this many holding std (surge and sway as one group): '
        'the move has begun. Holding station the current twist has heavier tails than its '
        'holding std (rao_supply 1077: 5-7.7 std in surge at rest, the low-passed 0.03-0.55), '
        'and the bare gate moved dropouts that begin before a turn by a few per cent the wrong '
        'way (rule N, docs/BENCHMARKS.md, fifty-sixth session); 0: the current twist alone', ''))
    dead_reckoning_twist_average_periods: float = field(default=1.0, metadata=field_doc(
        'the span of the wave-averaged twist: the published twist averaged (a boxcar) over this '
        'many wave periods 2π/ω0 of the newest ω0 estimate (one period has a zero at ω0, so the '
        'wave-band velocity the twist filter passes, bandwidth 1 rad/s, is dropped, with a lag '
        'of half the span); used by dead_reckoning_moving_twist_start and '
        'dead_reckoning_moving_gate_averaged; 0: none', 'wave periods'))
    dead_reckoning_moving_twist_start: str = field(default='current', metadata=field_doc(
        "with dead_reckoning_moving_twist: the twist the moving DOFs start from. 'current': the "
        "last published; with dead_reckoning_twist_average_periods > 0, 'average': the "
        'wave-averaged twist (it lags by half its span T: docs/BENCHMARKS.md, sixty-first '
        'session, alone it lost 4 % in the moves row on development seeds), '
        "'extrapolated': that average carried over its lag, 2 mean(T) - mean(2T) (both "
        'boxcars null ω0, and a ramp comes out exact); no ω0 yet, or a history shorter than '
        'the span: the current', ''))
    dead_reckoning_moving_twist_clamp: float = field(default=0.0, metadata=field_doc(
        'with the averaging span: the current twist a moving DOF starts from (the start '
        "'current'; the others have nothing to clamp) is kept within this many holding std of "
        'the span between the wave-averaged twist and its extrapolation over its lag (2 '
        'mean(T) - mean(2T); the average alone while the history is shorter than 2T): a move '
        'starts from the current twist, but not from a spike of it (2.4x / 3.6x the true speed '
        'at a heading failure, docs/BENCHMARKS.md, sixty-first session); 0: off',
        'holding std'))
    dead_reckoning_moving_twist_clamp_dofs: str = field(default='all', metadata=field_doc(
        "the DOFs dead_reckoning_moving_twist_clamp acts on: 'all', or 'horizontal' (surge "
        'and sway; the yaw rate starts from the current one)', ''))
    dead_reckoning_moving_gate_averaged: float = field(default=2.0, metadata=field_doc(
        'with dead_reckoning_twist_average_periods > 0: a DOF also counts as moving (the holding '
        'balance, the moving twist) when its wave-averaged twist exceeds this many holding std '
        '(surge and sway as one group): the average lags a move by half its span where the '
        'low-passed twist lags it by dead_reckoning_force_time, and it has none of the current '
        "twist's wave-band tails (2 with 1 period: rule T, docs/BENCHMARKS.md, sixty-first "
        'session, the moves row 0.86x on fresh seeds); 0: off', ''))
    dead_reckoning_excursion_std: float = field(default=2.0, metadata=field_doc(
        "the model's relative error in a manoeuvre: while dead reckoning, the covariance adds "
        "(this × the displacement the memory's model dead-reckons since the dropout began)², "
        'horizontally isotropic, and (this × its heading change)² (twist: the same on the '
        "model's twist), plus the square of what a reckoner other than the model misses of "
        "that displacement; the drift curve is learned holding station, where the thrust and "
        'the displacement are small, and held the truth in a setpoint move only half the time '
        '(docs/BENCHMARKS.md, fiftieth session); 2 made it 0.87-0.91 in the loop through '
        'dropouts in the moves, but the published std 6-154x the error in the open-loop '
        'dead-reckoning row, where the recorded thrust drives the model far while the error '
        'stays small (fifty-first session; hence dead_reckoning_excursion_band, with which '
        '2 is the default since the fifty-second session); 0 = off', '-'))
    dead_reckoning_excursion_band: float = field(default=2.0, metadata=field_doc(
        "with dead_reckoning_excursion_std: the displacement the term scales is the model's "
        "answer to the thrust beyond what station keeping needed, and only under a DP "
        "controller's thrust (the memory's dp_controlled): the memory's model balanced at rest "
        'against the thrust averaged over EXCURSION_FORCE_TIME before the dropout, driven by '
        'the thrust beyond ± this × the std of the thrust about that average while tracking, '
        'per DOF (holding station a DP thrust balances the environment and moves nothing; a '
        "setpoint move's thrust leaves the band); no term without a DP controller (the drift "
        "curve is learned on the thrust that moves such a vessel); 0: the model's answer to the "
        'whole thrust. With both at 2, fresh seeds: the truth inside the 95 % ellipse through '
        'dropouts in setpoint moves 0.97 / 0.90 (default before: 0.60 / 0.48), the open-loop '
        'row unchanged (docs/BENCHMARKS.md, fifty-second session)', '-'))
    twist_model: bool = field(default=False, metadata=field_doc(
        "the twist Kalman filter predicts with the vessel memory's model whenever its thrust "
        'gain is given or implied by the controller (else only when the drift test chose it)',
        ''))
    vessel_inertia: tuple[float, ...] = field(default=(0.0, 0.0, 0.0), metadata=field_doc(
        'optional: the vessel inertia M_ii with added mass per DOF (surge, sway, yaw); when '
        'given, the vessel memory uses the thrust gain 1/M_ii instead of fitting it (station-'
        'keeping data cannot identify it: the LF thrust mostly cancels the environment) and '
        "'auto' dead-reckons on the model; 0 = learn it", 'kg, kg, kg·m²'))
    controller_inertia: bool = field(default=True, metadata=field_doc(
        "without vessel_inertia: read the DP controller's PD gains Kp, Kd from its commands "
        '(thrust_command) on the published estimates and dead-reckon on the inertia Kd²/(4 Kp) '
        'under which that controller is critically damped (core.controller_gains); too few '
        'contiguous commands: the last successful read; no read yet, or commands the PD law does '
        "not explain (R² < 0.5, which also forgets the last read): the memory's choice", ''))
    controller_read_block_time: float = field(default=300.0, metadata=field_doc(
        "with controller_inertia: read the controller's gains per block of this length and "
        'take per DOF the median over the blocks whose PD law is believed (a setpoint move or a '
        'turn spoils only its own block); 0 = one read pooled over the whole history, as before '
        'the forty-seventh session (its rule on fresh seeds: rao_supply 0.39× the excursion '
        'after a dropout, docs/BENCHMARKS.md)', 's'))
    controller_read_damping: bool = field(default=False, metadata=field_doc(
        "with controller_inertia: the read inertia is the one under which the controller's Kd "
        "and the vessel's own damping (the vessel memory's fitted rate) together are critical, "
        'as for a DP PID designed with Kd = 2 zeta omega_n M - D (the MSS PID, and the '
        'simulator here); Kd^2/(4 Kp) alone reads such a yaw inertia 0.6x too small '
        '(core.controller_gains.damping_corrected_inertia). Off: with the fitted or kept '
        'damping rates it over-corrected in the screen (the heading overshot turns by up to '
        '2 rad; docs/BENCHMARKS.md, fifty-third session)', ''))
    controller_read_fitted_damping: bool = field(default=True, metadata=field_doc(
        'with controller_inertia: the read inertia is the one under which Kd and the damping '
        "force the window's fit found (D = f M_r, which the data fix whatever gain is assumed) "
        'together are critical, M = M_r (1 + f/(2 omega_r))^2, and the damping rates are scaled '
        "by the same factor (the fit's steady gain G/f kept): smooth in f, unlike "
        "controller_read_damping, which takes the fitted rate as the vessel's own "
        '(core.controller_gains.fitted_damping_scale; docs/BENCHMARKS.md, fifty-fifth '
        'session). Overrides controller_read_damping. On by default, in yaw only, with the '
        'pooled read since the sixtieth session (rule S)', ''))
    controller_read_fitted_damping_dofs: str = field(default='yaw', metadata=field_doc(
        "with controller_read_fitted_damping: the DOFs it corrects, 'all' or 'yaw' (surge and "
        'sway then keep the read inertia and their fitted rates): the yaw read is 0.6x for a '
        "PID that takes the vessel's damping off Kd (the simulator's yaw rate 0.086 1/s "
        'against omega_r 0.255 rad/s), while surge and sway are read 1.1-1.3x and their '
        'fitted rates often sit at the bound or vary 10x between windows (docs/BENCHMARKS.md, '
        'fifty-eighth session)', ''))
    controller_read_pool_blocks: int = field(default=8, metadata=field_doc(
        'with controller_inertia and controller_read_block_time > 0: the controller is read '
        'from the newest this many blocks ever read (each block of published estimates read '
        "once, kept across windows) instead of the blocks in one window's history; 0: off. "
        "The controller does not change between windows, but one window's 2-4 blocks, most "
        'with a move or a turn in them, moved the read yaw inertia 0.4-2.5x between two '
        'dropouts of one loop (core.lf_state.pooled_input_gain; docs/BENCHMARKS.md, '
        'fifty-ninth session; 8 by default since the sixtieth, rule S)', ''))
    controller_read_lone_r_squared: float = field(default=0.9, metadata=field_doc(
        'with controller_inertia: a DOF that one block alone believes (nothing outvotes it; '
        'or a read without blocks) needs a PD law that explains at least this fraction of the '
        'high-passed commands (R^2; core.controller_gains); 0: the 0.5 every block needs. A '
        'controller acting on these estimates explains 0.996 in median (rao_supply, '
        'rao_swell), one acting on another estimate 0.47-0.74 (onedof_feedback, a PID on the '
        'true LF pose): one such block, alone and believed, read 64.6 kg against about 1471 '
        'and the dead reckoning ran 303 m off in 120 s. 0.9 demanded of every block instead '
        'made the heading through hidden turns worse (rao_supply 1.16x: the median lost the '
        'low blocks; docs/BENCHMARKS.md, sixty-third session). 0.9 (between the two, not '
        'tuned) is the default since the sixty-third session (rule V: the development '
        'divergence gone, every fresh run unchanged); in [0, 1)', '-'))
    controller_read_median_r_squared: float = field(default=0.91, metadata=field_doc(
        'with controller_inertia: a controller identity gate. When the read has at least 3 '
        "blocks (the pool, or the window's) and no DOF's median R^2 over them reaches this, no "
        'DOF is read: the controller does not act on these estimates (core.controller_gains.'
        'identity_gated). A controller acting on them: best medians of 0.93 or more '
        "(rao_supply's and rao_swell's moves); one on another estimator's poses: at most 0.88, "
        'and on a 2 h supply-vessel log of a loop on the observer the read believed it at '
        "5-34x the true inertia; in the benchmark's stand-in for such logs a dead reckoning "
        'on such a read ran 30-130 m off in 120 s (docs/BENCHMARKS.md, sixty-fifth session). '
        '0.91 (the midpoint of the development extremes, not tuned) is the default since rule '
        'Y (fresh seeds: 9 of 36 foreign dropouts above 10 m at 120 s -> 2, every loop on these '
        'estimates unchanged). 0: off; in [0, 1)', '-'))
    controller_read_difference: bool = field(default=True, metadata=field_doc(
        "with controller_inertia: the controller's D term may also act on the published poses' "
        'own finite difference through a first-order low-pass of a time constant T_v the read '
        'finds (a grid of 0.25-8 s, refined; a DP controller that differentiates lf_pose '
        "itself, as dp_controller's default velocity_source 'difference', T_v 1 s), and each "
        'block keeps the twist or the difference, whichever explains the commands better '
        '(core.controller_gains.read_controller_gains); false: the published twist only. '
        "Read on the twist, such a controller explained at most 0.97 of its commands and a "
        "move's dropout diverged with the pose held (rao_supply); read on the difference with "
        'a T_v not its own, the inertia was 0.03-3.3x (docs/BENCHMARKS.md, sixty-fourth '
        'session). The default since the sixty-fourth session (rule X: fresh loops of such a '
        'controller through dropouts, 2 of 28 diverged -> 0, 0.91x the distance; every '
        'twist-fed run unchanged)',
        ''))
    controller_read_keep_dofs: bool = field(default=True, metadata=field_doc(
        'with controller_inertia: a read whose blocks believe some DOFs but in another none '
        "(a turn spoils yaw's blocks) keeps the last successful read's inertia in that DOF "
        'instead of forgetting the read (a PD law still explains the thrust in the others: the '
        'controller has not changed); false: forgotten, the thrust gain is then fitted, and a '
        'fitted yaw environment extrapolated to -91 MN m after a turn (rao_supply 1008; '
        'docs/BENCHMARKS.md, fifty-sixth session; the default since then, rule M)', ''))
    controller_read_holding_only: bool = field(default=False, metadata=field_doc(
        'with controller_inertia and controller_read_block_time: a block whose published '
        'estimates manoeuvred (a setpoint move or a turn, core.manoeuvre) is not read. The '
        "controller acts on the error from its filtered setpoint, which the read does not know; "
        'holding station that setpoint is constant and the high-pass removes it, in a move or a '
        "turn its transient is read as stiffness and damping (blocks with a move: surge inertia "
        "0.17-0.90x the controller's). Off: the median over the blocks outvotes most of them, "
        'and on fresh seeds the dead reckoning through dropouts in moves was 1.04x worse with '
        'it (docs/BENCHMARKS.md, seventy-second session, rule AA)', ''))
    controller_read_pair_ratio: float = field(default=3.0, metadata=field_doc(
        'with controller_inertia and controller_read_block_time: a DOF that exactly two '
        'blocks believe, with implied inertias more than this factor apart, is not read from '
        'them (with controller_read_keep_dofs the remembered read stands in there): the '
        'median of two is their mean, and a turn that spoils one block and still passes '
        'ruins it (rao_swell 1104, 51 s into the first turn: yaw inertia 5.5x the truth, the '
        'heading through a dropout 1.3 rad off); 0: off. 3 (taken, not tuned) is the default '
        'since the fifty-seventh session (rule P: the heading failures in the moves 5 -> 4 of '
        '176 on fresh seeds, the distance 1.004x; docs/BENCHMARKS.md)', '-'))
    free_fit_earth_fixed: bool = field(default=True, metadata=field_doc(
        'without a known or read thrust gain (no vessel_inertia, no controller read in force), '
        "3 DOF: the vessel memory's environment is one earth-fixed force and a constant yaw "
        'moment, as with a known gain, fitted after the gains and damping rates (those with a '
        'constant environment); false: a free [1, cos psi, sin psi] per DOF, which a window at '
        'one heading cannot identify and which extrapolates to absurd forces at another (-55 MN '
        'm of yaw 0.5 rad away on a simulated window; -91 MN m on rao_supply 1008); the '
        "default since the fifty-seventh session (rule O: the excited open-loop vessel's "
        'dead reckoning 0.61x at 120 s on fresh seeds, DP loops unchanged; docs/BENCHMARKS.md)',
        ''))
    dead_reckoning_damping_memory: str = field(default='yaw', metadata=field_doc(
        "with a known or read thrust gain, 'yaw' or 'all' (DOFs): the vessel memory keeps per "
        'DOF the damping rate of the window that identified it best (the most velocity energy, '
        'sum of the squared target velocity) across windows and dropouts, instead of each '
        'window fitting its own: a window in which the heading hardly moves cannot identify '
        'the yaw damping (rao_supply: 33-240 s between turns, 8-12 s with a turn, truth '
        '11.6 s), and a dead reckoning through the next turn on too little damping turned the '
        "estimate twice as fast as the vessel; 'off': each window its own (docs/BENCHMARKS.md, "
        "fifty-third session; 'yaw' the default since the fifty-fourth, rule J)", ''))
    dead_reckoning_damping_refuse_bound: bool = field(default=False, metadata=field_doc(
        'with dead_reckoning_damping_memory: a rate that a window fitted at its lower bound '
        '(1/1000 1/s: the data asked for no damping or a negative one, i.e. the window did not '
        'identify it) never replaces the kept rate, whatever its velocity energy; false: the '
        'energy decides alone (rao_supply 1124: a window without a turn, after one a dropout '
        'had hidden, replaced 0.09 1/s by the bound, and the heading through the next turn '
        'ended 1.5 rad off; docs/BENCHMARKS.md, fifty-eighth session)', ''))
    dead_reckoning_damping_turn: float = field(default=0.3, metadata=field_doc(
        'with dead_reckoning_damping_memory, 3 DOF: the kept yaw damping rate is replaced '
        'only by a window whose heading spans at least this much (a turn) and that moved more '
        'than the kept one; a window without a turn fills an empty memory only. A window '
        'without a turn cannot identify the yaw damping, and its velocity energy does not '
        'say so: a window at the end of a move (sway-yaw coupling) fitted 2.9x the true rate '
        'with 5x the energy of the start-up window it replaced (rao_supply 1116); 0: off, the '
        'energy decides alone. 0.3 rad (taken, not tuned: between the settling after a turn '
        'and the smallest setpoint turn) is the default since the fifty-eighth session (rule '
        'Q; docs/BENCHMARKS.md)', 'rad'))
    controller_read_earth_frame: bool = field(default=True, metadata=field_doc(
        'with controller_inertia, 3 DOF: high-pass the estimates and the commands in the earth '
        'frame before turning them into the body frame (a turn away from the setpoint origin '
        'then does not swing the pose the read regresses on); false: in the body frame', ''))
    controller_read_stiffness_frame: str = field(default='body', metadata=field_doc(
        "with controller_inertia, 3 DOF: the frame the controller's stiffness Kp acts in. "
        "'body': Kp on the body-frame error R(psi)^T (eta - eta_d), per DOF; 'earth': a "
        'diagonal Kp on the earth-frame error, turned into the body frame afterwards (the MSS '
        'DP PID and the simulator here), surge and sway read together; after a 90 deg turn '
        'the body read pairs surge Kd with the east Kp and reads the surge inertia 0.6x '
        "(supply vessel); 'auto': the one that explains the thrust better (R^2) "
        '(docs/BENCHMARKS.md, fifty-fifth session)', ''))
    dead_reckoner: str = field(default='auto', metadata=field_doc(
        "dead reckoner through a pose dropout: 'auto' (the vessel memory's choice by the "
        "open-loop drift test; hold when the test cannot tell), 'model' (the learned LF model "
        "driven by the thrust; the memory's choice while no model is fitted), "
        "'constant_velocity' or 'hold' (tuning seeds, DP loops through 60 s dropouts: auto; "
        "model unsafe on rao_supply; docs/BENCHMARKS.md)", ''))
    dead_reckoning_keep_model: bool = field(default=True, metadata=field_doc(
        'a new vessel memory whose LF model was refused (a window whose fit failed, e.g. a turn '
        'with a thrust gain of the wrong sign and no controller read) does not replace one '
        'with a model: the vessel has not changed, and without a model a dropout in a turn '
        "falls back to 'hold', whose held heading error the PID keeps turning against "
        '(docs/BENCHMARKS.md, fifty-first session; the default since the fifty-fourth, rule '
        'J); counted in memories_kept; false: the newest memory is always used', ''))
    reacquire_gate: float = field(default=CHI2_3DOF_999, metadata=field_doc(
        'a fix within this squared Mahalanobis distance of the dead-reckoned pose is accepted '
        'at once', ''))
    reacquire_time: float = field(default=10.0, metadata=field_doc(
        'a fix outside the gate is accepted after this long of consecutive fixes', 's'))
    reacquire_blend_time: float = field(default=30.0, metadata=field_doc(
        'after reacquisition the published pose moves from the dead-reckoned pose to the '
        'estimate over this time (no step); 0 = jump at once', 's'))
    narrow_reference: bool = field(default=True, metadata=field_doc(
        "calibrate against the targets' samples filtered with the predictor's narrow notch_zeta "
        'when its training targets use the broadband notch (notch_zeta_broadband): those wide-'
        'notch targets are smoother than the truth by a sea-dependent amount, so errors measured '
        'against them do not scale to the errors against the truth (retraining.narrow_reference; '
        'false: the training targets themselves)', ''))
    min_calibration_samples: int = field(default=60, metadata=field_doc(
        'fewest matched samples of one source for its own covariance (else all sources)', ''))

    def __post_init__(self) -> None:
        """Check every rule; the message says what to change."""
        for name in ('dead_reckoning_timeout', 'pose_cov_scale', 'twist_cov_scale',
                     'twist_accel_time', 'reacquire_gate'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'{name} must be a positive finite number, got {value}')
        for name, hint in NON_NEGATIVE:
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f'{name} must be a finite number >= 0{hint}, got {value}')
        check_force_margin(self.dead_reckoning_force_margin, 'dead_reckoning_force_margin')
        if not (math.isfinite(self.controller_read_pair_ratio) and
                (self.controller_read_pair_ratio == 0.0 or self.controller_read_pair_ratio > 1.0)):
            raise ValueError('controller_read_pair_ratio must be 0 (off) or a finite factor > 1, '
                             f'got {self.controller_read_pair_ratio}')
        if self.dead_reckoning_moving_twist_start not in MOVING_TWIST_STARTS:
            raise ValueError('dead_reckoning_moving_twist_start must be one of '
                             f'{MOVING_TWIST_STARTS}, got '
                             f'{self.dead_reckoning_moving_twist_start!r}')
        for what, used in (
                ("dead_reckoning_moving_twist_start other than 'current'",
                 self.dead_reckoning_moving_twist_start != 'current'),
                ('dead_reckoning_moving_twist_clamp > 0',
                 self.dead_reckoning_moving_twist_clamp > 0.0),
                ('dead_reckoning_moving_gate_averaged > 0',
                 self.dead_reckoning_moving_gate_averaged > 0.0)):
            if used and self.dead_reckoning_twist_average_periods <= 0.0:
                raise ValueError(f'{what} needs the averaging span: set '
                                 'dead_reckoning_twist_average_periods > 0 too (e.g. 1), or '
                                 'turn it off')
        if not (math.isfinite(self.dead_reckoning_velocity_time) and
                self.dead_reckoning_velocity_time > 0.0):
            raise ValueError('dead_reckoning_velocity_time must be a positive number of seconds, '
                             f'got {self.dead_reckoning_velocity_time}')
        if not (self.dead_reckoning_holding_max_turn >= 0.0):  # inf allowed, NaN not
            raise ValueError('dead_reckoning_holding_max_turn must be >= 0 rad (inf: any turn), '
                             f'got {self.dead_reckoning_holding_max_turn}')
        if not (self.dead_reckoning_holding_max_age >= 0.0):  # inf allowed, NaN not
            raise ValueError('dead_reckoning_holding_max_age must be >= 0 s (inf: any age), '
                             f'got {self.dead_reckoning_holding_max_age}')
        force_time = tuple(self.dead_reckoning_force_time)
        if len(force_time) != 3 or not all(math.isfinite(v) and v >= 0.0 for v in force_time):
            raise ValueError('dead_reckoning_force_time must be 3 finite numbers >= 0 s (surge, '
                             f'sway, yaw; 0: keep the fitted environment), got {force_time}')
        object.__setattr__(self, 'dead_reckoning_force_time',
                           tuple(float(v) for v in force_time))
        for name in ('prior_pose_std', 'prior_accel_std'):
            value = tuple(getattr(self, name))
            if len(value) != 3 or not all(math.isfinite(v) and v > 0.0 for v in value):
                raise ValueError(f'{name} must be 3 positive numbers (north, east, yaw), '
                                 f'got {value}')
            object.__setattr__(self, name, tuple(float(v) for v in value))
        inertia = tuple(float(v) for v in self.vessel_inertia)
        if len(inertia) != 3 or not all(math.isfinite(v) and v >= 0.0 for v in inertia) or (
                any(v > 0.0 for v in inertia) and not all(v > 0.0 for v in inertia)):
            raise ValueError('vessel_inertia must be 3 finite numbers, all 0 (learn) or all > 0 '
                             f'[kg, kg, kg·m²], got {self.vessel_inertia}')
        object.__setattr__(self, 'vessel_inertia', inertia)
        if not (math.isfinite(self.controller_read_median_r_squared) and
                0.0 <= self.controller_read_median_r_squared < 1.0):
            raise ValueError('controller_read_median_r_squared must be in [0, 1) (0: off), got '
                             f'{self.controller_read_median_r_squared}')
        if not (math.isfinite(self.controller_read_lone_r_squared) and
                0.0 <= self.controller_read_lone_r_squared < 1.0):
            raise ValueError('controller_read_lone_r_squared must be in [0, 1) (0: off), got '
                             f'{self.controller_read_lone_r_squared}')
        if not (math.isfinite(self.dead_reckoning_damping_turn) and
                0.0 <= self.dead_reckoning_damping_turn <= math.pi):
            raise ValueError('dead_reckoning_damping_turn must be in [0, pi] rad (0: off), '
                             f'got {self.dead_reckoning_damping_turn}')
        for name, choices in (('controller_read_fitted_damping_dofs', tuple(FITTED_DAMPING_DOFS)),
                              ('dead_reckoning_moving_twist_clamp_dofs',
                               tuple(MOVING_TWIST_CLAMP_DOFS)),
                              ('dead_reckoning_damping_memory', tuple(DAMPING_MEMORY_DOFS)),
                              ('controller_read_stiffness_frame', tuple(STIFFNESS_FRAMES))):
            if getattr(self, name) not in choices:
                raise ValueError(f'{name} must be one of {choices}, got {getattr(self, name)!r}')
        if self.dead_reckoner not in ('auto', *DEAD_RECKONERS):
            raise ValueError(f"dead_reckoner must be 'auto' or one of {DEAD_RECKONERS}, got "
                             f'{self.dead_reckoner!r}')
        blocks = self.controller_read_pool_blocks
        if not isinstance(blocks, int) or isinstance(blocks, bool) or blocks < 0 or \
                (blocks > 0 and self.controller_read_block_time <= 0.0):
            raise ValueError('controller_read_pool_blocks must be 0 (off) or a count > 0 with '
                             'controller_read_block_time > 0, got '
                             f'{self.controller_read_pool_blocks} (block time '
                             f'{self.controller_read_block_time} s)')
        if self.min_calibration_samples < 1:
            raise ValueError('min_calibration_samples must be >= 1, got '
                             f'{self.min_calibration_samples}')
