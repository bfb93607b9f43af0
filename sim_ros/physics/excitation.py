"""Open-loop excitation signals on the control input τc (thesis §5.2.2).

- PRBS: a random binary sequence ±A_i per DOF that may switch every `clock_period` [s]
  (Ljung 1999 §13.3: the clock period sets the bandwidth, ≈ 1/clock_period … rad/s); signs drawn
  from a seeded generator, independent per DOF.
- Multisine: Σ_k A_i sin(ω_k t + φ_k,i), random phases, amplitude normalized by √(n/2) so the RMS
  equals A_i.
- Steps: a piecewise-constant table [[t, τ_surge, τ_sway, τ_yaw], ...].
Every signal is a pure function of time once built (frozen dataclasses).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import math

import numpy as np

from sim_ros.physics.kinematics import FloatArray

EXCITATION_KINDS = ('none', 'prbs', 'multisine', 'steps')


@dataclass(frozen=True)
class Excitation:
    """τ_exc(t) (3,) [N, N, N·m]; kind 'none' gives zeros."""

    kind: str
    amplitude: tuple[float, float, float] = (0.0, 0.0, 0.0)
    clock_period: float = 10.0  # s, PRBS
    signs: FloatArray | None = None  # (n_periods, 3), PRBS
    frequencies: tuple[float, ...] = ()  # rad/s, multisine
    phases: FloatArray | None = None  # (n_freq, 3), multisine
    step_times: tuple[float, ...] = ()  # s, steps
    step_values: FloatArray | None = None  # (n_steps, 3), steps

    def __call__(self, t: float) -> FloatArray:
        """τ_exc at time t [s] (zero before the first step / for 'none')."""
        amp = np.asarray(self.amplitude)
        if self.kind == 'prbs' and self.signs is not None:
            index = min(max(int(t // self.clock_period), 0), len(self.signs) - 1)
            return np.asarray(amp * self.signs[index], dtype=np.float64)
        if self.kind == 'multisine' and self.phases is not None:
            omega = np.asarray(self.frequencies)[:, None]
            scale = math.sqrt(len(self.frequencies) / 2.0)
            return np.asarray(amp * np.sin(omega * t + self.phases).sum(axis=0) / scale,
                              dtype=np.float64)
        if self.kind == 'steps' and self.step_values is not None:
            index = int(np.searchsorted(self.step_times, t, side='right')) - 1
            return np.zeros(3) if index < 0 else np.asarray(self.step_values[index].copy())
        return np.zeros(3)


def no_excitation() -> Excitation:
    """τ_exc = 0."""
    return Excitation('none')


def prbs(amplitude: Sequence[float], clock_period: float, duration: float,
         rng: np.random.Generator) -> Excitation:
    """Random binary ±amplitude switching on a clock of `clock_period` [s] for `duration` [s]."""
    if not (clock_period > 0.0):
        raise ValueError(f'PRBS clock_period must be > 0 s, got {clock_period}')
    periods = int(math.ceil(max(duration, clock_period) / clock_period)) + 1
    signs = np.where(rng.random((periods, 3)) < 0.5, -1.0, 1.0)
    return Excitation('prbs', _amp(amplitude), clock_period=float(clock_period), signs=signs)


def multisine(amplitude: Sequence[float], frequencies: Sequence[float],
              rng: np.random.Generator) -> Excitation:
    """Σ sin(ω_k t + φ_k) with random phases; RMS = amplitude per DOF."""
    if len(frequencies) == 0 or any(f <= 0 for f in frequencies):
        raise ValueError('multisine needs at least one frequency, all > 0 rad/s')
    phases = rng.uniform(0.0, 2.0 * math.pi, (len(frequencies), 3))
    return Excitation('multisine', _amp(amplitude),
                      frequencies=tuple(float(f) for f in frequencies), phases=phases)


def steps(table: Sequence[Sequence[float]]) -> Excitation:
    """Piecewise-constant τ from rows [t, τ_surge, τ_sway, τ_yaw] (sorted by t)."""
    if len(table) == 0 or any(len(row) != 4 for row in table):
        raise ValueError('step excitation rows are [t_s, tau_surge_N, tau_sway_N, tau_yaw_Nm]')
    times = tuple(float(row[0]) for row in table)
    if any(b < a for a, b in zip(times, times[1:], strict=False)):
        raise ValueError('step excitation times must be sorted')
    values = np.array([[float(v) for v in row[1:]] for row in table])
    return Excitation('steps', (1.0, 1.0, 1.0), step_times=times, step_values=values)


def _amp(amplitude: Sequence[float]) -> tuple[float, float, float]:
    if len(amplitude) != 3 or any(a < 0 for a in amplitude):
        raise ValueError(f'excitation amplitude needs 3 values >= 0, got {amplitude}')
    return (float(amplitude[0]), float(amplitude[1]), float(amplitude[2]))
