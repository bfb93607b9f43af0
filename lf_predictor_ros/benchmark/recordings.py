"""Fair recordings: the data every open-loop score is computed on, with where it came from.

A recording is one simulated run of a scenario on the estimators' grid h, together with its
`Provenance`: scenario, seed, duration, and **how the thrust was made**:

| loop | thrust | scored? |
|---|---|---|
| ``open`` | the scenario's open-loop excitation (no controller) | yes |
| ``estimator`` | the DP PID fed a causal estimator's output (``estimator`` names it) | yes |
| ``truth_lf`` | the DP PID fed the true LF pose | **never** |

Why: with the PID on the true LF pose the recorded thrust is a noise-free function of the truth,
and any regression on it (the predictor's force regressors included) looks brilliant. Such a
recording is refused twice before scoring: by its provenance (`check_scorable`) and by the
data itself (`leak_check`: a linear map from the thrust alone, fitted in-sample by least squares
on the truth, must stay clearly worse than the best causal estimator on every DOF; the suite
always includes the oracle Kalman filter and the recording loop's own estimator in that set,
since a fair thrust carries no more than the measurements and the model do). The data test
applies to feedback loops only: an open-loop excitation is computed from nothing, and a
thrust-only map that predicts the motion well there measures the vessel's dynamics, not a leak.

The grid arrays are those the predictor node builds (`InputAligner` with ``average_poses``): the
measured pose is the mean of the sensor poses of each interval h, thrust, truth and ω0 those of
the grid instant.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from lf_predictor_ros.benchmark.stability import ABORT_EXCURSION
from lf_predictor_ros.core.alignment import block_mean_poses, mean_pose
from lf_predictor_ros.core.heading import wrap_angle
from sim_ros.simulation import (
    ClosedLoopRun,
    Scenario,
    SimRecord,
    VelocityEstimate,
    simulate,
    simulate_in_loop,
)

FloatArray = NDArray[np.float64]
LOOPS = ('open', 'estimator', 'truth_lf')
SCORABLE_LOOPS = ('open', 'estimator')
# leak check: thrust-only regressors (LEAK_LAGS lags and first-order low-passes of the body-frame
# thrust) and the share of the best causal estimator's RMSE the thrust-only fit must stay above on
# every DOF. Measured on supply_closed_loop (seeds 2 and 5, 1200–3600 s): fed the truth, the fit
# reaches 0.01–0.06 of the tuned observer's RMSE; on loops closed on the observer 0.63–1.13 (a
# filter of the loop estimator's own history, fitted on the truth, can undo part of its lag).
LEAK_LAGS = 4
LEAK_TIME_CONSTANTS = (3.0, 10.0, 30.0, 100.0, 300.0, 1000.0)  # [s]
LEAK_FACTOR = 0.35
# samples per fitted coefficient below which an in-sample fit flatters itself (the RMSE of a
# least-squares fit shrinks by about √(1 − p/n)): shorter scored records skip the data test
LEAK_MIN_SAMPLES_PER_COLUMN = 20


class LeakError(ValueError):
    """A recording whose thrust encodes the truth (or whose origin is unknown) was to be scored."""


@dataclass(frozen=True)
class Provenance:
    """Where a recording came from; part of the data set, checked before any score."""

    scenario: str
    seed: int
    duration: float  # [s] simulated
    sample_time: float  # [s] grid h of the arrays
    loop: str  # one of LOOPS
    estimator: str | None = None  # the estimator in the recording loop (loop == 'estimator')

    def __post_init__(self) -> None:
        """Validate the loop kind and that an estimator loop names its estimator."""
        if self.loop not in LOOPS:
            raise ValueError(f'loop must be one of {LOOPS}, got {self.loop!r}')
        if (self.loop == 'estimator') != (self.estimator is not None):
            raise ValueError("an 'estimator' loop must name its estimator, other loops must not")

    def label(self) -> str:
        """Short text for tables: 'open loop' / 'loop on observer' / 'loop on truth (LEAKS)'."""
        if self.loop == 'open':
            return 'open loop'
        if self.loop == 'estimator':
            return f'loop on {self.estimator}'
        return 'loop on the true LF pose (leaks)'

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {'scenario': self.scenario, 'seed': self.seed, 'duration': self.duration,
                'sample_time': self.sample_time, 'loop': self.loop, 'estimator': self.estimator}


@dataclass(frozen=True)
class Recording:
    """Grid arrays of one run and their provenance (arrays (n,) or (n, 3), oldest first)."""

    provenance: Provenance
    t: FloatArray  # [s]
    y: FloatArray  # measured pose, interval mean [m, m, rad]
    u: FloatArray  # applied thrust, body frame [N, N, N·m]
    truth: FloatArray  # true LF pose [m, m, rad]
    omega: FloatArray  # true wave peak frequency ω0 [rad/s]
    # the full-rate run of an 'estimator' recording: it *is* that estimator's closed loop
    loop_run: ClosedLoopRun | None = field(default=None, repr=False, compare=False)
    # the simulator run at the sensor rate the grid arrays were decimated from (`sim_bag`)
    full_rate: SimRecord | None = field(default=None, repr=False, compare=False)
    # first-order wave motion η_w = true pose − true LF pose of the grid instant [m, m, rad]
    # (heading wrapped); None where unknown. For `seen_truth`, not an estimator input.
    wave: FloatArray | None = field(default=None, repr=False, compare=False)

    def data(self) -> dict[str, FloatArray]:
        """The arrays as the dict the estimators' runners take (t, y, u, truth, omega)."""
        return {'t': self.t, 'y': self.y, 'u': self.u, 'truth': self.truth, 'omega': self.omega}


def grid_rows(stride: int) -> slice:
    """The sensor samples at the grid instants: the last of every ``stride`` (t = h, 2h, …)."""
    if stride < 1:
        raise ValueError(f'stride must be >= 1 sensor samples, got {stride}')
    return slice(stride - 1, None, stride)


def decimate(record: SimRecord, stride: int) -> dict[str, FloatArray]:
    """A simulator record on the grid h = stride · sensor period (module docstring)."""
    sl = grid_rows(stride)
    return {'t': record.t[sl], 'y': block_mean_poses(record.measured_pose, stride),
            'u': record.thrust[sl], 'truth': record.truth_lf_pose[sl],
            'omega': record.wave_peak_freq[sl], 'wave': wave_motion(record)[sl]}


def wave_motion(record: SimRecord) -> FloatArray:
    """η_w = truth_pose − truth_lf_pose per sample [m, m, rad], the heading difference wrapped."""
    out = np.array(record.truth_pose - record.truth_lf_pose, dtype=np.float64)
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def grid_stride(scenario: Scenario, sample_time: float) -> int:
    """Sensor samples per grid interval; h must be a whole multiple of the sensor period."""
    ratio = sample_time / scenario.sample_time
    if ratio < 1.0 - 1e-9 or abs(ratio - round(ratio)) > 1e-9:
        raise ValueError(f'grid h = {sample_time} s must be a whole multiple of the scenario '
                         f'sensor period {scenario.sample_time} s')
    return int(round(ratio))


class GridInput:
    """A loop's estimator fed as the predictor node feeds it: one call per grid interval h.

    Called by `simulate_in_loop` at every sensor sample; every ``stride``-th call it passes
    ``step(t, mean pose of the interval, thrust of the instant, true ω0)`` and returns its
    output; in between it returns the last one (the PID holds it). Before the first estimate the
    measurement itself is returned.
    """

    def __init__(self, step: Callable[[float, FloatArray, FloatArray, float], FloatArray],
                 schedule: Callable[[float], float], stride: int) -> None:
        """``step`` is the estimator (e.g. `StreamingEstimator.step`), ``schedule`` the true ω0."""
        self.step = step
        self.schedule = schedule
        self.stride = stride
        self._poses: list[FloatArray] = []
        self._held: FloatArray | None = None

    def steps_next(self) -> bool:
        """True if the next sensor sample completes a grid interval (``step`` will run)."""
        return len(self._poses) + 1 == self.stride

    def __call__(self, t: float, pose: FloatArray, thrust: FloatArray) -> FloatArray:
        """The estimate to hold after this sensor sample."""
        self._poses.append(pose)
        if len(self._poses) == self.stride:
            mean = mean_pose(np.array(self._poses))
            self._poses = []
            self._held = self.step(t, mean, thrust, self.schedule(t))
        return pose if self._held is None else self._held


def run_loop(scenario: Scenario, seed: int, duration: float | None, sample_time: float,
             step: Callable[[float, FloatArray, FloatArray, float], FloatArray], *,
             velocity: VelocityEstimate | None = None,
             command: Callable[[float, FloatArray], object] | None = None) -> ClosedLoopRun:
    """The scenario's DP loop closed on ``step`` (an estimator) fed one grid sample per h.

    The PID runs once per estimate and its command is held, as `dp_controller` does on each
    /lf_pose message in the DDS pipeline; the run stops at `stability.ABORT_EXCURSION`.
    ``velocity`` (default None: D term from the PID's finite difference, unchanged results): the
    estimator's body-frame LF velocity [u, v, r] for its latest output, or None when it has none
    (e.g. ``lambda: stream.estimator.velocity``); the PID takes its D term from it, as
    `dp_controller` with ``velocity_source: odometry`` does from /lf_odom
    (`simulate_in_loop`'s ``velocity``; it is read after every sensor sample, so it must return
    the value of the last ``step``). ``command``: called before each ``step`` with (t, the PID's
    command for the estimate valid at t), the ``thrust_command`` topic of the DDS pipeline.
    """
    grid = GridInput(step, scenario.waves.peak_freq, grid_stride(scenario, sample_time))

    def grid_command(t: float, tau: FloatArray) -> None:
        if command is not None and grid.steps_next():
            command(t, tau)

    return simulate_in_loop(scenario, seed, duration, grid, scenario.sample_time,
                            abort_excursion=ABORT_EXCURSION, pid_period=sample_time,
                            velocity=velocity, command=None if command is None else grid_command)


def record(scenario: Scenario, seed: int, duration: float | None, sample_time: float,
           loop_estimator: str | None,
           make_step: Callable[[str], Callable[[float, FloatArray, FloatArray, float], FloatArray]]
           | None = None, *, truth_fed: bool = False) -> Recording:
    """Simulate one recording of ``scenario`` on the grid ``sample_time`` (module docstring).

    Scenarios without a controller are recorded open loop. With a controller, the loop is
    closed on ``loop_estimator`` (built by ``make_step(name)``, fed every h like the node) and
    the PID runs once per h, as in the DDS pipeline. ``truth_fed`` records the leaking kind
    instead (PID on the true LF pose): only for demonstrating the leak check.
    """
    stride = grid_stride(scenario, sample_time)
    total = scenario.duration if duration is None else float(duration)
    if not scenario.controller.enabled:
        provenance = Provenance(scenario.name, seed, total, sample_time, 'open')
        raw = simulate(scenario, seed=seed, duration=total)
    elif truth_fed:
        provenance = Provenance(scenario.name, seed, total, sample_time, 'truth_lf')
        raw = simulate(scenario, seed=seed, duration=total, controller=True, feedback='truth_lf')
    else:
        if loop_estimator is None or make_step is None:
            raise ValueError(f'scenario {scenario.name!r} has a DP controller: name the causal '
                             'estimator to close the recording loop on (e.g. observer)')
        run = run_loop(scenario, seed, total, sample_time, make_step(loop_estimator))
        if run.aborted_at is not None:
            raise ValueError(f'the recording loop of {scenario.name!r} seed {seed} on '
                             f'{loop_estimator!r} diverged at t = {run.aborted_at:.0f} s: '
                             'choose a stable loop estimator')
        provenance = Provenance(scenario.name, seed, total, sample_time, 'estimator',
                                loop_estimator)
        return _recording(provenance, run.record, stride, run)
    return _recording(provenance, raw, stride)


def _recording(provenance: Provenance, raw: SimRecord, stride: int,
               run: ClosedLoopRun | None = None) -> Recording:
    grid = decimate(raw, stride)
    return Recording(provenance, grid['t'], grid['y'], grid['u'], grid['truth'], grid['omega'],
                     run, raw, grid.get('wave'))


def check_scorable(recording: Recording, scenario: str | None = None,
                   seed: int | None = None) -> None:
    """Raise `LeakError` unless the recording's provenance allows scoring (and matches)."""
    prov = recording.provenance
    if prov.loop not in SCORABLE_LOOPS:
        raise LeakError(f'recording {prov.scenario!r} seed {prov.seed} was made with the DP loop '
                        f'on the true LF pose: its thrust encodes the truth, so it is never '
                        'scored; record it with the loop closed on a causal estimator')
    if scenario is not None and prov.scenario != scenario:
        raise LeakError(f'recording is of scenario {prov.scenario!r}, not {scenario!r}')
    if seed is not None and prov.seed != seed:
        raise LeakError(f'recording is of seed {prov.seed}, not {seed}')


def _continuous(pose: FloatArray, ndof: int) -> FloatArray:
    out = np.array(pose[:, :ndof], dtype=np.float64)
    if ndof == 3:
        out[:, 2] = np.unwrap(out[:, 2])
    return out


def thrust_features(u: FloatArray, sample_time: float, lags: int = LEAK_LAGS,
                    time_constants: Sequence[float] = LEAK_TIME_CONSTANTS) -> FloatArray:
    """Causal regressors of the thrust alone (n, ndof·(lags + len(time_constants))).

    Per force channel: u[k], u[k−1], …, u[k−lags+1] and the outputs of first-order low-passes
    1/(T s + 1) for each T in ``time_constants`` [s] (exact discretization, zero initial state).
    Together they span the inverse of a PID (a band-pass with poles at the PID's zeros, seconds
    to minutes) with few columns, so an in-sample fit cannot win by over-fitting noise.
    """
    n, channels = u.shape
    blocks = []
    padded = np.vstack([np.repeat(u[:1], lags - 1, axis=0), u]) if lags > 1 else u
    for lag in range(lags):
        blocks.append(padded[lags - 1 - lag:lags - 1 - lag + n])
    for time_constant in time_constants:
        alpha = math.exp(-sample_time / time_constant)
        blocks.append(signal.lfilter([1.0 - alpha], [1.0, -alpha], u, axis=0))
    return np.asarray(np.hstack(blocks), dtype=np.float64).reshape(n, -1)


def thrust_only_rmse(u: FloatArray, truth: FloatArray, ndof: int, sample_time: float,
                     begin: int = 0) -> FloatArray:
    """RMSE per DOF of the best linear map from thrust alone to the true LF pose (in-sample).

    Regressors: `thrust_features` of the ndof force channels and a constant; least squares per
    DOF over the samples k ≥ begin. No position enters. If the thrust was computed from the truth
    by a linear controller (PID), this map inverts the controller and comes close to the truth;
    if it was computed from an estimate, it can at best reproduce that estimate.
    """
    if u.shape != truth.shape or u.ndim != 2 or u.shape[1] != 3:
        raise ValueError(f'u and truth must both be (n, 3), got {u.shape} and {truth.shape}')
    features = thrust_features(u[:, :ndof], sample_time)[begin:]
    if features.shape[0] < LEAK_MIN_SAMPLES_PER_COLUMN * features.shape[1]:
        raise ValueError(f'the leak check needs >= '
                         f'{LEAK_MIN_SAMPLES_PER_COLUMN * features.shape[1]} samples after the '
                         f'warm-up, got {features.shape[0]}: record longer')
    scale = np.std(features, axis=0)
    scale[scale == 0.0] = 1.0
    design = np.hstack([features / scale, np.ones((features.shape[0], 1))])
    target = _continuous(truth, ndof)[begin:]
    coef, *_ = np.linalg.lstsq(design, target, rcond=None)
    err = design @ coef - target
    if ndof == 3:
        err[:, 2] = wrap_angle(err[:, 2])
    return np.asarray(np.sqrt(np.mean(err**2, axis=0)), dtype=np.float64)


@dataclass(frozen=True)
class LeakReport:
    """Thrust-only RMSE vs the best estimator's, per DOF."""

    thrust_only_rmse: tuple[float, ...]
    best_rmse: tuple[float, ...]
    best_estimator: tuple[str, ...]
    factor: float
    checked: bool = True  # False: too few scored samples for the data test (provenance only)

    @property
    def ratios(self) -> tuple[float, ...]:
        """Thrust-only RMSE / best estimator RMSE per DOF (a leak makes one ≲ 1)."""
        return tuple(a / b if b > 0.0 else math.inf
                     for a, b in zip(self.thrust_only_rmse, self.best_rmse, strict=True))

    @property
    def leaking(self) -> bool:
        """True when the thrust alone beats ``factor`` × the best estimator's RMSE on a DOF."""
        return self.checked and any(r < self.factor for r in self.ratios)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {'thrust_only_rmse': list(self.thrust_only_rmse), 'best_rmse': list(self.best_rmse),
                'best_estimator': list(self.best_estimator), 'factor': self.factor,
                'ratios': list(self.ratios), 'leaking': self.leaking, 'checked': self.checked}


def leak_check(recording: Recording, estimator_rmse: Mapping[str, Sequence[float]], ndof: int,
               begin: int, factor: float = LEAK_FACTOR) -> LeakReport:
    """Compare the thrust-only fit with the best of ``estimator_rmse`` (name → RMSE per DOF)."""
    if not estimator_rmse:
        raise ValueError('the leak check needs the RMSE of at least one estimator')
    names = list(estimator_rmse)
    table = np.array([list(estimator_rmse[n])[:ndof] for n in names], dtype=np.float64)
    best = np.argmin(table, axis=0)
    checked = True
    try:
        only = thrust_only_rmse(recording.u, recording.truth, ndof,
                                recording.provenance.sample_time, begin)
    except ValueError:  # too short to trust an in-sample fit: the provenance check stands alone
        only, checked = np.full(ndof, math.nan), False
    return LeakReport(tuple(float(v) for v in only),
                      tuple(float(table[best[i], i]) for i in range(ndof)),
                      tuple(names[int(best[i])] for i in range(ndof)), factor, checked)


def require_fair(recording: Recording, report: LeakReport) -> None:
    """Raise `LeakError` if the provenance or the data say the thrust leaks the truth."""
    check_scorable(recording)
    if report.leaking:
        ratios = ', '.join(f'{r:.2f}' for r in report.ratios)
        raise LeakError(f'recording {recording.provenance.scenario!r} seed '
                        f'{recording.provenance.seed} ({recording.provenance.label()}): a linear '
                        f'map from the thrust alone reaches {ratios} × the best estimator '
                        f'(< {report.factor}): the thrust encodes the truth; it is not scored')


__all__ = ['LEAK_FACTOR', 'LEAK_LAGS', 'LEAK_MIN_SAMPLES_PER_COLUMN', 'LOOPS', 'GridInput',
           'LeakError', 'LeakReport', 'Provenance', 'Recording', 'check_scorable', 'decimate',
           'grid_stride', 'leak_check', 'record', 'require_fair', 'run_loop', 'thrust_only_rmse']
