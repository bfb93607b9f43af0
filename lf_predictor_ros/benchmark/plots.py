"""Figures of the results page: closed loops per scenario and the ω0-schedule adaptation.

matplotlib with the Agg backend (files only, no display), as `demo/report.py`.
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import matplotlib

matplotlib.use('Agg')
from matplotlib import pyplot as plt  # noqa: E402  (backend first)
import numpy as np  # noqa: E402

from lf_predictor_ros.benchmark.suite import AdaptationSeries, LoopSeries  # noqa: E402
from lf_predictor_ros.core.evaluation import DEFAULT_WAVE_BAND, DOF_NAMES  # noqa: E402

THRUST_UNITS = ('N', 'N', 'N·m')
PSD_MAX_FREQ = 2.0  # [rad/s] right edge of the thrust spectra (wave band 0.3–1.3 rad/s)
LOOP_STYLE = {'ideal': ('k', 1.2), 'adaptive': ('tab:red', 1.0), 'frozen': ('tab:purple', 0.8),
              'cascade': ('tab:green', 0.8), 'observer': ('tab:blue', 0.8),
              'observer_mistuned': ('tab:cyan', 0.8), 'raw': ('0.6', 0.6)}


def _style(name: str) -> tuple[str, float]:
    return LOOP_STYLE.get(name, ('tab:orange', 0.8))


def plot_closed_loops(title: str, loops: Mapping[str, LoopSeries], ndof: int,
                      path: Path, wave_band: tuple[float, float] = DEFAULT_WAVE_BAND) -> None:
    """Position (and heading) offset of each loop vs time; thrust PSD per DOF, wave band shaded."""
    fig = plt.figure(figsize=(5.0 * ndof + 2.0, 8.0), layout='constrained')
    grid = fig.add_gridspec(2, ndof)
    top = fig.add_subplot(grid[0, :2] if ndof == 3 else grid[0, 0])
    for name, loop in loops.items():
        color, width = _style(name)
        excursion = (np.hypot(loop.offset[:, 0], loop.offset[:, 1]) if ndof == 3
                     else loop.offset[:, 0])
        top.plot(loop.t, excursion, color=color, lw=width, label=name)
    top.set_title('horizontal distance from setpoint [m]' if ndof == 3
                  else 'north offset from setpoint [m]')
    top.set_xlabel('simulated time [s]')
    top.legend(loc='upper right', fontsize='small', ncol=2)
    if ndof == 3:
        ax = fig.add_subplot(grid[0, 2])
        for name, loop in loops.items():
            color, width = _style(name)
            ax.plot(loop.t, np.degrees(loop.offset[:, 2]), color=color, lw=width, label=name)
        ax.set_title('heading error [deg]')
        ax.set_xlabel('simulated time [s]')
    for i in range(ndof):
        ax = fig.add_subplot(grid[1, i])
        ax.axvspan(*wave_band, color='tab:orange', alpha=0.15, label='wave band')
        shown: list[float] = []
        for name, loop in loops.items():
            color, width = _style(name)
            visible = (loop.thrust_omega > 0.0) & (loop.thrust_omega <= PSD_MAX_FREQ)
            psd = loop.thrust_psd[visible, i]
            ax.semilogy(loop.thrust_omega[visible], psd, color=color, lw=width, label=name)
            shown += [float(v) for v in psd if v > 0.0]
        ax.set_xlim(0.0, PSD_MAX_FREQ)
        if shown:  # decades around the visible curves, not the near-zero bins of a calm loop
            ax.set_ylim(max(min(shown), max(shown) * 1e-8) / 2.0, max(shown) * 2.0)
        ax.set_title(f'{DOF_NAMES[i]} thrust PSD [{THRUST_UNITS[i]}²/Hz] (after warm-up)')
        ax.set_xlabel('ω [rad/s]')
        if i == 0:
            ax.legend(loc='upper right', fontsize='small', ncol=2)
    fig.suptitle(title)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def plot_adaptation(title: str, series: AdaptationSeries, path: Path,
                    unit: str = 'm') -> None:
    """Rolling RMSE (window Δ) of adaptive and frozen, the ω0 change times and the true ω0."""
    fig, ax = plt.subplots(figsize=(11.0, 5.0), layout='constrained')
    ax.plot(series.t, series.frozen_rmse, color='tab:purple', lw=0.9, label='frozen')
    ax.plot(series.t, series.adaptive_rmse, color='tab:red', lw=0.9, label='adaptive')
    for k, change in enumerate(series.changes):
        ax.axvline(change, color='k', ls='--', lw=0.8, label='ω0 change' if k == 0 else None)
    ax.set_yscale('log')
    ax.set_xlabel('simulated time [s]')
    ax.set_ylabel(f'rolling RMSE over Δ = {series.window:g} s [{unit}]')
    twin = ax.twinx()
    twin.plot(series.t, series.wave_peak_freq, color='tab:orange', lw=1.0, label='true ω0')
    twin.set_ylabel('ω0 [rad/s]')
    lines, labels = ax.get_legend_handles_labels()
    more, more_labels = twin.get_legend_handles_labels()
    ax.legend(lines + more, labels + more_labels, loc='upper right', fontsize='small')
    ax.set_title(title)
    fig.savefig(path, dpi=80)
    plt.close(fig)


__all__ = ['plot_adaptation', 'plot_closed_loops']
