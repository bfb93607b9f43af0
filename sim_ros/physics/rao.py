"""First-order wave motion of a DP vessel from parametric motion RAOs (our model).

A **response amplitude operator** RAO_i(ω, β) is the complex ratio of the first-order motion in
DOF i (surge m, sway m, yaw rad) to the amplitude of a regular wave of frequency ω coming from
the relative direction β = θ_wave − ψ (Fossen 2011 §8.2 and §10.2.1; Faltinsen 1990 ch. 3). Our
RAOs are not computed from a hull (no panel code): they are a smooth parametric form with the
right limits, written for this simulator:

    RAO_surge(ω, β) = −cos β · K_x · G_x(ω) · e^{−iπ/2}
    RAO_sway(ω, β)  = −sin β · K_y · G_y(ω) · e^{−iπ/2}
    RAO_yaw(ω, β)   =  sin 2β · K_ψ · k(ω) · G_ψ(ω)
    G_i(ω) = (1 + i ω/ω_c,i)^{−n}   (n-fold first-order low pass; |G| → 1 for long waves)
    ω_c,i = √(2π g / (κ_i L)),   k(ω) = ω²/g   (deep water: wavelength 2πg/ω² = κ_i L at ω_c,i)

- Long waves (ω → 0): the hull follows the horizontal particle motion. A wave ζ = a cos χ has the
  surface displacement a sin χ = a cos(χ − π/2) along its propagation direction, which points
  to θ + π, i.e. at −cos β (surge) and −sin β (sway) in the body frame: hence the gains K_x = K_y
  = 1 m/m are the physical long-wave limit. Yaw follows the wave slope k a (rad) with a
  gain K_ψ [rad/rad] and vanishes for long waves (the hull sees a uniform wave) and in head,
  following and beam seas (sin 2β: symmetric hull).
- Short waves (wavelength ≲ κ L): the force integrates over the hull and cancels; with inertia
  the motion falls like ω^{−n} above ω_c. Surge cancels over the length L (κ_x ≈ 1), sway over
  the beam (κ_y ≈ 0.5 for a supply vessel with B/L ≈ 0.24 and its deeper draft), yaw over L.
- Phase: the direction factors are signed, so the phase jumps by π where a factor changes sign
  (e.g. bow vs stern seas in surge) and the motion is continuous in β. The low pass adds a lag
  n·atan(ω/ω_c). Relative phases of the components come from the sea (`WaveComponents.phase`).

Wave motion (motion superposition, Fossen 2011 §8.2.1), components k of a `WaveComponents` sea
with the wave field evaluated at the origin of map_ned (DP: the vessel moves a few tens of
metres, ≪ wavelength; zero speed: the encounter frequency is ω):

    η_w,body,i(t) = Σ_k A_k Re[RAO_i(ω_k, θ_k − ψ(t)) e^{i(ω_k t + φ_k)}]
    η_w(t) = R(ψ(t)) η_w,body(t)     (north, east, yaw; ψ the LF heading)

The heading enters only through cos ψ, sin ψ, cos 2ψ, sin 2ψ (expand cos(θ − ψ) etc.), so the
sum is split into six heading-free series (`motion_basis`, one matrix product over the
components for a block of times) and a cheap per-sample combination with the current heading
(`motion_from_basis`). Pure functions: inputs are never modified.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import math

import numpy as np
import numpy.typing as npt

from sim_ros.physics.kinematics import FloatArray
from sim_ros.physics.sea_spectrum import GRAVITY, WaveComponents

ComplexArray = npt.NDArray[np.complex128]
SUPPLY_RAO_LENGTH = 76.2  # m, L of the MSS supply vessel (sim_ros.physics.vessels)
BASE_PHASE = -0.5 * math.pi  # rad, surface displacement lags elevation by 90° (deep water)


@dataclass(frozen=True)
class RaoParams:
    """Parameters of the parametric RAO (module docstring); defaults for the supply vessel.

    `length` L [m]; `surge_gain`, `sway_gain` K_x, K_y [m/m] (long-wave limits, 1 physical);
    `yaw_gain` K_ψ [rad of yaw per rad of wave slope]; `*_cutoff` κ_i [-]: the cutoff
    wavelength as a fraction of L; `order` n of the low pass (roll-off ω^{−n}).
    """

    length: float = SUPPLY_RAO_LENGTH
    surge_gain: float = 1.0
    sway_gain: float = 1.0
    yaw_gain: float = 1.0
    surge_cutoff: float = 1.0
    sway_cutoff: float = 0.5
    yaw_cutoff: float = 1.0
    order: int = 2

    def __post_init__(self) -> None:
        """Validate: positive length and cutoffs, gains >= 0, order 1–6."""
        if not (self.length > 0.0 and math.isfinite(self.length)):
            raise ValueError(f'rao.length must be the vessel length in m (> 0), got {self.length}')
        for name in ('surge_gain', 'sway_gain', 'yaw_gain'):
            value = getattr(self, name)
            if not (value >= 0.0 and math.isfinite(value)):
                raise ValueError(f'rao.{name} must be >= 0, got {value}')
        for name in ('surge_cutoff', 'sway_cutoff', 'yaw_cutoff'):
            value = getattr(self, name)
            if not (value > 0.0 and math.isfinite(value)):
                raise ValueError(f'rao.{name} (cutoff wavelength / length) must be > 0, got '
                                 f'{value}')
        if not (isinstance(self.order, int) and 1 <= self.order <= 6):
            raise ValueError(f'rao.order must be an integer 1–6 (2 is typical), got {self.order}')

    def cutoff_frequencies(self) -> FloatArray:
        """ω_c per DOF (surge, sway, yaw) [rad/s]: wavelength κ_i L in deep water."""
        kappa = np.array([self.surge_cutoff, self.sway_cutoff, self.yaw_cutoff])
        return np.asarray(np.sqrt(2.0 * math.pi * GRAVITY / (kappa * self.length)),
                          dtype=np.float64)


def frequency_response(params: RaoParams, omega: FloatArray) -> ComplexArray:
    """Direction-free part C_i(ω) of the RAOs, shape (3, *ω.shape): RAO_i = f_i(β) C_i(ω).

    f = (−cos β, −sin β, sin 2β); C_surge = K_x G_x e^{−iπ/2}, C_sway = K_y G_y e^{−iπ/2},
    C_yaw = K_ψ k G_ψ.
    """
    w = np.asarray(omega, dtype=np.float64)
    cutoff = params.cutoff_frequencies()
    lowpass = (1.0 + 1j * w[None, ...] / cutoff.reshape((3,) + (1,) * w.ndim)) ** (-params.order)
    base = np.exp(1j * BASE_PHASE)
    gains = np.stack([np.full(w.shape, params.surge_gain * base),
                      np.full(w.shape, params.sway_gain * base),
                      params.yaw_gain * w**2 / GRAVITY + 0j])
    return np.asarray(gains * lowpass, dtype=np.complex128)


def direction_factors(beta: FloatArray) -> FloatArray:
    """Signed direction factors f(β) = (−cos β, −sin β, sin 2β), shape (3, ...)."""
    b = np.asarray(beta, dtype=np.float64)
    return np.asarray(np.stack([-np.cos(b), -np.sin(b), np.sin(2.0 * b)]), dtype=np.float64)


def rao(params: RaoParams, omega: FloatArray, beta: FloatArray) -> ComplexArray:
    """Complex RAO (3, *shape) for surge [m/m], sway [m/m], yaw [rad/m] at ω [rad/s], β [rad].

    ω and β broadcast against each other.
    """
    w, b = np.broadcast_arrays(np.asarray(omega, dtype=np.float64),
                               np.asarray(beta, dtype=np.float64))
    return np.asarray(direction_factors(b) * frequency_response(params, w),
                      dtype=np.complex128)


def rao_amplitude_phase(params: RaoParams, omega: FloatArray,
                        beta: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(|RAO|, ∠RAO in (−π, π]), each (3, *shape), per DOF surge, sway, yaw."""
    value = rao(params, omega, beta)
    return (np.asarray(np.abs(value), dtype=np.float64),
            np.asarray(np.angle(value), dtype=np.float64))


def motion_variance(components: WaveComponents, params: RaoParams,
                    heading: float) -> FloatArray:
    """Body-frame variance (surge m², sway m², yaw rad²) at a fixed heading: Σ A²|RAO|²/2.

    Exact for a long record when all component frequencies differ (no common frequencies).
    """
    value = rao(params, components.frequency, components.direction - heading)
    return np.asarray(0.5 * (np.abs(value) ** 2) @ components.amplitude**2, dtype=np.float64)


def motion_basis(components: WaveComponents, params: RaoParams,
                 times: FloatArray) -> FloatArray:
    """The six heading-free series (len(times), 6) of the wave motion (module docstring).

    With P_i,k(t) = A_k Re[C_i(ω_k) e^{i(ω_k t + φ_k)}]: columns Σ cos θ P_x, Σ sin θ P_x,
    Σ sin θ P_y, Σ cos θ P_y, Σ sin 2θ P_ψ, Σ cos 2θ P_ψ. Then (`motion_from_basis`)
    surge = −(cos ψ B0 + sin ψ B1), sway = −(cos ψ B2 − sin ψ B3),
    yaw = cos 2ψ B4 − sin 2ψ B5.
    """
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    resp = frequency_response(params, components.frequency) * components.amplitude  # (3, K)
    theta = components.direction
    cos_t, sin_t = np.cos(theta), np.sin(theta)
    cos_2t, sin_2t = np.cos(2.0 * theta), np.sin(2.0 * theta)
    dirs = np.stack([cos_t, sin_t, sin_t, cos_t, sin_2t, cos_2t], axis=1)  # (K, 6)
    dof = [0, 0, 1, 1, 2, 2]
    weight_cos = resp.real[dof].T * dirs  # Re C: multiplies cos χ
    weight_sin = resp.imag[dof].T * dirs  # Im C: multiplies −sin χ
    chi = t[:, None] * components.frequency[None, :] + components.phase[None, :]
    return np.asarray(np.cos(chi) @ weight_cos - np.sin(chi) @ weight_sin, dtype=np.float64)


def motion_from_basis(basis: Sequence[float], heading: float) -> tuple[float, float, float]:
    """η_w (north m, east m, yaw rad) from one basis row and the LF heading ψ [rad] (floats).

    Body motion from the expansion of the direction factors in ψ, rotated by R(ψ).
    """
    b0, b1, b2, b3, b4, b5 = (float(v) for v in basis)
    c, s = math.cos(heading), math.sin(heading)
    c2, s2 = c * c - s * s, 2.0 * s * c
    surge = -(c * b0 + s * b1)  # −cos(θ − ψ) expanded
    sway = -(c * b2 - s * b3)  # −sin(θ − ψ)
    yaw = c2 * b4 - s2 * b5  # sin(2θ − 2ψ)
    return (c * surge - s * sway, s * surge + c * sway, yaw)


def wave_motion(components: WaveComponents, params: RaoParams, times: FloatArray,
                heading: float | FloatArray) -> FloatArray:
    """First-order wave motion η_w(t) (len(times), 3) [north m, east m, yaw rad], earth frame.

    `heading` ψ [rad] is the LF heading: a scalar or one value per time. Vectorized over the
    components (one matrix product) and the times.
    """
    basis = motion_basis(components, params, times)
    psi = np.broadcast_to(np.asarray(heading, dtype=np.float64), (basis.shape[0],))
    c, s = np.cos(psi), np.sin(psi)
    c2, s2 = np.cos(2.0 * psi), np.sin(2.0 * psi)
    surge = -(c * basis[:, 0] + s * basis[:, 1])
    sway = -(c * basis[:, 2] - s * basis[:, 3])
    yaw = c2 * basis[:, 4] - s2 * basis[:, 5]
    return np.asarray(np.stack([c * surge - s * sway, s * surge + c * sway, yaw], axis=1),
                      dtype=np.float64)


__all__ = ['RaoParams', 'direction_factors', 'frequency_response', 'motion_basis',
           'motion_from_basis', 'motion_variance', 'rao', 'rao_amplitude_phase', 'wave_motion']
