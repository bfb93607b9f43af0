"""Scenario configuration and the Simulator composing the physics (ROS-free).

Time base: the simulator produces one `SimSample` per output (sensor) period `sample_time`;
inside, the vessel is integrated with RK4 at `internal_step` (sample_time must be an integer
multiple), the command is held over the period (zero-order hold), and the shaft dynamics of the
DP vessels are solved exactly between RK4 stages. Random streams are separate children of
`np.random.SeedSequence(seed)` (waves, current, wind, drift, sensor noise, sensor faults,
excitation), so one seed reproduces a run exactly and changing one source leaves the others.

Ground truth:
- `truth_pose` is the total true pose (LF motion + first-order wave motion), heading wrapped.
- `truth_lf_pose` is the low-frequency pose. With **force superposition** (thesis eq. 5.2–5.4)
  it is the pose of the *LF twin*: the vessel model driven by the same applied thrust and the
  same LF environment (current, wind, drift) but no first-order wave force. The first-order
  wave force drives a wave-frequency state integrated alongside (same RK4 step), the response
  of the vessel model linearized once, at the run's operating point (`vessels.*.wave_rates_fn`;
  thesis vessels: `vessels.wave_operating_speed` of the initial state and mean current, so the
  WF motion stays zero-mean while the vessel speeds up), and the total pose is twin + WF motion.
  For the linear DP vessels this equals integrating a second vessel with the wave force
  inside; for the thesis vessels with quadratic damping it drops the rectified (second-order)
  effects: the mean force that would otherwise make vessel and twin drift apart (see the vessels
  module docstring) and the shift of the WF mean a velocity-dependent WF damping would make;
  slowly varying drift is modelled by the drift bias.
  With **motion superposition** (Fossen 2011 §8.2.1) η = η_LF + η_w: the vessel is the LF
  motion and truth_lf_pose is η_LF itself. Without waves (or σ = 0) the two truths coincide.
- `waves.model: rao` is motion superposition too, with η_w from motion RAOs over a JONSWAP
  sea with cos-2s spreading (`physics.sea_spectrum`, `physics.rao`): η_w(t) is evaluated with
  the *current LF heading* ψ_LF(t) (relative wave direction β = θ − ψ_LF, body motion rotated
  by R(ψ_LF)), so turning the vessel changes which DOFs move. `wave_peak_freq` is the
  spectral peak ω_p = 2π/T_p (at DP speed the encounter frequency equals ω).
- `measured_pose` = total truth + sensor noise (+ outliers), heading wrapped; on a dropout the
  last valid measurement is repeated and `measured_valid` is False.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from sim_ros.control.pid import PidGains, PidState, gains_from_bandwidth, pid_step
from sim_ros.physics import excitation as exc
from sim_ros.physics import schedule as sched
from sim_ros.physics.environment import EnvironmentConfig, EnvironmentGenerator, MarkovBias
from sim_ros.physics.integrate import RatesFn, rk4_step
from sim_ros.physics.kinematics import FloatArray, rotation, wrap_angle
from sim_ros.physics.rao import RaoParams, motion_basis, motion_from_basis
from sim_ros.physics.sea_spectrum import (
    DEFAULT_FREQ_RANGE,
    WaveComponents,
    check_sea,
    discretize_sea,
    peak_frequency,
)
from sim_ros.physics.sensors import SensorConfig, check_sensor_rate, sensor_errors
from sim_ros.physics.thrusters import ThrusterConfig, allocate, generalized_thrust
from sim_ros.physics.vessels import (
    DpVessel,
    LinearModel,
    ThesisVessel,
    WaveRatesFn,
    make_vessel,
    wave_operating_speed,
)
from sim_ros.physics.waves import (
    WAVE_MODELS,
    ShapingFilter,
    WaveGenerator,
    stationary_covariance,
)

PACKAGE = 'lf_predictor_ros'
REPO_ROOT = Path(__file__).resolve().parent.parent
BLOCK = 1024  # output samples of noise generated at a time
Vec3 = tuple[float, float, float]


# ---------------------------------------------------------------------------------- scenario
SCENARIO_WAVE_MODELS = (*WAVE_MODELS, 'rao')
RAO_KEYS = ('hs', 'tp', 'gamma', 'direction', 'spreading', 'components', 'frequency_range',
            'rao')
SHAPING_KEYS = ('damping', 'sigma', 'peak_freq', 'peak_freq_resolution')
MAX_WAVE_COMPONENTS = 5000  # N·M; ~300 are plenty (cost ∝ components)


@dataclass(frozen=True)
class WaveConfig:
    """First-order waves: model, then its parameters.

    'force' / 'motion' (shaping filters): λ, σ per DOF (north, east, yaw), ω0 schedule.
    'rao' (motion RAOs over a JONSWAP sea): Hs [m], Tp [s], γ, mean direction the waves come
    from [rad, clockwise from north], cos-2s spreading exponent s (None: long-crested),
    components (N frequencies, M directions), frequency_range (ω_lo, ω_hi) / ω_p, RAO parameters.
    For 'rao' the peak_freq schedule is derived: constant ω_p = 2π/Tp (reported per sample).
    """

    model: str = 'none'  # 'force' | 'motion' | 'rao' | 'none'
    damping: float = 0.1  # λ
    sigma: Vec3 = (0.0, 0.0, 0.0)  # force: N, N, N·m; motion: m, m, rad (per √rad/s)
    peak_freq: sched.PeakFreqSchedule = field(default_factory=lambda: sched.constant(0.8))
    peak_freq_resolution: float = 1e-3  # rad/s, ω0 rounding for the discretization cache
    hs: float = 0.0  # m, significant wave height (rao)
    tp: float = 10.0  # s, peak period (rao)
    gamma: float = 3.3  # JONSWAP peak enhancement (rao)
    direction: float = 0.0  # rad, mean direction the waves come from (rao)
    spreading: float | None = None  # s of cos-2s (rao); None: long-crested
    components: tuple[int, int] = (40, 1)  # frequencies × directions (rao)
    frequency_range: tuple[float, float] = DEFAULT_FREQ_RANGE  # (ω_lo, ω_hi) / ω_p (rao)
    rao: RaoParams = field(default_factory=RaoParams)

    def __post_init__(self) -> None:
        """For 'rao': validate the sea and derive peak_freq = constant ω_p."""
        if self.model != 'rao':
            return
        n_freq, n_dir = self.components
        if not (isinstance(n_freq, int) and isinstance(n_dir, int) and n_freq >= 1
                and n_dir >= 1 and n_freq * n_dir <= MAX_WAVE_COMPONENTS):
            raise ValueError(f'waves.components must be [frequencies, directions], integers '
                             f'>= 1 with a product <= {MAX_WAVE_COMPONENTS} (e.g. [40, 9]), '
                             f'got {self.components}')
        if self.spreading is None and n_dir != 1:
            raise ValueError('waves.spreading is null (long-crested): set components to '
                             f'[{n_freq}, 1], or give a cos-2s exponent s > 0 (2–5 wind sea, '
                             '10–25 swell)')
        if self.spreading is not None and not (0.0 < self.spreading < 1000.0):
            raise ValueError(f'waves.spreading s must be in (0, 1000) (2–5 wind sea, 10–25 '
                             f'swell) or null for long-crested, got {self.spreading}')
        if not math.isfinite(self.direction):
            raise ValueError(f'waves.direction must be finite [rad], got {self.direction}')
        lo, hi = self.frequency_range
        if not (0.0 < lo < 1.0 < hi <= 10.0):
            raise ValueError(f'waves.frequency_range (ω_lo/ω_p, ω_hi/ω_p) must satisfy 0 < lo '
                             f'< 1 < hi <= 10 (default {DEFAULT_FREQ_RANGE}), got '
                             f'{self.frequency_range}')
        check_sea(self.hs, self.tp, self.gamma)  # Hs >= 0, Tp > 0, 1 <= γ <= 7
        if not (1.0 <= self.tp <= 30.0):
            raise ValueError(f'waves.tp must be a peak period in [1, 30] s, got {self.tp}')
        object.__setattr__(self, 'peak_freq', sched.constant(peak_frequency(self.tp)))


@dataclass(frozen=True)
class ExcitationConfig:
    """Open-loop excitation on τc (thesis §5.2.2)."""

    kind: str = 'none'  # 'none' | 'prbs' | 'multisine' | 'steps'
    amplitude: Vec3 = (0.0, 0.0, 0.0)
    clock_period: float = 10.0  # s, PRBS
    frequencies: tuple[float, ...] = ()  # rad/s, multisine
    table: tuple[tuple[float, ...], ...] = ()  # rows [t, τx, τy, τn], steps


SetpointRow = tuple[float, float, float, float]


@dataclass(frozen=True)
class ControllerConfig:
    """The scenario's DP controller (sim_ros.control.pid).

    `setpoint_schedule` rows [t s, north m, east m, yaw rad], times non-decreasing: from t on
    the setpoint is that row (piecewise constant; before the first row: `setpoint`). The PID's
    setpoint filter 1/(T_f s + 1) smooths the steps; heading steps are taken the short way round
    (wrapped error), so keep them within ±180° (±90° is a large DP heading change).
    """

    enabled: bool = False
    setpoint: Vec3 = (0.0, 0.0, 0.0)  # m, m, rad
    setpoint_schedule: tuple[SetpointRow, ...] = ()
    bandwidth: Vec3 = (0.1, 0.1, 0.2)  # rad/s, ω_n
    zeta: float = 1.0
    setpoint_filter_time: float = 10.0  # s, T_f
    velocity_filter_time: float = 1.0  # s, T_v
    feedback: str = 'truth_lf'  # 'truth_lf' | 'measured'
    tau_max: Vec3 | None = None  # None: the actuator limit

    def __post_init__(self) -> None:
        """Validate the setpoint schedule: rows of 4 finite numbers, ordered times >= 0."""
        rows = self.setpoint_schedule
        if any(len(row) != 4 or not all(math.isfinite(v) for v in row) for row in rows):
            raise ValueError('controller.setpoint_schedule is a list of [t_s, north_m, east_m, '
                             'yaw_rad] rows of finite numbers')
        times = [row[0] for row in rows]
        if any(t < 0.0 for t in times) or any(b < a for a, b in zip(times, times[1:],
                                                                     strict=False)):
            raise ValueError(f'controller.setpoint_schedule times must be >= 0 and '
                             f'non-decreasing, got {times}; sort the rows by time')

    def setpoint_at(self, t: float) -> FloatArray:
        """Setpoint (3,) [m, m, rad] at time t [s]: the last schedule row with time <= t."""
        value: Sequence[float] = self.setpoint
        for row in self.setpoint_schedule:
            if row[0] > t:
                break
            value = row[1:]
        return np.array(value, dtype=np.float64)

    def setpoint_series(self, times: FloatArray) -> FloatArray:
        """Setpoints (len(times), 3) at many times [s] (for metrics against the schedule)."""
        t = np.asarray(times, dtype=np.float64).reshape(-1)
        table = np.array([self.setpoint] + [row[1:] for row in self.setpoint_schedule],
                         dtype=np.float64)
        starts = np.array([row[0] for row in self.setpoint_schedule], dtype=np.float64)
        return np.asarray(table[np.searchsorted(starts, t, side='right')], dtype=np.float64)


def with_schedule_shift(controller: ControllerConfig, shift: float) -> ControllerConfig:
    """The controller with every `setpoint_schedule` time ``shift`` [s] later (a new object).

    The setpoints and everything else are unchanged; without a schedule the controller itself
    is returned. Used by the benchmark to move the manoeuvres against the estimator's own
    timing (docs/BENCHMARKS.md, twenty-first session).
    """
    if not (math.isfinite(shift) and shift >= 0.0):
        raise ValueError(f'a schedule shift must be finite and >= 0 s, got {shift!r}')
    if shift == 0.0 or not controller.setpoint_schedule:
        return controller
    rows = tuple((row[0] + shift, row[1], row[2], row[3]) for row in controller.setpoint_schedule)
    return replace(controller, setpoint_schedule=rows)


def scenario_with_schedule_shift(scenario: Scenario, shift: float) -> Scenario:
    """The scenario with its scheduled events ``shift`` [s] later (pure).

    The events: setpoint moves and turns (`with_schedule_shift`) and the wave peak frequency's
    steps and ramps (`schedule.delayed`). Nothing else changes (seeds, sea, sensors); without
    events the scenario itself is returned (the test for "nothing to move"). The benchmark
    draws the shift per seed so that its held-out seeds sample the phase between the
    predictor's trainings and the events (docs/BENCHMARKS.md, twenty-first and twenty-second
    sessions).
    """
    controller = with_schedule_shift(scenario.controller, shift)
    waves = scenario.waves
    peak_freq = sched.delayed(waves.peak_freq, shift)
    if peak_freq is not waves.peak_freq:
        waves = replace(waves, peak_freq=peak_freq)
    if controller is scenario.controller and waves is scenario.waves:
        return scenario
    return replace(scenario, controller=controller, waves=waves)


@dataclass(frozen=True)
class Scenario:
    """Everything one simulation run needs; load with `load_scenario`."""

    name: str = 'unnamed'
    description: str = ''
    vessel: str = 'onedof'  # one of sim_ros.physics.vessels.VESSEL_KINDS
    sample_time: float = 0.1  # s, output/sensor period (1–100 Hz)
    internal_step: float = 0.1  # s, RK4 step; sample_time / internal_step is an integer
    duration: float = 600.0  # s
    seed: int = 0
    initial_pose: Vec3 = (0.0, 0.0, 0.0)
    initial_velocity: Vec3 = (0.0, 0.0, 0.0)
    actuator_limit: Vec3 | None = None  # |τ| limit of the thesis vessels (DP vessels: thrusters)
    waves: WaveConfig = field(default_factory=WaveConfig)
    environment: EnvironmentConfig = field(default_factory=EnvironmentConfig)
    sensors: SensorConfig = field(default_factory=SensorConfig)
    excitation: ExcitationConfig = field(default_factory=ExcitationConfig)
    controller: ControllerConfig = field(default_factory=ControllerConfig)

    def __post_init__(self) -> None:
        """Cross-field validation with messages that say what to change."""
        make_vessel(self.vessel)
        check_sensor_rate(self.sample_time)
        if not (self.internal_step > 0.0) or self.internal_step > self.sample_time * (1 + 1e-9):
            raise ValueError(f'internal_step {self.internal_step} s must be in (0, sample_time '
                             f'= {self.sample_time} s]')
        if abs(self.substeps * self.internal_step - self.sample_time) > 1e-9 * self.sample_time:
            raise ValueError(f'sample_time {self.sample_time} s must be an integer multiple of '
                             f'internal_step {self.internal_step} s')
        if not (self.duration > 0.0):
            raise ValueError(f'duration must be > 0 s, got {self.duration}')
        if self.waves.model not in SCENARIO_WAVE_MODELS:
            raise ValueError(f'waves.model must be one of {SCENARIO_WAVE_MODELS}, got '
                             f'{self.waves.model!r}')
        if self.waves.model != 'none' and not (0.0 < self.waves.damping < 1.0):
            raise ValueError(f'waves.damping λ must be in (0, 1), typical 0.1; got '
                             f'{self.waves.damping}')
        if any(s < 0 for s in self.waves.sigma):
            raise ValueError(f'waves.sigma must be >= 0 per DOF, got {self.waves.sigma}')
        if self.excitation.kind not in exc.EXCITATION_KINDS:
            raise ValueError(f'excitation.kind must be one of {exc.EXCITATION_KINDS}')
        if self.controller.feedback not in ('truth_lf', 'measured'):
            raise ValueError("controller.feedback must be 'truth_lf' or 'measured'")
        for limit in (self.actuator_limit, self.controller.tau_max):
            if limit is not None and any(v <= 0 for v in limit):
                raise ValueError('force limits must be > 0 per DOF (or null for none)')

    @property
    def substeps(self) -> int:
        """RK4 steps per output period."""
        return max(1, round(self.sample_time / self.internal_step))

    @property
    def ndof(self) -> int:
        """1 for the 1-DOF vessel, else 3."""
        return 1 if self.vessel == 'onedof' else 3


def _vec3(value: Any, key: str) -> Vec3:
    if isinstance(value, int | float):
        value = [value] * 3
    if not isinstance(value, Sequence) or len(value) != 3:
        raise ValueError(f'{key} must be a list of 3 numbers [north/surge, east/sway, yaw]')
    return (float(value[0]), float(value[1]), float(value[2]))


def _check_keys(data: Mapping[str, Any], allowed: Sequence[str], where: str) -> None:
    unknown = sorted(set(data) - set(allowed))
    if unknown:
        raise ValueError(f'unknown key(s) {unknown} in {where}; allowed: {sorted(allowed)}')


def _schedule(data: Any) -> sched.PeakFreqSchedule:
    """peak_freq: number | {constant} | {table} | {steps: {initial, changes}} | {ramp} | preset."""
    if isinstance(data, int | float):
        return sched.constant(float(data))
    if isinstance(data, str):
        if data != 'thesis_fig_4_1':
            raise ValueError(f"unknown peak_freq preset {data!r}; use 'thesis_fig_4_1'")
        return sched.thesis_fig_4_1()
    if not isinstance(data, Mapping) or len(data) != 1:
        raise ValueError('waves.peak_freq is a number, a preset name, or one of {constant: w}, '
                         '{table: [[t, w], ...]}, {steps: {initial: w, changes: [[t, w]]}}, '
                         '{ramp: {t_start, t_end, start, end}}')
    (kind, arg), = data.items()
    if kind == 'constant':
        return sched.constant(float(arg))
    if kind == 'table':
        return sched.table(arg)
    if kind == 'steps':
        return sched.steps(float(arg['initial']), [tuple(p) for p in arg.get('changes', [])])
    if kind == 'ramp':
        return sched.ramp(float(arg['t_start']), float(arg['t_end']), float(arg['start']),
                          float(arg['end']))
    raise ValueError(f'unknown peak_freq kind {kind!r}; use constant, table, steps or ramp')


def _bias(data: Mapping[str, Any], where: str, ndim: int, default_t: float) -> MarkovBias:
    _check_keys(data, ('mean', 'std', 'time_constant'), where)
    zeros = [0.0] * ndim
    mean = [float(v) for v in data.get('mean', zeros)]
    std = [float(v) for v in data.get('std', zeros)]
    if len(mean) != ndim or len(std) != ndim:
        raise ValueError(f'{where}: mean and std need {ndim} values')
    return MarkovBias(tuple(mean), tuple(std), float(data.get('time_constant', default_t)))


def _rao_params(data: Any) -> RaoParams:
    if not isinstance(data, Mapping):
        raise ValueError('waves.rao is a mapping of RAO parameters, e.g. {length: 76.2, '
                         'yaw_gain: 1.0}; see sim_ros.physics.rao.RaoParams')
    _check_keys(data, [f.name for f in fields(RaoParams)], 'waves.rao')
    values: dict[str, Any] = {}
    for key, value in data.items():
        if key == 'order':
            if isinstance(value, bool) or not isinstance(value, int):
                raise ValueError(f'waves.rao.order must be an integer (e.g. 2), got {value!r}')
            values[key] = value
        else:
            values[key] = float(value)
    return RaoParams(**values)


def _pair(value: Any, key: str, kind: type) -> Any:
    if not isinstance(value, Sequence) or isinstance(value, str) or len(value) != 2:
        raise ValueError(f'{key} must be a list of 2 numbers')
    if kind is int and not all(isinstance(v, int) and not isinstance(v, bool) for v in value):
        raise ValueError(f'{key} must be 2 integers [frequencies, directions], got {value}')
    return (kind(value[0]), kind(value[1]))


def _wave_config(w: dict[str, Any]) -> WaveConfig:
    """The waves section: shaping-filter keys for force/motion, sea + RAO keys for rao."""
    _check_keys(w, [f.name for f in fields(WaveConfig)], 'waves')
    model = str(w.get('model', 'none'))
    if model == 'rao':
        wrong = sorted(set(w) & set(SHAPING_KEYS))
        if wrong:
            raise ValueError(f'waves.model rao takes hs, tp, gamma, direction, spreading, '
                             f'components, frequency_range, rao; {wrong} belong to the force/'
                             'motion models (ω_p comes from tp)')
        spreading = w.get('spreading')
        return WaveConfig(
            model=model, hs=float(w.get('hs', 0.0)), tp=float(w.get('tp', 10.0)),
            gamma=float(w.get('gamma', 3.3)), direction=float(w.get('direction', 0.0)),
            spreading=None if spreading is None else float(spreading),
            components=_pair(w.get('components', [40, 1 if spreading is None else 8]),
                             'waves.components', int),
            frequency_range=_pair(w.get('frequency_range', list(DEFAULT_FREQ_RANGE)),
                                  'waves.frequency_range', float),
            rao=_rao_params(w.get('rao', {})))
    wrong = sorted(set(w) & set(RAO_KEYS))
    if wrong:
        raise ValueError(f'{wrong} are keys of waves.model rao, not of {model!r}')
    return WaveConfig(
        model=model, damping=float(w.get('damping', 0.1)),
        sigma=_vec3(w.get('sigma', 0.0), 'waves.sigma'),
        peak_freq=_schedule(w.get('peak_freq', 0.8)),
        peak_freq_resolution=float(w.get('peak_freq_resolution', 1e-3)))


def _setpoint_schedule(data: Any) -> tuple[SetpointRow, ...]:
    if not isinstance(data, Sequence) or isinstance(data, str):
        raise ValueError('controller.setpoint_schedule is a list of [t_s, north_m, east_m, '
                         'yaw_rad] rows')
    rows: list[SetpointRow] = []
    for row in data:
        if not isinstance(row, Sequence) or isinstance(row, str) or len(row) != 4:
            raise ValueError(f'controller.setpoint_schedule row {row!r} must be [t_s, north_m, '
                             'east_m, yaw_rad]')
        rows.append((float(row[0]), float(row[1]), float(row[2]), float(row[3])))
    return tuple(rows)


def scenario_from_dict(data: Mapping[str, Any], name: str = 'unnamed') -> Scenario:
    """Build and validate a Scenario from a parsed YAML mapping (SI units, radians)."""
    top = [f.name for f in fields(Scenario)]
    _check_keys(data, top, 'scenario')
    kwargs: dict[str, Any] = {'name': str(data.get('name', name))}
    for key in ('description', 'vessel'):
        if key in data:
            kwargs[key] = str(data[key])
    for key in ('sample_time', 'internal_step', 'duration'):
        if key in data:
            kwargs[key] = float(data[key])
    if 'internal_step' not in data and 'sample_time' in data:
        kwargs['internal_step'] = float(data['sample_time'])
    if 'seed' in data:
        kwargs['seed'] = int(data['seed'])
    for key in ('initial_pose', 'initial_velocity'):
        if key in data:
            kwargs[key] = _vec3(data[key], key)
    if data.get('actuator_limit') is not None:
        kwargs['actuator_limit'] = _vec3(data['actuator_limit'], 'actuator_limit')
    if 'waves' in data:
        kwargs['waves'] = _wave_config(dict(data['waves']))
    if 'environment' in data:
        e = dict(data['environment'])
        _check_keys(e, [f.name for f in fields(EnvironmentConfig)], 'environment')
        kwargs['environment'] = EnvironmentConfig(
            current_speed=float(e.get('current_speed', 0.0)),
            current_direction=float(e.get('current_direction', 0.0)),
            current_variation=_bias(e.get('current_variation', {}), 'current_variation', 2,
                                    600.0),
            wind=_bias(e.get('wind', {}), 'wind', 3, 300.0),
            drift=_bias(e.get('drift', {}), 'drift', 3, 300.0))
    if 'sensors' in data:
        s = dict(data['sensors'])
        _check_keys(s, [f.name for f in fields(SensorConfig)], 'sensors')
        kwargs['sensors'] = SensorConfig(**{k: float(v) for k, v in s.items()})
    if 'excitation' in data:
        x = dict(data['excitation'])
        _check_keys(x, [f.name for f in fields(ExcitationConfig)], 'excitation')
        kwargs['excitation'] = ExcitationConfig(
            kind=str(x.get('kind', 'none')), amplitude=_vec3(x.get('amplitude', 0.0),
                                                               'excitation.amplitude'),
            clock_period=float(x.get('clock_period', 10.0)),
            frequencies=tuple(float(f) for f in x.get('frequencies', [])),
            table=tuple(tuple(float(v) for v in row) for row in x.get('table', [])))
    if 'controller' in data:
        c = dict(data['controller'])
        _check_keys(c, [f.name for f in fields(ControllerConfig)], 'controller')
        kwargs['controller'] = ControllerConfig(
            enabled=bool(c.get('enabled', False)),
            setpoint=_vec3(c.get('setpoint', 0.0), 'controller.setpoint'),
            bandwidth=_vec3(c.get('bandwidth', [0.1, 0.1, 0.2]), 'controller.bandwidth'),
            setpoint_schedule=_setpoint_schedule(c.get('setpoint_schedule', [])),
            zeta=float(c.get('zeta', 1.0)),
            setpoint_filter_time=float(c.get('setpoint_filter_time', 10.0)),
            velocity_filter_time=float(c.get('velocity_filter_time', 1.0)),
            feedback=str(c.get('feedback', 'truth_lf')),
            tau_max=None if c.get('tau_max') is None else _vec3(c['tau_max'],
                                                                'controller.tau_max'))
    return Scenario(**kwargs)


def scenario_search_dirs() -> list[Path]:
    """config/scenarios in the source tree, then in the installed share dir (if ROS is there)."""
    dirs = [REPO_ROOT / 'config' / 'scenarios']
    try:
        from ament_index_python.packages import get_package_share_directory

        dirs.append(Path(get_package_share_directory(PACKAGE)) / 'config' / 'scenarios')
    except Exception:  # noqa: BLE001 - ament index absent or package not installed
        pass
    return dirs


def load_scenario(name_or_path: str | os.PathLike[str]) -> Scenario:
    """Load a scenario by name (config/scenarios/NAME.yaml) or from a YAML file path."""
    import yaml

    text = str(name_or_path)
    path = Path(text)
    if not (text.endswith(('.yaml', '.yml')) or os.sep in text):
        candidates = [d / f'{text}.yaml' for d in scenario_search_dirs()]
        found = [c for c in candidates if c.is_file()]
        if not found:
            raise ValueError(f'scenario {text!r} not found in {[str(d) for d in candidates]}; '
                             f'available: {available_scenarios()}')
        path = found[0]
    if not path.is_file():
        raise ValueError(f'scenario file {path} does not exist')
    with open(path, encoding='utf-8') as stream:
        data = yaml.safe_load(stream)
    if not isinstance(data, Mapping):
        raise ValueError(f'scenario file {path} must hold a YAML mapping')
    try:
        return scenario_from_dict(data, name=path.stem)
    except (TypeError, KeyError) as err:
        raise ValueError(f'scenario file {path}: {err}') from err


def available_scenarios() -> list[str]:
    """Scenario names found in the search directories."""
    names = {p.stem for d in scenario_search_dirs() if d.is_dir() for p in d.glob('*.yaml')}
    return sorted(names)


# --------------------------------------------------------------------------------- simulator
@dataclass(frozen=True)
class SimSample:
    """One output sample (see docs/ARCHITECTURE.md)."""

    t: float
    measured_pose: FloatArray
    measured_valid: bool
    truth_pose: FloatArray
    truth_lf_pose: FloatArray
    thrust: FloatArray  # applied generalized force, body [N, N, N·m]
    thrust_command: FloatArray
    wave_peak_freq: float  # rad/s


def _pose(state: Sequence[float]) -> FloatArray:
    return np.array([state[0], state[1], wrap_angle(state[2])])


class Simulator:
    """Vessel + sea + sensors, stepped one output period at a time (see module docstring)."""

    def __init__(self, scenario: Scenario, seed: int | None = None) -> None:
        """Build the physics of `scenario`; `seed` overrides scenario.seed."""
        self.scenario = scenario
        self.seed = scenario.seed if seed is None else int(seed)
        streams = [np.random.default_rng(s) for s in np.random.SeedSequence(self.seed).spawn(8)]
        self.vessel = make_vessel(scenario.vessel)
        self._rates = self.vessel.rates_fn()
        self.sample_time = scenario.sample_time
        self.ndof = scenario.ndof
        self._substeps = scenario.substeps
        self._h = scenario.sample_time / self._substeps
        self._k = 0  # output samples done
        mask = np.array([1.0, 0.0, 0.0]) if self.ndof == 1 else np.ones(3)
        self._mask = mask
        state = [*scenario.initial_pose, *scenario.initial_velocity]
        if self.ndof == 1:
            state = [state[0], 0.0, 0.0, state[3], 0.0, 0.0]
        self._state: list[float] = state
        waves = scenario.waves
        sigma = np.asarray(waves.sigma) * mask
        self._wave_model = waves.model if np.any(sigma > 0) else 'none'
        self._waves: WaveGenerator | None = None
        self._sea: WaveComponents | None = None
        if waves.model == 'rao':
            self._wave_model = 'rao' if waves.hs > 0.0 else 'none'
        if self._wave_model == 'rao':
            self._sea = discretize_sea(waves.hs, waves.tp, waves.gamma, waves.direction,
                                       waves.spreading, *waves.components, streams[0],
                                       waves.frequency_range)
            self._wave_basis0: list[float] = motion_basis(self._sea, waves.rao,
                                                          np.zeros(1))[0].tolist()
        elif self._wave_model != 'none':
            step = self._h if self._wave_model == 'force' else self.sample_time
            self._waves = WaveGenerator(self._wave_model, waves.damping, sigma, waves.peak_freq,
                                        step, streams[0], waves.peak_freq_resolution)
        self._wave_initial = np.zeros(3) if self._waves is None else self._waves.output.copy()
        self._wf: list[float] | None = [0.0] * 6 if self._wave_model == 'force' else None
        if self._wf is not None and self._waves is not None:
            if isinstance(self.vessel, ThesisVessel):
                wave_rates = self.vessel.wave_rates_fn(self._wave_operating_speed())
            else:
                wave_rates = self.vessel.wave_rates_fn()
            self._rates = _with_wave_motion(self._rates, wave_rates)
            self._wf = _initial_wave_motion(self._wave_linear_model(), self._state[2],
                                            self._waves, streams[7])
            self._state = [*self._state, *self._wf]
        self._env = EnvironmentGenerator(scenario.environment, self.sample_time,
                                         (streams[1], streams[2], streams[3]))
        self._sensor_rngs = (streams[4], streams[5])
        self._excitation = self._build_excitation(streams[6])
        # actuators
        self._thrusters: ThrusterConfig | None = None
        if isinstance(self.vessel, DpVessel):
            self._thrusters = self.vessel.thrusters
            self._rpm = np.zeros(self._thrusters.thrust_coeff.shape[0])
            elapsed = np.arange(2 * self._substeps + 1) * (0.5 * self._h)
            self._decay = np.exp(-elapsed / self._thrusters.shaft_time_constant)[:, None]
        limit = scenario.actuator_limit
        self._limit = None if limit is None else np.asarray(limit, dtype=np.float64)
        self._blocks_left = 0
        self._thrust = np.zeros(3)
        self._refill()
        total, lf = self._truths(None)
        self._last_measured = total.copy()
        self.sample = SimSample(0.0, total.copy(), True, total, lf, np.zeros(3), np.zeros(3),
                                float(waves.peak_freq(0.0)))

    # ------------------------------------------------------------------ public API
    @property
    def t(self) -> float:
        """Simulated time [s] of the latest sample."""
        return self._k * self.sample_time

    def actuator_limit(self) -> FloatArray | None:
        """|τ| limit per DOF: thruster capacity (DP vessels), scenario.actuator_limit (thesis)."""
        if self._thrusters is not None:
            return self._thrusters.max_generalized_force()
        return None if self._limit is None else self._limit.copy()

    def true_model(self) -> LinearModel:
        """M and linear D (3×3); thesis vessels linearized at THESIS_OPERATING_SPEED."""
        return self.vessel.linearize()

    def wave_components(self) -> WaveComponents | None:
        """The discretized sea of `waves.model: rao` (None for the other models)."""
        return self._sea

    def excitation(self, t: float) -> FloatArray:
        """The scenario's open-loop excitation τ_exc(t) (not added by `step`)."""
        return self._excitation(t) * self._mask

    def step(self, tau_command: FloatArray) -> SimSample:
        """Advance one output period with `tau_command` (body, 3,) held; return the sample."""
        command = np.asarray(tau_command, dtype=np.float64)
        if command.shape != (3,) or not np.all(np.isfinite(command)):
            raise ValueError('tau_command must be a finite (3,) array [N, N, N·m]')
        command = command * self._mask
        if self._blocks_left == 0:
            self._refill()
        i = BLOCK - self._blocks_left
        self._blocks_left -= 1
        stages = self._actuate(command)
        h, rates = self._h, self._rates
        tail = self._lf_tail[i]
        for j in range(self._substeps):
            s0, s1, s2 = stages[2 * j], stages[2 * j + 1], stages[2 * j + 2]
            if self._wf is None:
                self._state = rk4_step(rates, self._state, h, [*s0, *tail], [*s1, *tail],
                                       [*s2, *tail])
            else:
                w0, w1, w2 = self._wave_force[i * self._substeps + j]
                self._state = rk4_step(rates, self._state, h, [*s0, *tail, *w0],
                                       [*s1, *tail, *w1], [*s2, *tail, *w2])
        self._k += 1
        total, lf = self._truths(i)
        valid = bool(self._valid[i])
        if valid:
            measured = total + self._errors[i]
            measured[2] = wrap_angle(float(measured[2]))
            self._last_measured = measured.copy()
        else:
            measured = self._last_measured.copy()
        self.sample = SimSample(self.t, measured, valid, total, lf, self._thrust.copy(),
                                command, float(self._peak[i]))
        return self.sample

    # ------------------------------------------------------------------ internals
    def _wave_operating_speed(self) -> tuple[float, float, float]:
        """Operating point of a thesis vessel's WF dynamics: initial state and mean current."""
        current = self.scenario.environment.mean_current()
        return wave_operating_speed(self._state[2], self._state[3:6],
                                    (float(current[0]), float(current[1])))

    def _wave_linear_model(self) -> LinearModel:
        """(M, D) of the WF dynamics (thesis vessels: linearized at `_wave_operating_speed`)."""
        if isinstance(self.vessel, ThesisVessel):
            return self.vessel.linearize(self._wave_operating_speed())
        return self.vessel.linearize()

    def _build_excitation(self, rng: np.random.Generator) -> exc.Excitation:
        cfg = self.scenario.excitation
        if cfg.kind == 'prbs':
            return exc.prbs(cfg.amplitude, cfg.clock_period, self.scenario.duration, rng)
        if cfg.kind == 'multisine':
            return exc.multisine(cfg.amplitude, cfg.frequencies, rng)
        if cfg.kind == 'steps':
            return exc.steps(cfg.table)
        return exc.no_excitation()

    def _refill(self) -> None:
        """Generate the next BLOCK output periods of every noise source at once."""
        scn = self.scenario
        current, env_force = self._env.next_block(BLOCK)
        # per-step tails of the RK4 input: earth-fixed LF force (3) and current (2), as floats
        self._lf_tail: list[list[float]] = np.hstack([env_force * self._mask, current]).tolist()
        noise_rng, fault_rng = self._sensor_rngs
        errors, valid = sensor_errors(scn.sensors, noise_rng.standard_normal((BLOCK, 3)),
                                      fault_rng.random((BLOCK, 4)))
        self._errors = errors * self._mask
        self._valid = valid
        times = (self._k + 1 + np.arange(BLOCK, dtype=np.float64)) * self.sample_time
        self._peak = scn.waves.peak_freq.sample(times)
        self._wave_motion = np.zeros((BLOCK, 3))
        if self._sea is not None:
            self._wave_basis: list[list[float]] = motion_basis(self._sea, scn.waves.rao,
                                                               times).tolist()
        if self._waves is not None and self._wave_model == 'motion':
            self._wave_motion, _ = self._waves.next_block(BLOCK)
        if self._waves is not None and self._wave_model == 'force':
            start = self._waves.output.copy()
            forces, impulses, _ = self._waves.next_block_with_impulses(BLOCK * self._substeps)
            # exact samples at the sub-step boundaries; the RK4 mid stages get the value that
            # makes the step's Simpson impulse h (τ0 + 4 τm + τ1)/6 the exact ∫τ dt (= τ at the
            # midpoint to O(h⁴)). A zero-order hold would delay the force by h/2 and leave a
            # constant WF velocity error b·τ(0)·h/2 that the weakly damped vessel turns into a
            # metre-size position offset; the linear interpolation's O(h³) impulse error per
            # step made the WF mean random-walk (`WaveGenerator.next_block_with_impulses`).
            bounds = np.vstack([start[None, :], forces])
            mid = (6.0 * impulses / self._h - bounds[:-1] - bounds[1:]) / 4.0
            self._wave_force = np.stack([bounds[:-1], mid, bounds[1:]], axis=1).tolist()
        self._blocks_left = BLOCK

    def _actuate(self, command: FloatArray) -> list[list[float]]:
        """Applied body force at the RK4 stage times (2·substeps + 1 rows)."""
        if self._thrusters is None:
            applied = command if self._limit is None else np.clip(command, -self._limit,
                                                                  self._limit)
            self._thrust = applied
            row = applied.tolist()
            return [row] * (2 * self._substeps + 1)
        n_cmd = allocate(self._thrusters, command)
        rpm = n_cmd + (self._rpm - n_cmd) * self._decay  # exact shaft response
        self._rpm = rpm[-1].copy()
        forces = generalized_thrust(self._thrusters, rpm)
        self._thrust = forces[-1].copy()
        result: list[list[float]] = forces.tolist()
        return result

    def _truths(self, index: int | None) -> tuple[FloatArray, FloatArray]:
        """(total pose, LF pose) now; `index` is the block row, None for the initial sample."""
        state = self._state
        lf = _pose(state)
        if self._wave_model == 'force':
            total = _pose([state[0] + state[6], state[1] + state[7], state[2] + state[8]])
        elif self._wave_model == 'motion':
            wave = self._wave_initial if index is None else self._wave_motion[index]
            total = lf + wave
            total[2] = wrap_angle(float(total[2]))
        elif self._wave_model == 'rao':  # η_w with the current LF heading (motion superposition)
            basis = self._wave_basis0 if index is None else self._wave_basis[index]
            north, east, yaw = motion_from_basis(basis, state[2])
            total = lf + np.array([north, east, yaw]) * self._mask
            total[2] = wrap_angle(float(total[2]))
        else:
            total = lf.copy()
        return total, lf


def _initial_wave_motion(model: LinearModel, heading: float, waves: WaveGenerator,
                         rng: np.random.Generator) -> list[float]:
    """WF state at t = 0 drawn from its stationary distribution given the wave-filter state.

    WF motion of the linear(ized) vessel: η_w = (M s + D)⁻¹ f s⁻¹ with f = R(ψ)ᵀ K_ω s² x3
    (per DOF, x3 the last section of the force filter). With the stable auxiliary state
    q = (M s + D)⁻¹ R(ψ)ᵀ K_ω x3 this is η_w = q̇ = M⁻¹(R(ψ)ᵀ K_ω x3 − D q) (body axes, rotated to
    earth with R(ψ)), ν_w = η̇_w. q is drawn from its stationary distribution conditioned on the
    filter state (augmented Lyapunov equation). The WF position has no restoring force, so a
    wrong start would stay as a permanent offset of the order of the WF motion itself.
    """
    shaping = waves.continuous_filter()
    n = shaping.a.shape[0]
    rot = rotation(heading)
    m_inv = np.linalg.inv(model.mass)
    # K_ω x3 per DOF (earth) as a linear map of the stacked filter state, body axes via R(ψ)ᵀ
    pick_x3 = np.kron(np.diag(waves.sigma), shaping.c_integrals[1][None, :])  # (3, 3n)
    pick_dx3 = np.kron(np.diag(waves.sigma), shaping.c_integrals[0][None, :])
    a_aug = np.zeros((3 * n + 3, 3 * n + 3))
    g_aug = np.zeros((3 * n + 3, 3))
    for dof in range(3):
        a_aug[dof * n:(dof + 1) * n, dof * n:(dof + 1) * n] = shaping.a
        g_aug[dof * n:(dof + 1) * n, dof] = shaping.g[:, 0]
    a_aug[3 * n:, :3 * n] = m_inv @ rot.T @ pick_x3
    a_aug[3 * n:, 3 * n:] = -m_inv @ model.damping
    cov = stationary_covariance(ShapingFilter(a_aug, g_aug, np.zeros((1, 3 * n + 3)),
                                              np.zeros((2, 3 * n + 3))))
    x_f = waves.state.reshape(-1)
    p_xx, p_qx, p_qq = cov[:3 * n, :3 * n], cov[3 * n:, :3 * n], cov[3 * n:, 3 * n:]
    gain = np.linalg.lstsq(p_xx, p_qx.T, rcond=None)[0].T
    cond_cov = p_qq - gain @ p_qx.T
    vals, vecs = np.linalg.eigh(0.5 * (cond_cov + cond_cov.T))
    q = gain @ x_f + vecs @ (np.sqrt(np.clip(vals, 0.0, None)) * rng.standard_normal(3))
    force = rot.T @ (pick_x3 @ x_f)  # body-axis K_ω x3
    force_rate = rot.T @ (pick_dx3 @ x_f)
    q_dot = m_inv @ (force - model.damping @ q)
    nu_w = m_inv @ (force_rate - model.damping @ q_dot)
    eta_w = rot @ q_dot
    return [*eta_w.tolist(), *nu_w.tolist()]


def _with_wave_motion(lf_rates: RatesFn, wf_rates: WaveRatesFn) -> RatesFn:
    """Rates of the 12-state [x_LF, x_WF] with 11 inputs (8 LF inputs + wave force)."""

    def rates(x: Sequence[float], inp: Sequence[float]) -> list[float]:
        lf = x[:6]
        return lf_rates(lf, inp) + wf_rates(lf, x[6:], inp)

    return rates


# ------------------------------------------------------------------------------- offline run
@dataclass(frozen=True)
class SimRecord:
    """Arrays of one run, one row per output sample t = T, 2T, ….

    thrust_command[k] is the command held during the period ending at t[k]; measured_valid is
    1.0 or 0.0 (dropout).
    """

    t: FloatArray
    measured_pose: FloatArray
    measured_valid: FloatArray
    truth_pose: FloatArray
    truth_lf_pose: FloatArray
    thrust: FloatArray
    thrust_command: FloatArray
    wave_peak_freq: FloatArray


class _RecordBuffer:
    """Preallocated arrays of a run, filled one `SimSample` at a time (`simulate*`)."""

    _POSES = ('measured_pose', 'truth_pose', 'truth_lf_pose', 'thrust', 'thrust_command')

    def __init__(self, count: int) -> None:
        self.poses = {k: np.empty((count, 3)) for k in self._POSES}
        self.t, self.valid, self.peak = np.empty(count), np.empty(count), np.empty(count)

    def store(self, k: int, sample: SimSample) -> None:
        """Row k := the sample."""
        self.t[k], self.peak[k] = sample.t, sample.wave_peak_freq
        self.valid[k] = sample.measured_valid
        for name in self._POSES:
            self.poses[name][k] = getattr(sample, name)

    def record(self, rows: int | None = None) -> SimRecord:
        """The first ``rows`` rows (all by default) as a `SimRecord`."""
        keep = slice(0, rows)
        p = {name: values[keep] for name, values in self.poses.items()}
        return SimRecord(self.t[keep], p['measured_pose'], self.valid[keep], p['truth_pose'],
                         p['truth_lf_pose'], p['thrust'], p['thrust_command'], self.peak[keep])


def controller_gains(scenario: Scenario, model: LinearModel) -> PidGains:
    """PID gains of the scenario from the vessel's (linearized) M and D diagonals."""
    ctl = scenario.controller
    return gains_from_bandwidth(np.diag(model.mass), ctl.bandwidth, ctl.zeta,
                                np.diag(model.damping), ctl.setpoint_filter_time,
                                ctl.velocity_filter_time)


def simulate(scenario: Scenario, seed: int | None = None, duration: float | None = None,
             controller: bool | None = None, feedback: str | None = None) -> SimRecord:
    """Run `scenario` offline and return its arrays.

    Closed loop with the scenario's PID (`controller` True; default from the scenario) fed by
    `feedback` ('truth_lf' or 'measured'; default from the scenario), or open loop with the
    scenario's excitation. In closed loop the excitation is added to the PID command. The PID
    setpoint follows `controller.setpoint_schedule` (`ControllerConfig.setpoint_at(t)`).
    """
    sim = Simulator(scenario, seed)
    use_pid = scenario.controller.enabled if controller is None else bool(controller)
    source = scenario.controller.feedback if feedback is None else feedback
    if source not in ('truth_lf', 'measured'):
        raise ValueError("feedback must be 'truth_lf' or 'measured'")
    total = scenario.duration if duration is None else float(duration)
    count = int(round(total / scenario.sample_time))
    buffer = _RecordBuffer(count)
    gains = controller_gains(scenario, sim.true_model())
    limit = scenario.controller.tau_max or sim.actuator_limit()
    setpoint = np.asarray(scenario.controller.setpoint)
    scheduled = bool(scenario.controller.setpoint_schedule)
    state = PidState()
    for k in range(count):
        tau = sim.excitation(sim.t)
        if scheduled:
            setpoint = scenario.controller.setpoint_at(sim.t)
        if use_pid:
            pose = sim.sample.truth_lf_pose if source == 'truth_lf' else sim.sample.measured_pose
            tau_pid, state = pid_step(state, gains, pose, setpoint, sim.sample_time, limit)
            tau = tau + tau_pid
        buffer.store(k, sim.step(tau))
    return buffer.record()



# ------------------------------------------------------------------- closed loop on an estimate
PoseEstimator = Callable[[float, FloatArray, FloatArray], FloatArray]
# the estimator's body-frame LF velocity [u m/s, v m/s, r rad/s] for its last estimate, or None
VelocityEstimate = Callable[[], FloatArray | Sequence[float] | None]


@dataclass(frozen=True)
class ClosedLoopRun:
    """A closed-loop run with the PID fed by an estimator (`simulate_in_loop`).

    ``estimate_t[j]`` is the time of the j-th estimator call and ``estimates[j]`` the pose it
    returned (non-finite values kept as returned; the PID held the last finite one instead, and
    ``nonfinite_estimates`` counts them). ``aborted_at`` is the time [s] the run was stopped
    because the true LF pose left ``abort_excursion`` (None: ran to the end), in which case the
    record holds the samples up to and including that time. ``missing_velocities`` counts the
    finite estimates for which the ``velocity`` hook gave None or a non-finite value (0 without
    the hook).
    """

    record: SimRecord
    estimate_t: FloatArray
    estimates: FloatArray
    nonfinite_estimates: int
    aborted_at: float | None
    missing_velocities: int = 0


def _call_period_samples(period: float, sample_time: float) -> int:
    """Output samples per estimator call; the period must be a whole number of them."""
    stride = int(round(period / sample_time))
    if not (period > 0.0) or stride < 1 or abs(stride * sample_time - period) > 1e-9 * period:
        raise ValueError(f'estimator period {period} s must be a positive integer multiple of '
                         f'the scenario sample_time {sample_time} s (e.g. 1.0 s at 10 Hz)')
    return stride


def _excursion(lf_pose: FloatArray, setpoint: FloatArray, ndof: int) -> float:
    """Horizontal distance [m] of the LF pose from the setpoint (1 DOF: |north offset|)."""
    offset = lf_pose - setpoint
    return float(abs(offset[0]) if ndof == 1 else math.hypot(offset[0], offset[1]))


def simulate_in_loop(scenario: Scenario, seed: int | None, duration: float | None,
                     estimate: PoseEstimator, period: float, *,
                     abort_excursion: float | None = None,
                     pid_period: float | None = None,
                     velocity: VelocityEstimate | None = None,
                     command: Callable[[float, FloatArray], object] | None = None
                     ) -> ClosedLoopRun:
    """Closed loop with the scenario's PID acting on the pose an estimator returns.

    The same loop as `simulate` (gains `controller_gains`, `pid_step` every sample_time, the
    limit ``controller.tau_max`` or the actuator capacity, the scenario's setpoint or setpoint
    schedule, excitation added to the command), except that the PID is fed ``estimate(t,
    measured_pose (3,), applied_thrust (3,)) -> pose (3,)`` instead of a true or measured pose.
    The estimator is called at t = period, 2·period, … with the sample of that instant (copies
    of ``sample.measured_pose`` and ``sample.thrust``); between calls the PID holds the last
    estimate (zero-order hold), before the first call it uses the first measurement (t = 0). A
    non-finite estimate is not used: the last finite one is held and the event counted.

    ``pid_period`` [s] (default sample_time): how often the PID runs (dt = pid_period), its
    command held in between. ``pid_period = period`` is the DDS pipeline, where the
    dp_controller node answers each lf_pose once and the simulator holds the command.

    ``velocity`` (default None: the PID's D term uses its finite difference of the held poses,
    bit for bit the loop without the hook): a function of no arguments called right after each
    estimator call that returned a finite pose, returning the estimator's body-frame LF velocity
    [u, v, r] for that estimate, or None. It is held with the pose and passed to `pid_step` as
    ``velocity_body`` (the D term −Kd ν, as the dp_controller node with ``velocity_source:
    odometry`` does with lf_odom's twist). None or a non-finite value: the PID uses the finite
    difference until the next valid velocity (counted in ``missing_velocities``).

    ``command`` (default None): called right before each estimator call with (t, the command
    held during the period ending at t), as the ``thrust_command`` topic delivers it: with
    ``pid_period = period`` the command the PID computed from the previous estimate (valid at t).

    The run is deterministic for a seed and a deterministic estimator; it stops early when the
    true LF pose leaves ``abort_excursion`` [m] from the setpoint (a diverged loop; with a
    schedule, from the setpoint in force at that time).
    """
    stride = _call_period_samples(period, scenario.sample_time)
    pid_stride = _call_period_samples(scenario.sample_time if pid_period is None else pid_period,
                                      scenario.sample_time)
    pid_dt = scenario.sample_time if pid_period is None else pid_stride * scenario.sample_time
    if abort_excursion is not None and not (abort_excursion > 0.0):
        raise ValueError(f'abort_excursion must be > 0 m (or None), got {abort_excursion}')
    sim = Simulator(scenario, seed)
    total = scenario.duration if duration is None else float(duration)
    count = int(round(total / scenario.sample_time))
    buffer = _RecordBuffer(count)
    gains = controller_gains(scenario, sim.true_model())
    limit = scenario.controller.tau_max or sim.actuator_limit()
    setpoint = np.asarray(scenario.controller.setpoint, dtype=np.float64)
    scheduled = bool(scenario.controller.setpoint_schedule)
    held = sim.sample.measured_pose.copy()
    held_velocity: FloatArray | None = None
    state = PidState()
    calls: list[float] = []
    returned: list[FloatArray] = []
    nonfinite = 0
    missing_velocities = 0
    aborted_at: float | None = None
    done = count
    tau_pid = np.zeros(3)
    for k in range(count):
        if scheduled:
            setpoint = scenario.controller.setpoint_at(sim.t)
        if k % pid_stride == 0:
            tau_pid, state = pid_step(state, gains, held, setpoint, pid_dt, limit,
                                      held_velocity)
        sample = sim.step(sim.excitation(sim.t) + tau_pid)
        buffer.store(k, sample)
        if (k + 1) % stride == 0:
            if command is not None:
                command(sample.t, sample.thrust_command.copy())
            value = np.array(estimate(sample.t, sample.measured_pose.copy(),
                                      sample.thrust.copy()), dtype=np.float64)
            if value.shape != (3,):
                raise ValueError(f'the estimator must return a (3,) pose [north, east, yaw], '
                                 f'got shape {value.shape}')
            calls.append(sample.t)
            returned.append(value)
            if np.all(np.isfinite(value)):
                held = value.copy()
                if velocity is not None:
                    held_velocity = _velocity_of(velocity())
                    if held_velocity is None:
                        missing_velocities += 1
            else:
                nonfinite += 1
        if abort_excursion is not None and not (
                _excursion(sample.truth_lf_pose, setpoint, sim.ndof) <= abort_excursion):
            aborted_at, done = sample.t, k + 1
            break
    record = buffer.record(done)
    estimates = np.array(returned, dtype=np.float64).reshape(-1, 3)
    return ClosedLoopRun(record, np.array(calls, dtype=np.float64), estimates, nonfinite,
                         aborted_at, missing_velocities)


def _velocity_of(value: FloatArray | Sequence[float] | None) -> FloatArray | None:
    """A copy of a velocity hook's value as a finite (3,) array, or None (use the difference)."""
    if value is None:
        return None
    array = np.array(value, dtype=np.float64)
    if array.shape != (3,):
        raise ValueError(f'the velocity hook must return a (3,) body velocity [u, v, r] or '
                         f'None, got shape {array.shape}')
    return array if bool(np.all(np.isfinite(array))) else None


__all__ = ['ClosedLoopRun', 'ControllerConfig', 'ExcitationConfig', 'PoseEstimator', 'Scenario',
           'SimRecord', 'SimSample', 'Simulator', 'VelocityEstimate', 'WaveConfig',
           'available_scenarios', 'controller_gains', 'load_scenario', 'scenario_from_dict',
           'simulate', 'simulate_in_loop']
