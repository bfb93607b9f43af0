"""Report of one closed-loop demo run: ``report.png``, ``metrics.json`` and ``report.md``.

Inputs (`RunData`) are plain arrays, so the report can be made from a bag (`load_run`, via
`lf_predictor_ros.bag.series`) or from synthetic data in a test.

Metrics (``metrics.json``), all over t ≥ ``warmup`` [s sim]:

- ``estimation``: `core.evaluation.score` of the published ``lf_pose`` against ``truth/lf_pose``
  matched by stamp (lf_pose is stamped with the time it is valid for, so a sample of the
  prediction is compared with the truth at that time): per-DOF RMSE, rate RMSE, wave-band power
  of the error, lag.
- ``closed_loop``: per loop (``predictor``: the DDS run with the predictor's lf_pose fed to the
  controller; ``raw_measurement``: offline, controller fed ``measured_pose``; ``ideal``: offline,
  controller fed the true LF pose), `core.evaluation.loop_metrics` of the true LF pose and the
  applied thrust:
  ``position_rmse`` = √mean(Δn² + Δe²) [m] from the setpoint, ``heading_rmse`` [rad] (3 DOF),
  ``max_excursion`` = max √(Δn² + Δe²) [m] (1 DOF: max |Δn|), ``thrust_wave_band_power`` per DOF
  (Welch PSD of the thrust integrated over the wave band [N², N², (N·m)²], `band_power`) and
  ``thrust_total_variation`` per DOF = Σ|τ[k+1] − τ[k]| [N, N, N·m] (actuator wear).
- ``run``: scenario, seed, duration, wall time, × real time, trainings, lockstep timeouts, …

The wave-band power ratio (predictor loop / raw loop) says how much wave-frequency thrust the
predictor keeps out of the thrusters: the purpose of a wave filter (thesis §1, §5.4).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
import json
import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use('Agg')
from matplotlib import pyplot as plt  # noqa: E402  (backend first)
import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

from lf_predictor_ros.core.evaluation import (  # noqa: E402
    DEFAULT_WAVE_BAND,
    DOF_NAMES,
    LoopRun,
    band_power,
    loop_metrics,
    score,
)

FloatArray = NDArray[np.float64]
NS_PER_S = 1_000_000_000  # [ns/s]
DOF_UNITS = ('m', 'm', 'rad')
THRUST_UNITS = ('N', 'N', 'N·m')
PNG_NAME = 'report.png'
METRICS_NAME = 'metrics.json'
MARKDOWN_NAME = 'report.md'
LOOP_LABELS = {'predictor': 'predictor in the loop (DDS)',
               'raw_measurement': 'raw measured_pose fed back (offline)',
               'ideal': 'true LF pose fed back (offline, ideal)'}


@dataclass(frozen=True)
class Trace:
    """A time series: times (n,) [s] and values (n, k)."""

    t: FloatArray
    values: FloatArray

    def __post_init__(self) -> None:
        """Check that there is one row of values per time."""
        if self.t.ndim != 1 or self.values.ndim != 2 or self.values.shape[0] != self.t.size:
            raise ValueError(f'a Trace needs t (n,) and values (n, k); got {self.t.shape} and '
                             f'{self.values.shape}')

    def after(self, start: float) -> Trace:
        """The samples at t ≥ start."""
        keep = self.t >= start
        return Trace(self.t[keep], self.values[keep])


@dataclass(frozen=True)
class RunData:
    """Everything the report shows; ``loops`` maps 'predictor', 'raw_measurement', 'ideal'."""

    ndof: int
    measured_pose: Trace
    truth_lf_pose: Trace
    lf_pose: Trace
    wave_peak_freq: Trace
    wave_peak_freq_truth: Trace
    loops: Mapping[str, LoopRun]
    retrain_times: Sequence[float] = ()
    setpoint: Sequence[float] = (0.0, 0.0, 0.0)
    wave_band: tuple[float, float] = DEFAULT_WAVE_BAND
    run_info: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ReportPaths:
    """Files written by `write_report`."""

    png: Path
    metrics: Path
    markdown: Path


# -------------------------------------------------------------------------------- metrics
def match_by_stamp(first: Trace, second: Trace) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(t, first values, second values) at the stamps both traces hold (to the nanosecond)."""
    first_ns = np.round(first.t * NS_PER_S).astype(np.int64)
    second_ns = np.round(second.t * NS_PER_S).astype(np.int64)
    _, first_index, second_index = np.intersect1d(first_ns, second_ns, assume_unique=False,
                                                  return_indices=True)
    return first.t[first_index], first.values[first_index], second.values[second_index]


def retrain_times_from_diagnostics(
        diagnostics: Sequence[tuple[float, str, Mapping[str, str]]],
        key: str = 'trainings') -> list[float]:
    """Stamps [s] at which a status's ``trainings`` count increased (one entry per increase)."""
    last: dict[str, int] = {}
    times: list[float] = []
    for stamp, name, values in diagnostics:
        raw = values.get(key)
        if raw is None:
            continue
        try:
            count = int(float(raw))
        except ValueError:
            continue
        if count > last.get(name, 0):
            times.append(float(stamp))
        last[name] = max(count, last.get(name, 0))
    return times


def compute_metrics(run: RunData, warmup: float) -> dict[str, Any]:
    """The content of ``metrics.json`` (see the module docstring)."""
    t, estimate, truth = match_by_stamp(run.lf_pose.after(warmup), run.truth_lf_pose)
    metrics: dict[str, Any] = {'warmup': warmup, 'wave_band': list(run.wave_band)}
    if t.size >= 3:
        metrics['estimation'] = score(t, estimate, truth, run.ndof, run.wave_band).to_dict()
    else:
        metrics['estimation'] = {'samples': int(t.size),
                                 'note': 'fewer than 3 lf_pose stamps match truth/lf_pose'}
    loops = {name: loop_metrics(loop, run.ndof, run.setpoint, run.wave_band, warmup)
             for name, loop in run.loops.items()}
    metrics['closed_loop'] = loops
    if 'predictor' in loops and 'raw_measurement' in loops:
        metrics['thrust_wave_band_power_ratio'] = {
            dof: _ratio(loops['predictor']['thrust_wave_band_power'][dof],
                        loops['raw_measurement']['thrust_wave_band_power'][dof])
            for dof in DOF_NAMES[: run.ndof]}
    metrics['run'] = dict(run.run_info)
    metrics['run']['retrain_times'] = [float(v) for v in run.retrain_times]
    return metrics


def _ratio(numerator: float, denominator: float) -> float:
    return numerator / denominator if denominator > 0.0 else math.nan


# -------------------------------------------------------------------------------- figure
def plot_report(run: RunData, path: Path, metrics: Mapping[str, Any] | None = None) -> None:
    """Write the PNG: per DOF pose, thrust and error; ω0 estimate vs truth across the bottom.

    With ``metrics`` (`compute_metrics`) the thrust titles give its wave-band power ratio, after
    the warm-up like the report's table; without, the ratio over the whole run.
    """
    ncol = run.ndof
    fig = plt.figure(figsize=(5.5 * ncol + 1.0, 12.0), layout='constrained')
    grid = fig.add_gridspec(4, ncol)
    predictor = run.loops.get('predictor')
    raw = run.loops.get('raw_measurement')
    matched_t, estimate, truth = match_by_stamp(run.lf_pose, run.truth_lf_pose)
    for i in range(ncol):
        name, unit = DOF_NAMES[i], DOF_UNITS[i]
        ax = fig.add_subplot(grid[0, i])
        ax.plot(run.measured_pose.t, run.measured_pose.values[:, i], color='0.7', lw=0.6,
                label='measured')
        ax.plot(run.truth_lf_pose.t, run.truth_lf_pose.values[:, i], color='k', lw=1.0,
                label='true LF')
        ax.plot(run.lf_pose.t, run.lf_pose.values[:, i], color='tab:red', lw=0.9,
                label='predicted LF (lf_pose)')
        ax.set_title(f'{name} pose [{unit}]')
        ax.legend(loc='upper right', fontsize='small')
        ax = fig.add_subplot(grid[1, i])
        if raw is not None:
            ax.plot(raw.t, raw.thrust[:, i], color='0.6', lw=0.6, label='raw measurement loop')
        if predictor is not None:
            ax.plot(predictor.t, predictor.thrust[:, i], color='tab:blue', lw=0.8,
                    label='predictor loop')
        ax.set_title(f'{name} thrust [{THRUST_UNITS[i]}]'
                     + thrust_ratio_label(run, predictor, raw, i, metrics))
        ax.legend(loc='upper right', fontsize='small')
        ax = fig.add_subplot(grid[2, i])
        error = estimate[:, i] - truth[:, i]
        if i == 2:
            error = np.angle(np.exp(1j * error))
        ax.plot(matched_t, error, color='tab:red', lw=0.7)
        for k, t_retrain in enumerate(run.retrain_times):
            ax.axvline(t_retrain, color='tab:green', lw=0.8, ls='--',
                       label='retraining' if k == 0 else None)
        ax.set_title(f'{name} LF estimation error [{unit}]')
        ax.set_xlabel('simulated time [s]')
        if run.retrain_times:
            ax.legend(loc='upper right', fontsize='small')
    ax = fig.add_subplot(grid[3, :])
    ax.plot(run.wave_peak_freq_truth.t, run.wave_peak_freq_truth.values[:, 0], color='k',
            label='true ω0 (scenario schedule)')
    if run.wave_peak_freq.t.size:
        ax.step(run.wave_peak_freq.t, run.wave_peak_freq.values[:, 0], where='post',
                color='tab:orange', label='estimated ω0 (/wave_peak_frequency)')
    ax.set_title('wave peak frequency ω0 [rad/s]')
    ax.set_xlabel('simulated time [s]')
    ax.legend(loc='lower right', fontsize='small')
    info = run.run_info
    fig.suptitle(f"demo: {info.get('scenario', '?')}, seed {info.get('seed', '?')}, "
                 f"{info.get('duration', '?')} s simulated")
    fig.savefig(path, dpi=90)
    plt.close(fig)


def thrust_ratio_label(run: RunData, predictor: LoopRun | None, raw: LoopRun | None, dof: int,
                       metrics: Mapping[str, Any] | None = None) -> str:
    """Title line: wave-band thrust power predictor / raw loop, as in ``metrics`` if given."""
    if metrics is not None and DOF_NAMES[dof] in metrics.get('thrust_wave_band_power_ratio', {}):
        ratio = metrics['thrust_wave_band_power_ratio'][DOF_NAMES[dof]]
        return f"\nwave-band power predictor/raw = {ratio:.3g} (t ≥ {metrics['warmup']:g} s)"
    if predictor is None or raw is None:
        return ''
    sample_time = float(np.median(np.diff(predictor.t)))
    ratio = _ratio(band_power(predictor.thrust[:, dof], sample_time, run.wave_band),
                   band_power(raw.thrust[:, dof], float(np.median(np.diff(raw.t))),
                              run.wave_band))
    return f'\nwave-band power predictor/raw = {ratio:.3g} (whole run)'


# -------------------------------------------------------------------------------- markdown
def markdown_summary(metrics: Mapping[str, Any], ndof: int, png_name: str = PNG_NAME) -> str:
    """A short readable summary: run info, estimation and closed-loop tables, the image."""
    info = metrics.get('run', {})
    lines = [f"# Demo run: {info.get('scenario', '?')}", '',
             f"Seed {info.get('seed', '?')}, {info.get('duration', '?')} s simulated in "
             f"{_fmt(info.get('wall_time'))} s wall ({_fmt(info.get('real_time_factor'))}× "
             f"real time); trainings: {info.get('trainings', '?')}; lockstep timeouts: "
             f"{info.get('lockstep_timeouts', '?')}; metrics after {metrics.get('warmup')} s.",
             '', 'The predictor loop ran over DDS (simulator, predictor, dp_controller, recorder '
             'as processes). The raw-measurement and ideal (true LF pose) loops are offline runs '
             'of `sim_ros.simulation.simulate` with the same scenario and seed.', '',
             '## LF pose estimate (lf_pose vs truth/lf_pose, matched by stamp)', '',
             '| DOF | RMSE | rate RMSE | wave-band error power | lag [s] |',
             '|---|---|---|---|---|']
    estimation = metrics.get('estimation', {})
    for dof in DOF_NAMES[:ndof]:
        row = estimation.get(dof)
        if isinstance(row, Mapping):
            lines.append(f"| {dof} | {_fmt(row['rmse'])} | {_fmt(row['derivative_rmse'])} | "
                         f"{_fmt(row['wave_band_power'])} | {_fmt(row['lag'])} |")
    lines += ['', '## Closed loop (true LF pose vs setpoint; applied thrust)', '',
              '| loop | position RMSE [m] | max excursion [m] | heading RMSE [rad] | '
              'thrust wave-band power | thrust total variation |', '|---|---|---|---|---|---|']
    for name, loop in metrics.get('closed_loop', {}).items():
        power = ', '.join(_fmt(v) for v in loop['thrust_wave_band_power'].values())
        variation = ', '.join(_fmt(v) for v in loop['thrust_total_variation'].values())
        lines.append(f"| {LOOP_LABELS.get(name, name)} | {_fmt(loop['position_rmse'])} | "
                     f"{_fmt(loop['max_excursion'])} | {_fmt(loop.get('heading_rmse'))} | "
                     f'{power} | {variation} |')
    ratio = metrics.get('thrust_wave_band_power_ratio')
    if ratio:
        lines += ['', 'Thrust wave-band power, predictor loop / raw loop: '
                  + ', '.join(f'{dof} {_fmt(v)}' for dof, v in ratio.items()) + '.']
    lines += ['', f'![report]({png_name})', '']
    return '\n'.join(lines)


def _fmt(value: Any) -> str:
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return f'{value:.4g}'
    return '–' if value is None else str(value)


def write_report(run: RunData, out_dir: Path, warmup: float) -> ReportPaths:
    """Write ``report.png``, ``metrics.json`` and ``report.md`` into ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = ReportPaths(out_dir / PNG_NAME, out_dir / METRICS_NAME, out_dir / MARKDOWN_NAME)
    metrics = compute_metrics(run, warmup)
    paths.metrics.write_text(json.dumps(metrics, indent=2, allow_nan=True) + '\n',
                             encoding='utf-8')
    plot_report(run, paths.png, metrics)
    paths.markdown.write_text(markdown_summary(metrics, run.ndof), encoding='utf-8')
    return paths


__all__ = ['LoopRun', 'ReportPaths', 'RunData', 'Trace', 'compute_metrics', 'loop_metrics',
           'markdown_summary', 'match_by_stamp', 'plot_report', 'retrain_times_from_diagnostics',
           'thrust_ratio_label', 'write_report']
