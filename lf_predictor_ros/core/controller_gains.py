"""The DP controller's gains, read from the thrust it commands; the inertia they imply.

A DP loop on the LF odometry computes its thrust from the published pose and twist. Its PD part
(Fossen 2011 §12.2.6, the DP PID τ = −Kp Rᵀ(ψ)(η − η_d) − Kd ν − Ki ∫…) is visible in the data:
regressed on the published estimates (and their integral), the commanded thrust's fast part
(above the setpoint changes, high-passed over ``HIGHPASS_TIME``) gives per DOF the stiffness Kp
and the damping Kd the controller applies. This needs no vessel model and no excitation: the
controller is a known function of the published estimates, whatever the sea does.

Station-keeping data cannot teach the vessel's inertia (the LF thrust cancels the environment:
closed-loop identification without excitation, docs/BENCHMARKS.md, issue 14). A dead reckoner
without one holds the pose, and a controller acting on a held pose pushes the vessel away with
Kp × (the error when the fix was lost) + its integrator. A dead reckoner driven by the thrust
closes the loop through its model instead. The inertia

    M_i = Kd_i² / (4 Kp_i)

is the one under which the controller's own PD is critically damped (M s² + Kd s + Kp with
ζ = Kd / (2 √(Kp M)) = 1). A controller designed with Kp = M ω_n², Kd = 2 ζ M ω_n (the MSS
PID and most DP designs) implies ζ² M: the true inertia for ζ = 1, a lighter vessel for a less
damped design, which makes the model loop faster and more damped, never unstable.

Conventions as ``core.lf_dynamics``: 1 DOF = surge (north, no rotation), 3 DOF = [north m,
east m, heading rad] with the heading unwrapped, ν and τ in ``base_link_fsd``. Pure functions.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import uniform_filter1d
from scipy.optimize import minimize_scalar
from scipy.signal import lfilter

from lf_predictor_ros.core.lf_dynamics import as_series, body_to_earth, earth_to_body

FloatArray = NDArray[np.float64]

# The thrust and the estimates are high-passed by subtracting their moving mean over this window
# before the regression: it removes the integrator's slow force, the environment and setpoint
# changes (the DP setpoint filter's time constant is tens of seconds) [s].
HIGHPASS_TIME = 60.0
# The thrust may lag the estimate it was computed from by a few samples (message timing): the
# regression is done for every shift up to this many samples either way and the best one kept.
MAX_SHIFT = 2
# A DOF's gains are believed only if the PD law explains at least this fraction of the
# high-passed thrust variance (R²): a thrust from another estimator, an open-loop test or a
# joystick explains little [-].
MIN_R_SQUARED = 0.5
# Fewer samples than this give no gains [-].
MIN_SAMPLES = 120
# A DOF's gains are believed only if the natural frequency they imply, ω_n = 2 Kp / Kd (= √(Kp/M)
# with M = Kd² / (4 Kp)), is below this × the wave peak frequency ω0, when ω0 is known: a DP
# controller acts below the wave band, behind a wave filter that exists to keep it there (the
# MSS DP PID's ω_n is 0.1–0.2 rad/s, anchors §5; ω0 of the sea states here ≥ 0.48 rad/s). A
# faster PD law is not the controller acting on these estimates: the applied thrust of a
# controller on another estimator read as commands gave ω_n = 1.2–7.6 rad/s at ω0 = 0.8 rad/s
# on onedof_feedback, an inertia 10⁴× too small and a dead reckoning kilometres off
# (docs/BENCHMARKS.md, fifty-second session) [-].
MAX_NATURAL_FREQ_RATIO = 1.0
# `identity_gated` judges a controller from at least this many blocks (a median of fewer is
# not a majority)
IDENTITY_MIN_BLOCKS = 3
# The frames the stiffness Kp may act in (`fit_controller_gains`): 'body', Kp on the body-frame
# error R(ψ)ᵀ(η − η_d) (Fossen 2011 §12.2.6); 'earth', Kp on the earth-frame error, turned
# into the body frame afterwards, τ = −R(ψ)ᵀ Kp (η − η_d) − Kd ν (the MSS DP PID, anchors §5,
# and `sim_ros.control.pid`); 'auto', whichever explains the thrust better.
STIFFNESS_FRAMES = ('body', 'earth', 'auto')
# The filter time constants T_v a DP controller's own velocity difference may have, the grid
# `read_controller_gains` tries (``controller_read_difference``): 1 s is `dp_controller`'s and
# the MSS PID's; the search reaches T_v / 2 below the first and 2 T_v above the last [s]
DIFFERENCE_TIMES = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0)
# `read_controller_gains` refines a winning difference filter's time constant by a bounded
# search in log T_v between its grid neighbours (at a grid end: this factor beyond it), to this
# tolerance in log T_v [-]
DIFFERENCE_SEARCH_FACTOR = 2.0
DIFFERENCE_SEARCH_TOLERANCE = 0.01


@dataclass(frozen=True)
class ControllerGains:
    """The PD part of a DP controller as seen in its thrust, one entry per DOF.

    Attributes:
        stiffness: Kp [N/m, N/m, N·m/rad] (body frame; with ``stiffness_frame`` 'earth', on
            the north, east and heading errors).
        damping: Kd [N·s/m, N·s/m, N·m·s/rad].
        r_squared: fraction of the high-passed thrust variance the PD law explains [-].
        shift: samples the thrust lags the estimates by (negative: leads).
        stiffness_frame: 'body' or 'earth' (`STIFFNESS_FRAMES`): the frame Kp acts in.
        difference_time: 0: Kd acts on the published twist; > 0: on the poses' own finite
            difference low-passed over this time constant T_v [s] (`read_controller_gains`).
    """

    stiffness: FloatArray
    damping: FloatArray
    r_squared: FloatArray
    shift: int
    stiffness_frame: str = 'body'
    difference_time: float = 0.0

    def believed(self, max_natural_freq: float = math.inf,
                 min_r_squared: float = MIN_R_SQUARED) -> NDArray[np.bool_]:
        """Per DOF: a PD law that explains the thrust (R² ≥ ``min_r_squared``), positive gains.

        And whose natural frequency 2 Kp / Kd is below ``max_natural_freq`` [rad/s] (inf: no
        bound; `implied_input_gain` passes ``MAX_NATURAL_FREQ_RATIO`` × ω0).
        """
        return (self.r_squared >= min_r_squared) & (self.stiffness > 0.0) & \
            (self.damping > 0.0) & (self.natural_freq() < max_natural_freq)

    def implied_inertia(self, max_natural_freq: float = math.inf,
                        min_r_squared: float = MIN_R_SQUARED) -> FloatArray | None:
        """M_i = Kd_i² / (4 Kp_i) per DOF (module docstring), or None unless every DOF is believed.

        [kg, kg, kg·m²]. ``max_natural_freq``, ``min_r_squared``: as `believed`.
        """
        if not np.all(self.believed(max_natural_freq, min_r_squared)):
            return None
        return self.inertia_per_dof()

    def inertia_per_dof(self) -> FloatArray:
        """Kd_i² / (4 Kp_i) of every DOF, believed or not (inf or NaN where Kp_i = 0)."""
        with np.errstate(divide='ignore', invalid='ignore'):
            result: FloatArray = self.damping ** 2 / (4.0 * self.stiffness)
        return result

    def natural_freq(self) -> FloatArray:
        """ω_n = 2 Kp_i / Kd_i of every DOF, believed or not (= √(Kp/M) at M = Kd²/(4 Kp)).

        [rad/s]; inf or NaN where Kd_i = 0.
        """
        with np.errstate(divide='ignore', invalid='ignore'):
            result: FloatArray = 2.0 * self.stiffness / self.damping
        return result


def block_bounds(length: int, block: int, minimum: int) -> list[tuple[int, int]]:
    """[start, end) of consecutive blocks covering ``length`` samples, each ≥ ``minimum``.

    Blocks of ``block`` samples (at least ``minimum``); a remainder shorter than ``minimum``
    joins the last block; a series shorter than ``minimum`` has no block.
    """
    size = max(block, minimum)
    if length < minimum:
        return []
    full = length // size
    edges = [i * size for i in range(max(full, 1))]
    if full >= 1 and length - full * size >= minimum:
        edges.append(full * size)
    return list(zip(edges, edges[1:] + [length], strict=True))


def identity_gated(blocks: Sequence[ControllerGains], median_r_squared: float
                   ) -> tuple[list[ControllerGains], bool]:
    """The blocks with R² 0 in every DOF unless some DOF's median R² reaches ``median_r_squared``.

    Whether the controller acts on these estimates at all, asked of the blocks together (a
    controller identity gate): the PD law of a controller acting on the published estimates
    explains nearly all of the high-passed commands in most blocks, in the DOFs a move or a
    turn does not spoil (surge and sway of rao_supply's moves: a median over any eight
    consecutive blocks of at least 0.96; yaw there down to 0.46), while one acting on another
    estimator's poses explains less in every DOF: 0.47–0.74 on onedof_feedback (a PID on the
    true LF pose, sixty-third session), and on a 2 h log of the supply vessel's loop on the
    observer, whose blocks the read believed at 5–34× the true inertia, a best median over
    three or more blocks of at most 0.88, against 0.93 or more for controllers acting on
    these estimates (docs/BENCHMARKS.md, sixty-fifth session; `OdometryParams.
    controller_read_median_r_squared`, 0.91 by rule Y). So the gate asks the best DOF: when
    no DOF's median R² over the blocks reaches it, no DOF is read. A per-block bound would drop the
    spoilt blocks of a true read (their values keep the median honest, sixty-third session);
    the median keeps them. Fewer than `IDENTITY_MIN_BLOCKS` blocks are not judged: the median
    of one or two is no majority (one spoilt block decides it; in rao_supply's moves two
    consecutive blocks of a controller acting on these estimates had a best median of 0.82,
    while single foreign blocks reached 0.90). NaN R² count as 0. Returns (the blocks, gated
    or not; whether they were gated). ``median_r_squared`` ≤ 0: unchanged.
    """
    if median_r_squared <= 0.0 or len(blocks) < IDENTITY_MIN_BLOCKS or \
            np.max(median_r_squared_per_dof(blocks)) >= median_r_squared:
        return list(blocks), False
    return [replace(b, r_squared=np.zeros_like(b.r_squared)) for b in blocks], True


def median_r_squared_per_dof(blocks: Sequence[ControllerGains]) -> FloatArray:
    """Per DOF the median R² over the blocks, NaN counted as 0 (no blocks: empty)."""
    if not blocks:
        return np.zeros(0)
    r_squared = np.nan_to_num(np.array([b.r_squared for b in blocks], dtype=np.float64))
    result: FloatArray = np.median(r_squared, axis=0)
    return result


def median_implied_inertia(blocks: Sequence[ControllerGains],
                           max_natural_freq: float = math.inf, pair_ratio: float = math.inf,
                           lone_r_squared: float = 0.0
                           ) -> tuple[FloatArray | None, NDArray[np.int64]]:
    """Per DOF the median of Kd² / (4 Kp) over the blocks where that DOF is believed.

    One read per block of the history and the median over them (forty-seventh session): a
    setpoint move or a turn corrupts the read of the block it falls in (its R² drops to
    0.4–0.7 and the inertia is off by 0.02–20×), and pooled over the whole history it had
    corrupted every later read. Returns (the inertia, or None unless every DOF is believed in
    at least one block; the count of believed blocks per DOF). ``max_natural_freq``: as
    `ControllerGains.believed`. ``pair_ratio``: a DOF that exactly two blocks believe, with
    inertias more than this factor apart, is believed by neither; ``lone_r_squared``: a DOF
    that one block alone believes needs this R² (`_believed_blocks`).
    """
    return _median_believed(blocks, ControllerGains.inertia_per_dof, max_natural_freq,
                            pair_ratio, lone_r_squared)


def median_natural_freq(blocks: Sequence[ControllerGains],
                        max_natural_freq: float = math.inf,
                        pair_ratio: float = math.inf,
                        lone_r_squared: float = 0.0) -> FloatArray | None:
    """Per DOF the median of 2 Kp / Kd over the believed blocks (`median_implied_inertia`'s).

    None unless every DOF is believed in at least one block [rad/s].
    """
    return _median_believed(blocks, ControllerGains.natural_freq, max_natural_freq,
                            pair_ratio, lone_r_squared)[0]


def believed_medians(blocks: Sequence[ControllerGains], max_natural_freq: float = math.inf,
                     pair_ratio: float = math.inf,
                     lone_r_squared: float = 0.0) -> tuple[FloatArray, FloatArray]:
    """Per DOF the medians of the inertia and of 2 Kp / Kd over the blocks believing it.

    NaN in a DOF no block believes (`median_implied_inertia` gives None then): what a read
    still says about the DOFs that are believed. Returns (inertia, natural frequency).
    """
    return (_per_dof_medians(blocks, ControllerGains.inertia_per_dof, max_natural_freq,
                             pair_ratio, lone_r_squared)[0],
            _per_dof_medians(blocks, ControllerGains.natural_freq, max_natural_freq,
                             pair_ratio, lone_r_squared)[0])


def _median_believed(blocks: Sequence[ControllerGains],
                     quantity: Callable[[ControllerGains], FloatArray],
                     max_natural_freq: float, pair_ratio: float = math.inf,
                     lone_r_squared: float = 0.0
                     ) -> tuple[FloatArray | None, NDArray[np.int64]]:
    """Per DOF the median of ``quantity`` over the blocks that believe that DOF; the counts.

    (None, counts) unless every DOF is believed in at least one block.
    """
    median, counts = _per_dof_medians(blocks, quantity, max_natural_freq, pair_ratio,
                                      lone_r_squared)
    return (median if counts.size and np.all(counts > 0) else None), counts


def _believed_blocks(blocks: Sequence[ControllerGains], max_natural_freq: float,
                     pair_ratio: float, lone_r_squared: float = 0.0
                     ) -> NDArray[np.bool_]:
    """Per block and DOF: believed (`ControllerGains.believed`), and not a disagreeing pair.

    The median of two blocks is their mean: when a turn or a move spoils one of them and it
    still passes (rao_swell 1104 at 540 s, 51 s into the first turn after start-up: yaw
    inertia 2.4e10 from two blocks against 2.6e9 from the block before the turn, the truth
    4.3e9; the dead-reckoned heading 1.3 rad off), no majority says which. A DOF that exactly
    two blocks believe, with inertias more than ``pair_ratio`` apart, is then believed by
    neither (inf: never); with three or more the median outvotes one spoilt block. Nothing
    outvotes a block that alone believes a DOF: it then needs an R² of at least
    ``lone_r_squared`` (≤ ``MIN_R_SQUARED``: no more than any block). A controller acting on
    another estimate explains 0.47–0.74 of the commands (onedof_feedback, a PID on the true
    LF pose), one acting on these estimates 0.996 in median (docs/BENCHMARKS.md, sixty-third
    session).
    """
    believed = np.array([b.believed(max_natural_freq) for b in blocks])
    if lone_r_squared > MIN_R_SQUARED and believed.size:
        strict = np.array([b.believed(max_natural_freq, lone_r_squared) for b in blocks])
        lone = believed.sum(axis=0) == 1
        believed[:, lone] = strict[:, lone]
    if math.isinf(pair_ratio):
        return believed
    inertia = np.array([b.inertia_per_dof() for b in blocks])
    for i in np.flatnonzero(believed.sum(axis=0) == 2):
        low, high = np.sort(inertia[believed[:, i], i])
        if high > pair_ratio * low:
            believed[:, i] = False
    return believed


def _per_dof_medians(blocks: Sequence[ControllerGains],
                     quantity: Callable[[ControllerGains], FloatArray],
                     max_natural_freq: float, pair_ratio: float = math.inf,
                     lone_r_squared: float = 0.0
                     ) -> tuple[FloatArray, NDArray[np.int64]]:
    """Per DOF the median of ``quantity`` over the blocks believing it (NaN: none); counts."""
    if not blocks:
        return np.zeros(0), np.zeros(0, dtype=np.int64)
    believed = _believed_blocks(blocks, max_natural_freq, pair_ratio, lone_r_squared)
    counts = believed.sum(axis=0).astype(np.int64)
    values = np.array([quantity(b) for b in blocks])
    median = np.array([float(np.median(values[believed[:, i], i])) if counts[i] else math.nan
                       for i in range(believed.shape[1])])
    return median, counts


def fitted_damping_scale(natural_freq: ArrayLike, damping_rate: ArrayLike) -> FloatArray:
    """(1 + f / (2 ω_r))² per DOF: M / M_r when the fitted damping *force* makes the loop critical.

    The read (`ControllerGains.implied_inertia`) gives M_r = Kd² / (4 Kp) and ω_r = 2 Kp / Kd
    (``natural_freq``). A window's fit with the read gain 1/M_r finds a damping rate f
    (``damping_rate``); what the data fix is the damping force per velocity D = f M_r (and the
    steady gain G / f), not f itself: with a gain k × too large the fitted rate comes out k ×
    too large (rao_supply's loop on the true LF pose, read gain 1.12 / 1.24 / 1.59× in surge /
    sway / yaw: fitted rates 2.1 / 2.0 / 1.6× the simulator's; docs/BENCHMARKS.md, fifty-fifth
    session). A PID designed as Kd = 2 ζ ω_n M − D (the MSS design with the vessel's damping
    taken off, `sim_ros.control.pid`) makes M s² + (Kd + D) s + Kp critical, so M = (Kd + D)² /
    (4 Kp) = M_r (1 + D / Kd)² = M_r (1 + f / (2 ω_r))² (Kd = 2 ω_r M_r). Unlike
    `damping_corrected_inertia`, which takes f as the vessel's own rate and is steep near
    f = ω_r / 2, this is smooth in f and exact for the simulator's yaw (fitted f 0.14 1/s, ω_r
    0.255 rad/s: × 1.62, the true 1/0.61). Non-finite or negative rates or frequencies: 1.
    """
    freq = np.asarray(natural_freq, dtype=np.float64)
    rate = np.asarray(damping_rate, dtype=np.float64)
    if freq.shape != rate.shape:
        raise ValueError(f'natural_freq and damping_rate must have one entry per DOF, got '
                         f'shapes {freq.shape} and {rate.shape}')
    with np.errstate(divide='ignore', invalid='ignore'):
        ratio = np.where(np.isfinite(rate) & (rate > 0.0) & np.isfinite(freq) & (freq > 0.0),
                         rate / (2.0 * freq), 0.0)
    scale: FloatArray = (1.0 + ratio) ** 2
    return scale


def damping_corrected_inertia(inertia: ArrayLike, natural_freq: ArrayLike,
                              damping_rate: ArrayLike) -> FloatArray:
    """The inertia under which the controller *and the vessel's own damping* are critical.

    The read (`ControllerGains.implied_inertia`) assumes the controller's Kd alone damps the
    loop: M_r = Kd² / (4 Kp). A controller designed as the MSS DP PID, Kd = 2 ζ ω_n M − D
    (`sim_ros.control.pid.gains_from_bandwidth`; Fossen 2011 §12.2.6 with the vessel's linear
    damping D taken off), makes the closed loop M s² + (D + Kd) s + Kp critical instead, and
    M_r = M (1 − D / (2 ω_n M))²: 0.61 M in yaw for the supply vessel (T = M/D = 11.5 s, ω_n =
    0.2 rad/s), and a dead reckoning that turns 1.6× too fast (docs/BENCHMARKS.md, fifty-third
    session). With the read's ω_r = 2 Kp / Kd (``natural_freq``; Kd = 2 ω_r M_r, Kp = ω_r²
    M_r) and the vessel's damping rate f = D / M (``damping_rate``, e.g. the vessel memory's
    −F_ii), (Kd + f M)² = 4 Kp M gives, with x = M / M_r and a = f / ω_r,
    a² x² − 4 (1 − a) x + 4 = 0, whose smaller root x = 2 / ((1 − a) + √(1 − 2 a)) is 1 at
    a = 0 (no damping: the read as it is). Above a = 1/2 no inertia makes the loop critical
    (the damping alone over-damps it); a is clipped there (x = 4, the closest to critical).
    Negative or non-finite rates count as 0. Per DOF; a new array [kg, kg, kg·m²].
    """
    m_r = np.array(inertia, dtype=np.float64)
    freq = np.asarray(natural_freq, dtype=np.float64)
    rate = np.asarray(damping_rate, dtype=np.float64)
    if not (m_r.shape == freq.shape == rate.shape):
        raise ValueError(f'inertia, natural_freq and damping_rate must have one entry per DOF, '
                         f'got shapes {m_r.shape}, {freq.shape}, {rate.shape}')
    with np.errstate(divide='ignore', invalid='ignore'):
        a = np.where(np.isfinite(rate) & (rate > 0.0) & np.isfinite(freq) & (freq > 0.0),
                     rate / freq, 0.0)
    a = np.clip(a, 0.0, 0.5)
    result: FloatArray = m_r * 2.0 / ((1.0 - a) + np.sqrt(1.0 - 2.0 * a))
    return result


def difference_velocity(poses: ArrayLike, sample_time: float, filter_time: float) -> FloatArray:
    """The body velocity a DP PID differentiates from the poses it is given.

    ν_k = R(ψ_k)ᵀ v_k with v_k = v_{k−1} + α ((η_k − η_{k−1}) / h − v_{k−1}), v_0 = 0: the
    finite difference through the first-order low-pass 1/(T_v s + 1), exactly discretized (α =
    1 − e^{−h/T_v}), as `sim_ros.control.pid.pid_step` (MSS ``PIDnonlinearMIMO.m``) computes
    the D term's velocity when it is given no measured one. ``poses`` (m, n), n = 1 or 3
    (heading unwrapped, so no step wraps), ``sample_time`` h and ``filter_time`` T_v [s], both
    > 0. Returns (m, n) [m/s, m/s, rad/s]; 1 DOF: v itself.
    """
    eta = as_series(poses, 'poses')
    if not (math.isfinite(sample_time) and sample_time > 0.0 and math.isfinite(filter_time)
            and filter_time > 0.0):
        raise ValueError(f'sample_time and filter_time must be finite and > 0 [s], got '
                         f'{sample_time} and {filter_time}')
    steps = np.zeros_like(eta)
    steps[1:] = np.diff(eta, axis=0) / sample_time
    alpha = 1.0 - math.exp(-sample_time / filter_time)
    velocity = np.asarray(lfilter([alpha], [1.0, alpha - 1.0], steps, axis=0), dtype=np.float64)
    return earth_to_body(eta, velocity, eta.shape[1])


def fit_controller_gains(poses: ArrayLike, twists: ArrayLike, forces: ArrayLike,
                         sample_time: float, highpass_time: float = HIGHPASS_TIME,
                         max_shift: int = MAX_SHIFT, run_starts: Sequence[int] = (),
                         earth_highpass: bool = False,
                         stiffness_frame: str = 'body') -> ControllerGains:
    """Least squares of the high-passed thrust on −(body-frame pose), −ν and −∫pose, per DOF.

    The series may be several contiguous runs one after the other (``run_starts``): each run is
    high-passed, integrated and shifted on its own, so no moving mean, integral or shift crosses
    a break, and the runs are pooled into one regression with one shift.

    Args:
        poses: the estimates the controller was given, shape (m, n), n = 1 or 3 (heading
            unwrapped), uniform sample time within a run.
        twists: their body velocities ν, shape (m, n).
        forces: the commanded body-frame thrust at the same instants, shape (m, n).
        sample_time: h [s].
        highpass_time: window of the moving mean removed from every signal [s].
        max_shift: largest shift of the thrust against the estimates tried [samples].
        run_starts: the row where each run after the first starts, increasing, in (0, m);
            empty: one run.
        earth_highpass: 3 DOF: high-pass the pose, its integral, the velocity and the thrust in
            the earth frame (where the setpoint, the integrator's force and the environment are
            constant) and rotate them into the body frame afterwards; False: rotate first, as
            before the forty-seventh session. In a turn away from the setpoint's origin the
            body-frame pose R(ψ)ᵀη swings with ψ and the body-frame moving mean cannot take the
            setpoint out (rao_supply, 45° turn: sway inertia read 16× too large; earth frame
            0.7–0.8×, docs/BENCHMARKS.md, forty-seventh session). 1 DOF: no difference.
        stiffness_frame: 3 DOF, the frame the controller's Kp and Ki act in (`STIFFNESS_FRAMES`).
            'body': per DOF as above. 'earth': τ = −R(ψ)ᵀ (Kp e + Ki ∫e) − Kd ν with diagonal
            Kp and Ki on the earth-frame error e = η − η_d, surge and sway in one least squares
            (their rows share Kp_N, Kp_E); the yaw row as in 'body'. A PID designed so, Kp_i =
            M_ii ω_n², has in the body frame the stiffness R(ψ)ᵀ Kp R(ψ): at ψ = 90° surge sees
            Kp_E = M_22 ω_n², and Kd_u² / (4 Kp) reads M_11² / M_22 (0.6 M_11 on the supply
            vessel), sway M_22² / M_11 (1.67 M_22) (docs/BENCHMARKS.md, fifty-fifth session).
            'auto': both, the one whose R² summed over the DOFs is larger. 1 DOF: 'body'.

    Raises:
        ValueError: bad shapes, non-finite values, bad run starts, a run shorter than
            ``MIN_SAMPLES`` + 2 ``max_shift`` samples or a bad sample time: pass longer, clean,
            uniformly sampled runs.
    """
    eta = as_series(poses, 'poses')
    nu = as_series(twists, 'twists')
    tau = as_series(forces, 'forces')
    n = eta.shape[1]
    if n not in (1, 3) or nu.shape != eta.shape or tau.shape != eta.shape:
        raise ValueError(f'poses, twists and forces must all have shape (m, 1) or (m, 3), got '
                         f'{eta.shape}, {nu.shape} and {tau.shape}')
    if not (np.isfinite(sample_time) and sample_time > 0.0 and highpass_time > sample_time):
        raise ValueError(f'sample_time must be > 0 and highpass_time > sample_time [s], got '
                         f'{sample_time} and {highpass_time}')
    if stiffness_frame not in STIFFNESS_FRAMES:
        raise ValueError(f'stiffness_frame must be one of {STIFFNESS_FRAMES}, got '
                         f'{stiffness_frame!r}')
    frames = ('body',) if n != 3 else ('body', 'earth') if stiffness_frame == 'auto' else \
        (stiffness_frame,)
    m = eta.shape[0]
    bounds = np.r_[0, np.array(run_starts, dtype=np.int64).reshape(-1), m]
    if np.any(np.diff(bounds) <= 0):
        raise ValueError(f'run_starts must increase within (0, {m}), got {list(run_starts)}')
    need = MIN_SAMPLES + 2 * max_shift
    if np.any(np.diff(bounds) < need):
        raise ValueError(f'runs of {np.diff(bounds).tolist()} samples: a run with fewer than '
                         f'{need} is too few to read controller gains: use longer runs')
    window = max(3, int(round(highpass_time / sample_time)))
    # per run: high-passed position, integral, velocity, thrust (body frame); with an earth
    # stiffness also the earth-frame high-passed position and integral and the heading
    runs: list[tuple[FloatArray, ...]] = []
    for first, end in zip(bounds[:-1].tolist(), bounds[1:].tolist(), strict=True):
        pose = eta[first:end]
        run: tuple[FloatArray, ...]
        if earth_highpass and n == 3:
            run = _earth_highpassed(pose, nu[first:end], tau[first:end], sample_time, window)
        else:
            body = earth_to_body(pose, pose, n)  # R(ψ)ᵀ[N, E], ψ: PD's error
            run = (_highpass(body, window),
                   _highpass(np.cumsum(body, axis=0) * sample_time, window),
                   _highpass(nu[first:end], window), _highpass(tau[first:end], window))
        if 'earth' in frames:
            run = (*run, _highpass(pose, window),
                   _highpass(np.cumsum(pose, axis=0) * sample_time, window), pose[:, 2:])
        runs.append(run)
    best: ControllerGains | None = None
    for shift in range(-max_shift, max_shift + 1):
        # thrust[k + shift] was computed from the estimate at k, both in the same run
        parts = []
        for run in runs:
            k = run[3].shape[0]
            lo, hi = max(0, -shift), min(k, k - shift)
            parts.append(tuple(column[lo + shift:hi + shift] if j == 3 else column[lo:hi]
                               for j, column in enumerate(run)))
        columns = [np.concatenate(column) for column in zip(*parts, strict=True)]
        position, integral, velocity, thrust = columns[:4]
        for frame in frames:
            gains = _fit_pid(position, integral, velocity, thrust, shift) if frame == 'body' \
                else _fit_pid_earth(position, integral, velocity, thrust, columns[4], columns[5],
                                    columns[6], shift)
            if best is None or float(np.sum(gains.r_squared)) > float(np.sum(best.r_squared)):
                best = gains
    assert best is not None
    return best


def read_controller_gains(poses: ArrayLike, twists: ArrayLike, forces: ArrayLike,
                          sample_time: float, *, difference_times: Sequence[float] = (),
                          lead: int = 0, run_starts: Sequence[int] = (),
                          earth_highpass: bool = False,
                          stiffness_frame: str = 'body') -> ControllerGains:
    """`fit_controller_gains` with the D term on the twist, or on the poses' own difference.

    A DP controller may take its D term from the published twist (lf_odom) or differentiate the
    pose it is given (`difference_velocity`, a filter time T_v of its own: `dp_controller`'s
    default, 1 s). The second explains the commands on the twist only in part (at most 0.97
    per block and DOF, rao_supply) and reads the inertia wrong (0.13–0.34× on a synthetic MSS
    PID with T_v 0.5–5 s), and on the difference with another T_v than its own wrong too
    (0.03–3.3×; docs/BENCHMARKS.md, sixty-fourth session). So each T_v of the increasing grid
    ``difference_times`` [s] is fitted as the velocity (``twists`` replaced), then the best
    one's T_v refined by a bounded search in log T_v between its grid neighbours (beyond a grid
    end: ``DIFFERENCE_SEARCH_FACTOR``), and the fit with the largest R² summed over the DOFs,
    the twist's or a difference's, is returned (``difference_time`` says which). Empty grid:
    `fit_controller_gains` on the twist alone.

    Args:
        poses: the estimates the controller was given, (lead + m, n).
        twists: their published body velocities, (m, n): the stretch read.
        forces: the commands, (m, n), the stretch read.
        sample_time: h [s].
        difference_times: the grid of T_v [s] tried (empty: the twist only).
        lead: the first ``lead`` rows of ``poses`` only warm the difference's filter up (the
            stretch before the one read, in the same run: the controller's filter was warm).
        run_starts: as `fit_controller_gains` (rows of the stretch read); the difference
            restarts at each.
        earth_highpass: as `fit_controller_gains`.
        stiffness_frame: as `fit_controller_gains`.

    Raises:
        ValueError: as `fit_controller_gains`; a grid that is not increasing, finite and > 0,
            or a bad ``lead``.
    """
    eta = as_series(poses, 'poses')
    grid = [float(t) for t in difference_times]
    if not all(math.isfinite(t) and t > 0.0 for t in grid) or np.any(np.diff(grid) <= 0.0):
        raise ValueError(f'difference_times must be finite, > 0 and increasing [s], got '
                         f'{list(difference_times)}')
    if not 0 <= lead < eta.shape[0]:
        raise ValueError(f'lead must be in [0, {eta.shape[0]}) rows, got {lead}')
    stretch = eta[lead:]

    def fit(velocity: ArrayLike, filter_time: float) -> ControllerGains:
        gains = fit_controller_gains(stretch, velocity, forces, sample_time,
                                     run_starts=run_starts, earth_highpass=earth_highpass,
                                     stiffness_frame=stiffness_frame)
        return replace(gains, difference_time=filter_time)

    def difference(filter_time: float) -> FloatArray:
        bounds = [0, *[int(k) for k in run_starts], stretch.shape[0]]
        parts = [difference_velocity(eta[:lead + bounds[1]], sample_time, filter_time)[lead:]]
        parts += [difference_velocity(stretch[a:b], sample_time, filter_time)
                  for a, b in zip(bounds[1:-1], bounds[2:], strict=True)]
        return np.concatenate(parts)

    def score(gains: ControllerGains) -> float:
        return float(np.sum(gains.r_squared))

    best = fit(twists, 0.0)
    if not grid:
        return best
    fits = [fit(difference(t), t) for t in grid]
    k = int(np.argmax([score(g) for g in fits]))
    low = grid[k - 1] if k > 0 else grid[0] / DIFFERENCE_SEARCH_FACTOR
    high = grid[k + 1] if k + 1 < len(grid) else grid[-1] * DIFFERENCE_SEARCH_FACTOR
    found = minimize_scalar(lambda x: -score(fit(difference(math.exp(x)), math.exp(x))),
                            bounds=(math.log(low), math.log(high)), method='bounded',
                            options={'xatol': DIFFERENCE_SEARCH_TOLERANCE})
    refined = fit(difference(math.exp(found.x)), math.exp(found.x))
    return max((best, fits[k], refined), key=score)


def _fit_pid(position: FloatArray, integral: FloatArray, velocity: FloatArray,
             thrust: FloatArray, shift: int) -> ControllerGains:
    """Per DOF the least squares of τ = −Kp x − Kd ν − Ki ∫x.

    The integral is a regressor too, else its force (in quadrature with x, against ν) is read as
    damping (−11 % Kd in yaw on the MSS PID).
    """
    n = position.shape[1]
    stiffness, damping, r_squared = np.zeros(n), np.zeros(n), np.zeros(n)
    for i in range(n):
        phi = -np.column_stack([position[:, i], velocity[:, i], integral[:, i]])
        y = thrust[:, i]
        total = float(np.sum(y ** 2))
        if total <= 0.0 or not np.all(np.any(phi != 0.0, axis=0)):
            continue
        coef, *_ = np.linalg.lstsq(phi, y, rcond=None)
        stiffness[i], damping[i] = coef[0], coef[1]
        r_squared[i] = 1.0 - float(np.sum((y - phi @ coef) ** 2)) / total
    return ControllerGains(stiffness, damping, r_squared, shift)


def _fit_pid_earth(position: FloatArray, integral: FloatArray, velocity: FloatArray,
                   thrust: FloatArray, earth_position: FloatArray, earth_integral: FloatArray,
                   heading: FloatArray, shift: int) -> ControllerGains:
    """3 DOF: the least squares of τ = −R(ψ)ᵀ (Kp e + Ki ∫e) − Kd ν with Kp, Ki diagonal.

    Surge and sway in one regression on the earth-frame north / east errors ``earth_position``
    and their integrals ``earth_integral`` (high-passed) turned by the heading ψ at each sample
    (unknowns Kp_N, Kp_E, Kd_u, Kd_v, Ki_N, Ki_E); R² per DOF from that fit's residuals in its
    row. Yaw on its own, as `_fit_pid` (a rotation about the down axis leaves it alone).
    """
    psi = heading[:, 0]
    c, s = np.cos(psi), np.sin(psi)
    e_n, e_e = earth_position[:, 0], earth_position[:, 1]
    i_n, i_e = earth_integral[:, 0], earth_integral[:, 1]
    zero = np.zeros_like(psi)
    surge = np.column_stack([c * e_n, s * e_e, velocity[:, 0], zero, c * i_n, s * i_e])
    sway = np.column_stack([-s * e_n, c * e_e, zero, velocity[:, 1], -s * i_n, c * i_e])
    phi = -np.vstack([surge, sway])
    y = np.concatenate([thrust[:, 0], thrust[:, 1]])
    stiffness, damping, r_squared = np.zeros(3), np.zeros(3), np.zeros(3)
    rows = psi.shape[0]
    if np.all(np.any(phi != 0.0, axis=0)):
        coef, *_ = np.linalg.lstsq(phi, y, rcond=None)
        stiffness[:2], damping[:2] = coef[:2], coef[2:4]
        residual = y - phi @ coef
        for i in range(2):
            part = slice(i * rows, (i + 1) * rows)
            total = float(np.sum(y[part] ** 2))
            if total > 0.0:
                r_squared[i] = 1.0 - float(np.sum(residual[part] ** 2)) / total
    yaw = _fit_pid(position[:, 2:], integral[:, 2:], velocity[:, 2:], thrust[:, 2:], shift)
    stiffness[2], damping[2], r_squared[2] = yaw.stiffness[0], yaw.damping[0], yaw.r_squared[0]
    return ControllerGains(stiffness, damping, r_squared, shift, 'earth')


def _earth_highpassed(eta: FloatArray, nu: FloatArray, tau: FloatArray, sample_time: float,
                      window: int) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """3 DOF: (position, integral, velocity, thrust) high-passed in the earth frame, in the body.

    Each signal is turned into the earth frame (the pose already is; ν and τ by R(ψ)), its
    moving mean removed there, and the rest turned into the body frame by R(ψ)ᵀ at its sample.
    """
    def body(earth: FloatArray) -> FloatArray:
        return earth_to_body(eta, _highpass(earth, window), 3)

    return (body(eta), body(np.cumsum(eta, axis=0) * sample_time),
            body(body_to_earth(eta, nu)), body(body_to_earth(eta, tau)))


def _highpass(values: FloatArray, window: int) -> FloatArray:
    """Values minus their centred moving mean over ``window`` samples (edges: nearest)."""
    result: FloatArray = values - uniform_filter1d(values, window, axis=0, mode='nearest')
    return result

