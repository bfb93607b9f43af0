"""Planar kinematics shared by the vessels, sensors and the DP controller.

Earth frame `map_ned` (x north, y east), body frame `base_link_fsd`; ψ is the rotation about the
down axis. R(ψ) is the 3-DOF rotation of Fossen (2011) eq. 2.61 (his J(η) reduced to the
horizontal plane): η̇ = R(ψ) ν.
"""
from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def wrap_angle(angle: float) -> float:
    """Wrap an angle [rad] to (−π, π]."""
    wrapped = math.remainder(angle, 2.0 * math.pi)  # in [−π, π]
    return math.pi if wrapped == -math.pi else wrapped


def wrap_angles(angles: FloatArray) -> FloatArray:
    """Wrap an array of angles [rad] to (−π, π] (returns a new array)."""
    wrapped = np.asarray(np.remainder(angles + np.pi, 2.0 * np.pi) - np.pi, dtype=np.float64)
    wrapped[wrapped == -np.pi] = np.pi
    return wrapped


def rotation(heading: float) -> FloatArray:
    """R(ψ): body-frame vector → earth frame, 3×3 (Fossen 2011, eq. 2.61 in the plane)."""
    c, s = math.cos(heading), math.sin(heading)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def earth_to_body(heading: float, vector_earth: FloatArray) -> FloatArray:
    """R(ψ)ᵀ v: an earth-fixed generalized vector (north, east, yaw) in the body frame."""
    c, s = math.cos(heading), math.sin(heading)
    north, east, yaw = float(vector_earth[0]), float(vector_earth[1]), float(vector_earth[2])
    return np.array([c * north + s * east, -s * north + c * east, yaw])


def body_to_earth(heading: float, vector_body: FloatArray) -> FloatArray:
    """R(ψ) v: a body-frame generalized vector (surge, sway, yaw) in the earth frame."""
    c, s = math.cos(heading), math.sin(heading)
    surge, sway, yaw = float(vector_body[0]), float(vector_body[1]), float(vector_body[2])
    return np.array([c * surge - s * sway, s * surge + c * sway, yaw])
