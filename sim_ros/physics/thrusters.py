"""Supply vessel thrusters: allocation, RPM saturation, shaft dynamics, thrust (MSS SIMsupply.m).

Two bow and two stern tunnel thrusters and two main propellers (anchors §2):
configuration T (3×6, rows surge, sway, yaw; yaw row = lever arms [m]), thrust coefficients
K = diag(3.2 ×4, 31.2 ×2) [N/RPM²], thrust f_i = K_i |n_i| n_i, n in RPM. The other DP hulls
(`vessels.HullDesign`) have the same layout with their own lever arms and coefficients
(`tunnels_and_mains`).
Allocation by pseudo-inverse u = Bᵀ (B Bᵀ)⁻¹ τ with B = T K and u_i = |n_i| n_i
(Fossen 2011 §12.3.2, unconstrained least-norm), then n_c = sign(u)√|u| saturated at n_max.
Shaft dynamics ṅ = (n_c − n)/T_n with n_c held over a sample period are linear and solved
exactly: n(t) = n_c + (n0 − n_c) e^{−t/T_n}.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from sim_ros.physics.kinematics import FloatArray


def tunnels_and_mains_layout(tunnel_arms: tuple[float, float, float, float],
                             main_offset: float) -> FloatArray:
    """Configuration T (3×6) of four tunnel thrusters and two main propellers.

    The tunnels push sway at the lever arms `tunnel_arms` [m, + forward]; the mains push surge
    `main_offset` [m] to port and starboard (yaw arms −offset, +offset). The supply vessel's
    layout (anchors §2) is ((30, 22, −22, −30), 8).
    """
    return np.array([[0.0, 0.0, 0.0, 0.0, 1.0, 1.0],
                     [1.0, 1.0, 1.0, 1.0, 0.0, 0.0],
                     [*tunnel_arms, -main_offset, main_offset]])


def _default_config() -> FloatArray:
    return tunnels_and_mains_layout((30.0, 22.0, -22.0, -30.0), 8.0)  # lever arms in m


def _coefficients(tunnel_coeff: float, main_coeff: float) -> FloatArray:
    return np.array([tunnel_coeff] * 4 + [main_coeff] * 2)  # N/RPM²


def _default_k() -> FloatArray:
    return _coefficients(3.2, 31.2)  # N/RPM²


def _default_n_max() -> FloatArray:
    return np.array([250.0, 250.0, 250.0, 250.0, 160.0, 160.0])  # RPM


@dataclass(frozen=True)
class ThrusterConfig:
    """Thruster layout and limits (defaults: MSS SIMsupply.m)."""

    configuration: FloatArray = field(default_factory=_default_config)  # T, 3×6
    thrust_coeff: FloatArray = field(default_factory=_default_k)  # K_i [N/RPM²]
    max_rpm: FloatArray = field(default_factory=_default_n_max)  # n_max [RPM]
    shaft_time_constant: float = 1.0  # T_n [s]

    def __post_init__(self) -> None:
        """Validate shapes, positivity and that the layout can produce every force."""
        count = self.thrust_coeff.shape[0]
        if self.configuration.shape != (3, count) or self.max_rpm.shape != (count,):
            raise ValueError('thruster configuration must be 3×n with n thrust_coeff and max_rpm')
        if np.any(self.thrust_coeff <= 0) or np.any(self.max_rpm <= 0):
            raise ValueError('thrust coefficients and max RPM must be > 0')
        if not (self.shaft_time_constant > 0.0):
            raise ValueError('shaft time constant must be > 0 s')
        if np.linalg.matrix_rank(self.configuration) < 3:
            raise ValueError('thruster configuration must span surge, sway and yaw (rank 3)')

    @cached_property
    def input_matrix(self) -> FloatArray:
        """B = T K: generalized force per unit |n|n."""
        return np.asarray(self.configuration * self.thrust_coeff, dtype=np.float64)

    @cached_property
    def allocation_matrix(self) -> FloatArray:
        """Bᵀ (B Bᵀ)⁻¹ (Moore–Penrose right inverse)."""
        b = self.input_matrix
        return np.asarray(b.T @ np.linalg.inv(b @ b.T), dtype=np.float64)

    def max_generalized_force(self) -> FloatArray:
        """Largest |τ| per DOF if all thrusters push that DOF alone [N, N, N·m]."""
        f_max = self.thrust_coeff * self.max_rpm**2
        return np.asarray(np.abs(self.configuration) @ f_max, dtype=np.float64)


def tunnels_and_mains(tunnel_arms: tuple[float, float, float, float], main_offset: float,
                      tunnel_coeff: float, main_coeff: float) -> ThrusterConfig:
    """The supply vessel's kind of thruster set for another hull (`tunnels_and_mains_layout`).

    Thrust coefficients K [N/RPM²] `tunnel_coeff` and `main_coeff`; n_max 250 and 160 RPM and
    the shaft time constant as the supply vessel's (`ThrusterConfig` defaults).
    """
    return ThrusterConfig(configuration=tunnels_and_mains_layout(tunnel_arms, main_offset),
                          thrust_coeff=_coefficients(tunnel_coeff, main_coeff))


def allocate(config: ThrusterConfig, tau: FloatArray) -> FloatArray:
    """Commanded shaft speeds n_c [RPM] for τ: pseudo-inverse then RPM saturation."""
    u = config.allocation_matrix @ tau  # u_i = |n_i| n_i
    n_c = np.sign(u) * np.sqrt(np.abs(u))
    return np.asarray(np.minimum(np.maximum(n_c, -config.max_rpm), config.max_rpm),
                      dtype=np.float64)


def shaft_speed(n0: FloatArray, n_cmd: FloatArray, elapsed: FloatArray,
                time_constant: float) -> FloatArray:
    """Exact n(t) of ṅ = (n_c − n)/T_n at the times `elapsed` (m,) → (m, n_thrusters)."""
    decay = np.exp(-np.asarray(elapsed) / time_constant)[:, None]
    return np.asarray(n_cmd + (n0 - n_cmd) * decay, dtype=np.float64)


def generalized_thrust(config: ThrusterConfig, rpm: FloatArray) -> FloatArray:
    """τ = T K |n| n for rpm (…, n_thrusters) → (…, 3) [N, N, N·m]."""
    return np.asarray((np.abs(rpm) * rpm) @ config.input_matrix.T, dtype=np.float64)
