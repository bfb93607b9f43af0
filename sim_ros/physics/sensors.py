"""Position reference and heading sensors: GNSS north/east and gyro-compass heading.

y = η_total + v, v ~ N(0, diag(σ_p², σ_p², σ_ψ²)) white at the sensor rate (anchors §3:
y = η_LF + η_w + v), heading wrapped to (−π, π]. Optional faults, each sample independently:
a dropout (probability p_d: no new measurement; the last valid one is held and flagged invalid),
an outlier (probability p_o: a jump of `outlier_position` [m] in a random horizontal direction
and ±`outlier_heading` [rad]).
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
import numpy.typing as npt

from sim_ros.physics.kinematics import FloatArray, wrap_angles

MIN_SENSOR_RATE = 1.0  # Hz
MAX_SENSOR_RATE = 100.0  # Hz


@dataclass(frozen=True)
class SensorConfig:
    """Noise standard deviations and fault probabilities."""

    position_std: float = 0.0  # m, per axis
    heading_std: float = 0.0  # rad
    dropout_probability: float = 0.0
    outlier_probability: float = 0.0
    outlier_position: float = 0.0  # m
    outlier_heading: float = 0.0  # rad

    def __post_init__(self) -> None:
        """Validate ranges."""
        for name in ('position_std', 'heading_std', 'outlier_position', 'outlier_heading'):
            if not (getattr(self, name) >= 0.0):
                raise ValueError(f'sensor {name} must be >= 0, got {getattr(self, name)}')
        for name in ('dropout_probability', 'outlier_probability'):
            if not (0.0 <= getattr(self, name) < 1.0):
                raise ValueError(f'sensor {name} must be in [0, 1), got {getattr(self, name)}')


def check_sensor_rate(sample_time: float) -> None:
    """Raise if 1/sample_time is outside 1–100 Hz."""
    if not (1.0 / MAX_SENSOR_RATE - 1e-12 <= sample_time <= 1.0 / MIN_SENSOR_RATE + 1e-12):
        raise ValueError(f'sample_time {sample_time} s is outside the 1–100 Hz sensor range; '
                         'use 0.01–1 s')


def sensor_errors(config: SensorConfig, noise: FloatArray, uniforms: FloatArray,
                  ) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """Pure, vectorized: additive measurement errors and validity for n samples.

    `noise` (n, 3) standard normal, `uniforms` (n, 4) in [0, 1) (dropout draw, outlier draw,
    outlier direction, outlier heading sign). Returns (errors (n, 3) = white noise + outlier
    jumps, valid (n,) bool, False on a dropout).
    """
    std = np.array([config.position_std, config.position_std, config.heading_std])
    errors = noise * std
    outlier = uniforms[:, 1] < config.outlier_probability
    if np.any(outlier):
        angle = 2.0 * math.pi * uniforms[:, 2]
        sign = np.where(uniforms[:, 3] < 0.5, -1.0, 1.0)
        jump = np.stack([config.outlier_position * np.cos(angle),
                         config.outlier_position * np.sin(angle),
                         config.outlier_heading * sign], axis=1)
        errors = errors + jump * outlier[:, None]
    valid = uniforms[:, 0] >= config.dropout_probability
    return np.asarray(errors, dtype=np.float64), valid


def measure(truth: FloatArray, errors: FloatArray) -> FloatArray:
    """Measured pose(s): truth + errors with the heading wrapped to (−π, π] (new array)."""
    pose = np.array(truth, dtype=np.float64) + errors
    pose[..., 2] = wrap_angles(np.asarray(pose[..., 2], dtype=np.float64))
    return pose
