"""Low-frequency environment: ocean current and slowly varying forces (wind, wave drift).

- Current (Fossen 2011 §8.3): earth-fixed velocity v_c = V_c [cos β_c, sin β_c] (β_c the
  direction the current flows towards, from north, clockwise), plus an optional Gauss–Markov
  variation per component: δ̇ = −δ/T_c + w. MSS `SIMsupply.m` uses V_c = 0.5 m/s, β_c = 20°.
- Wind gusts and second-order wave drift as first-order Markov biases (anchors §2, Fossen 2011
  §11.3): ḃ = −b/T_b + E w, b earth-fixed [N, N, N·m], around a mean.

Every process is parametrized by its stationary standard deviation and time constant and
discretized exactly: x[k+1] = m + φ (x[k] − m) + s √(1 − φ²) z, φ = exp(−h/T), so statistics do
not depend on the step h. The processes start at their mean.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math

import numpy as np
import scipy.signal

from sim_ros.physics.kinematics import FloatArray


def _zeros3() -> tuple[float, float, float]:
    return (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class MarkovBias:
    """First-order Markov process per DOF: mean, stationary std, time constant [s]."""

    mean: tuple[float, ...] = field(default_factory=_zeros3)
    std: tuple[float, ...] = field(default_factory=_zeros3)
    time_constant: float = 300.0  # s, T_b in 100–1000 s (anchors §2)

    def __post_init__(self) -> None:
        """Validate: same length, std >= 0, T > 0."""
        if len(self.mean) != len(self.std):
            raise ValueError(f'Markov bias mean {self.mean} and std {self.std} need the same '
                             'number of components')
        if any(s < 0.0 for s in self.std):
            raise ValueError(f'Markov bias std must be >= 0, got {self.std}')
        if not (self.time_constant > 0.0):
            raise ValueError(f'Markov time constant must be > 0 s, got {self.time_constant}')


@dataclass(frozen=True)
class EnvironmentConfig:
    """Current [m/s, rad] and earth-fixed slowly varying forces (wind, drift)."""

    current_speed: float = 0.0  # m/s
    current_direction: float = 0.0  # rad, towards, from north
    current_variation: MarkovBias = field(
        default_factory=lambda: MarkovBias((0.0, 0.0), (0.0, 0.0), 600.0))
    wind: MarkovBias = field(default_factory=MarkovBias)
    drift: MarkovBias = field(default_factory=MarkovBias)

    def __post_init__(self) -> None:
        """Validate shapes and signs."""
        if not (self.current_speed >= 0.0):
            raise ValueError(f'current speed must be >= 0 m/s, got {self.current_speed}')
        if len(self.current_variation.mean) != 2:
            raise ValueError('current_variation has 2 components (north, east) in m/s')
        if len(self.wind.mean) != 3 or len(self.drift.mean) != 3:
            raise ValueError('wind and drift biases have 3 components (north N, east N, yaw N·m)')

    def mean_current(self) -> FloatArray:
        """Mean earth-fixed current velocity (north, east) [m/s]."""
        return np.array([self.current_speed * math.cos(self.current_direction),
                         self.current_speed * math.sin(self.current_direction)])


def markov_coefficients(time_constant: float, step: float) -> tuple[float, float]:
    """(φ, √(1−φ²)) of the exact discretization of ḃ = −b/T + w over `step` [s]."""
    phi = math.exp(-step / time_constant)
    return phi, math.sqrt(max(0.0, 1.0 - phi * phi))


def markov_step(value: FloatArray, bias: MarkovBias, step: float,
                noise: FloatArray) -> FloatArray:
    """Pure step of the Markov bias: m + φ (x − m) + s √(1−φ²) z."""
    phi, gain = markov_coefficients(bias.time_constant, step)
    mean = np.asarray(bias.mean)
    return np.asarray(mean + phi * (value - mean) + np.asarray(bias.std) * gain * noise,
                      dtype=np.float64)


class MarkovGenerator:
    """Block generator of a `MarkovBias` sampled every `step` [s] (exact AR(1) via lfilter)."""

    def __init__(self, bias: MarkovBias, step: float, rng: np.random.Generator) -> None:
        """Start at the mean; noise only from `rng`."""
        self.bias = bias
        self.phi, self.gain = markov_coefficients(bias.time_constant, step)
        self.mean = np.asarray(bias.mean, dtype=np.float64)
        self.std = np.asarray(bias.std, dtype=np.float64)
        self.deviation = np.zeros_like(self.mean)
        self.rng = rng
        self.active = bool(np.any(self.std > 0.0))

    def next_block(self, count: int) -> FloatArray:
        """Values at the end of each of the next `count` steps, shape (count, ndim)."""
        if not self.active:
            return np.tile(self.mean, (count, 1))
        z = self.rng.standard_normal((count, self.mean.size)) * (self.std * self.gain)
        dev, _ = scipy.signal.lfilter([1.0], [1.0, -self.phi], z, axis=0,
                                      zi=(self.phi * self.deviation)[None, :])
        dev = np.asarray(dev, dtype=np.float64)
        self.deviation = dev[-1].copy()
        return np.asarray(self.mean + dev, dtype=np.float64)


class EnvironmentGenerator:
    """Current (north, east) and total earth-fixed LF force (wind + drift), in blocks."""

    def __init__(self, config: EnvironmentConfig, step: float,
                 rngs: tuple[np.random.Generator, np.random.Generator, np.random.Generator]
                 ) -> None:
        """One child generator each for current, wind and drift."""
        self.config = config
        self.mean_current = config.mean_current()
        self.current = MarkovGenerator(config.current_variation, step, rngs[0])
        self.wind = MarkovGenerator(config.wind, step, rngs[1])
        self.drift = MarkovGenerator(config.drift, step, rngs[2])

    def next_block(self, count: int) -> tuple[FloatArray, FloatArray]:
        """(current (count, 2) [m/s], force (count, 3) [N, N, N·m]) for the next steps."""
        current = self.current.next_block(count) + self.mean_current
        force = self.wind.next_block(count) + self.drift.next_block(count)
        return current, force
