"""Vessel models: the thesis 1-DOF and 3-DOF models and three 3-DOF DP vessels.

All vessels share one state layout, a list of six floats [north m, east m, ψ rad, u m/s,
v m/s, r rad/s] (η then ν), and one input layout, eight floats
[τ_surge N, τ_sway N, τ_yaw N·m (body, from the actuators), f_north N, f_east N, f_yaw N·m
(earth-fixed disturbance: wind, drift, first-order waves), v_c,north, v_c,east m/s (current)].
Earth-fixed forces enter through G(ψ) = R(ψ)ᵀ; the current through the relative velocity
ν_r = ν − R(ψ)ᵀ [v_c; 0] in the damping.

Thesis models (Franz 2018 §5.1.2–5.1.3), diagonal, per DOF i:
    η̇ = R(ψ) ν,   ν̇_i = a_i ν_r,i |ν_r,i| + b_i (τ_i + (R(ψ)ᵀ f)_i).
1-DOF (eq. 5.5–5.7): a = −0.017 1/m, b = 0.00068 1/kg in surge, zero elsewhere (east and yaw
stay 0, so R(ψ) = I and the model is exactly ẋ1 = x2, ẋ2 = a x2|x2| + b(τc + τ_wave)).
3-DOF (eq. 5.8, A, B, G(ψ) not in the surviving text; our choice): A = diag(a, a, 10 a),
B = diag(b, b, b), G(ψ) = R(ψ)ᵀ (earth-fixed wave forces to the body), J(ψ) = R(ψ). Surge and
sway copy the 1-DOF dynamics; yaw has 10× the quadratic damping, so its quadratic-damping step
response u(t) = u∞ tanh(t/T_q), T_q = 1/√(−a b τ), is √10 ≈ 3.2× faster for the same input
(for τ = 100: T_q = 29 s in surge/sway, 9.3 s in yaw).

Supply vessel (Fossen, Sagatun & Sørensen 1996; MSS `supply.m`; anchors §2): M ν̇ + D ν_r = τ +
R(ψ)ᵀ f, η̇ = R(ψ) ν, linear damping, valid below about 3 m/s. M, D in SI from Mbis, Dbis:
M = m T⁻¹ Mbis T⁻¹, D = m √(g/L) T⁻¹ Dbis T⁻¹, T⁻¹ = diag(1, 1, L). Open-loop time constants
(eigenvalues of M⁻¹D) ≈ 88 s, 44 s, 11.5 s.

Shuttle tanker (`tanker`; our own design, not a published model: a test hull the predictor was
never developed on, twice the supply vessel's length and five times its mass). The same linear
model in the same nondimensional form (the bis system, `bis_matrices`, as MSS supply.m), with
L = 150 m, beam 27 m, draught 9.5 m, block coefficient 0.80: m = ρ L B T C_b = 31.55e6 kg
(ρ = 1025 kg/m³). Mbis: surge 1.05 (5 % added mass; a slender hull's is small), sway 1.95,
yaw 0.12 (radius of gyration with added inertia 0.35 L), sway–yaw coupling −0.06. Dbis from
chosen open-loop time constants M_ii / D_ii of 200 s (surge: a slender hull, little damping),
60 s (sway) and 25 s (yaw), i.e. Dbis_ii = Mbis_ii / (√(g/L) T_i), couplings −0.008 and
−0.003. Eigen time constants ≈ 200 s, 60 s, 25 s (the supply vessel's 88, 44, 11.5 s): a
slower vessel, not the supply vessel scaled (Froude scaling would give 123, 62, 16 s). Its
thrusters (`tunnels_and_mains`): the supply vessel's layout with lever arms for 150 m and
larger units, 5.6 MN surge, 3.0 MN sway, 226 MN·m yaw at full RPM.

Workboat (`workboat`; our own design, not a published model: the other end of the size range, a
40 m DP offshore workboat, e.g. for ROV support). L = 40 m, beam 11 m, draught 3.5 m, block
coefficient 0.60: m = 0.947e6 kg (a sixth of the supply vessel's). Mbis: surge 1.08, sway 1.7
(a beamy, shallow hull), yaw 0.14, coupling −0.05; Dbis from time constants of 50 s (surge),
20 s (sway) and 6 s (yaw), couplings −0.01 and −0.004. Eigen time constants ≈ 50 s, 20 s,
6 s: faster than the supply vessel Froude-scaled to 40 m (64, 32, 8.3 s). Thrusters: the same
layout for 40 m with small units, 307 kN surge, 200 kN sway, 4.2 MN·m yaw.

Crew boat (`crewboat`; our own design, not a published model): a *development* hull of the
workboat's class, for work on what fails there without screening on the test hulls (tanker,
workboat). L = 30 m, beam 8 m, draught 2.5 m, block coefficient 0.55: m = 0.338e6 kg. Mbis:
surge 1.1, sway 1.6, yaw 0.13, coupling −0.04; Dbis from time constants of 40 s, 15 s and 5 s,
couplings −0.008 and −0.003. Thrusters for 30 m: 128 kN surge, 87.5 kN sway, 1.35 MN·m yaw.

First-order wave motion under force superposition (`wave_rates_fn`): the wave-frequency state
x_WF (same layout) is the response of the model *linearized once, at the run's operating point*
(`wave_operating_speed`), to the first-order wave force, rotated with the LF heading, and the
total motion is x_LF + x_WF (Fossen 2011 §10.2's LF/WF separation: a linear, zero-mean WF part).
Integrating one nonlinear vessel with the wave force inside instead makes the quadratic damping
rectify the ≈ 0.4 m/s wave velocity into a mean force, so that vessel and a wave-free twin drift
apart by metres within minutes (measured: 7–25 m std over 10 min in the
1-DOF scenarios); that rectified force is a second-order wave effect, which the environment
models separately as the slowly varying drift bias. So is a WF damping that follows the LF
velocity: without restoring force, η_w then shifts its mean each time the vessel speeds up (the
seventeenth session measured 0.06–0.19 m RMS of such slow motion on onedof_feedback), which is
why the slope is held at the operating point.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
import math

import numpy as np

from sim_ros.physics.integrate import RatesFn, State
from sim_ros.physics.kinematics import FloatArray, earth_to_body
from sim_ros.physics.thrusters import ThrusterConfig, tunnels_and_mains

# --- thesis models, eq. 5.6-5.7 ---------------------------------------------------------------
ONEDOF_A = -0.017  # 1/m, quadratic damping coefficient a (eq. 5.6)
ONEDOF_B = 0.00068  # 1/kg, input gain b (eq. 5.7); equivalent mass 1/b ≈ 1471 kg
THREEDOF_A = (ONEDOF_A, ONEDOF_A, 10.0 * ONEDOF_A)  # our choice, see module docstring
THREEDOF_B = (ONEDOF_B, ONEDOF_B, ONEDOF_B)
# Operating speeds of the documented linearization D_i = 2|a_i| u0_i / b_i (m/s, m/s, rad/s):
# typical DP velocities; linear time constants 1/(2|a| u0) = 294 s, 294 s, 147 s.
THESIS_OPERATING_SPEED = (0.1, 0.1, 0.02)

# --- supply vessel, MSS supply.m ----------------------------------------------------------------
SUPPLY_LENGTH = 76.2  # m, L
SUPPLY_MASS = 6000e3  # kg, m
GRAVITY = 9.81  # m/s²
SUPPLY_MBIS = np.array([[1.1274, 0.0, 0.0], [0.0, 1.8902, -0.0744], [0.0, -0.0744, 0.1278]])
SUPPLY_DBIS = np.array([[0.0358, 0.0, 0.0], [0.0, 0.1183, -0.0124], [0.0, -0.0041, 0.0308]])


def bis_matrices(mass: float, length: float, mass_bis: FloatArray,
                 damping_bis: FloatArray) -> tuple[FloatArray, FloatArray]:
    """M = m T⁻¹ Mbis T⁻¹ and D = m √(g/L) T⁻¹ Dbis T⁻¹ in SI, T⁻¹ = diag(1, 1, L).

    The bis system of Fossen, Sagatun & Sørensen 1996 (anchors §2, MSS supply.m): `mass` m
    [kg], `length` L [m]; returns M [kg, kg·m, kg·m²] and D [kg/s, kg·m/s, kg·m²/s]. The
    inputs are not modified.
    """
    t_inv = np.diag([1.0, 1.0, length])
    return (np.asarray(mass * t_inv @ mass_bis @ t_inv, dtype=np.float64),
            np.asarray(mass * math.sqrt(GRAVITY / length) * t_inv @ damping_bis @ t_inv,
                       dtype=np.float64))


SUPPLY_M, SUPPLY_D = bis_matrices(SUPPLY_MASS, SUPPLY_LENGTH, SUPPLY_MBIS, SUPPLY_DBIS)
SUPPLY_CURRENT_SPEED = 0.5  # m/s, MSS SIMsupply.m
SUPPLY_CURRENT_DIRECTION = math.radians(20.0)  # rad, β_c in MSS SIMsupply.m

SEA_WATER_DENSITY = 1025.0  # kg/m³, ρ


@dataclass(frozen=True)
class HullDesign:
    """A DP hull of our own design: main dimensions, bis coefficients and thrusters."""

    length: float  # m, L
    beam: float  # m, B
    draught: float  # m, T
    block_coefficient: float  # C_b
    mass_bis: FloatArray  # Mbis
    damping_bis: FloatArray  # Dbis
    thrusters: ThrusterConfig

    @property
    def displacement(self) -> float:
        """The displaced mass m = ρ L B T C_b [kg]."""
        return (SEA_WATER_DENSITY * self.length * self.beam * self.draught
                * self.block_coefficient)

    def vessel(self) -> DpVessel:
        """The linear DP model of this hull (`bis_matrices`) with its thrusters."""
        mass, damping = bis_matrices(self.displacement, self.length, self.mass_bis,
                                     self.damping_bis)
        return DpVessel(mass, damping, self.thrusters)


# Shuttle tanker, our own design (module docstring): m ≈ 31.55e6 kg; tunnel thrusters 750 kN,
# mains 2.8 MN (9 m off the centre line) at full RPM.
TANKER_DESIGN = HullDesign(
    150.0, 27.0, 9.5, 0.80,
    mass_bis=np.array([[1.05, 0.0, 0.0], [0.0, 1.95, -0.06], [0.0, -0.06, 0.12]]),
    damping_bis=np.array([[0.0205, 0.0, 0.0], [0.0, 0.127, -0.008], [0.0, -0.003, 0.0188]]),
    thrusters=tunnels_and_mains((62.0, 55.0, -55.0, -62.0), 9.0, 12.0, 110.0))
# Workboat, our own design: m ≈ 0.947e6 kg; tunnels 50 kN, mains 154 kN (4 m off).
WORKBOAT_DESIGN = HullDesign(
    40.0, 11.0, 3.5, 0.60,
    mass_bis=np.array([[1.08, 0.0, 0.0], [0.0, 1.7, -0.05], [0.0, -0.05, 0.14]]),
    damping_bis=np.array([[0.0436, 0.0, 0.0], [0.0, 0.1716, -0.01], [0.0, -0.004, 0.0471]]),
    thrusters=tunnels_and_mains((16.0, 13.0, -14.0, -17.0), 4.0, 0.8, 6.0))
# Crew boat, our own design, the small class's development hull: m ≈ 0.338e6 kg; tunnels
# 21.9 kN, mains 64 kN (3 m off).
CREWBOAT_DESIGN = HullDesign(
    30.0, 8.0, 2.5, 0.55,
    mass_bis=np.array([[1.1, 0.0, 0.0], [0.0, 1.6, -0.04], [0.0, -0.04, 0.13]]),
    damping_bis=np.array([[0.0481, 0.0, 0.0], [0.0, 0.1865, -0.008], [0.0, -0.003, 0.0455]]),
    thrusters=tunnels_and_mains((12.0, 10.0, -10.0, -12.0), 3.0, 0.35, 2.5))

VESSEL_KINDS = ('onedof', 'threedof', 'supply', 'tanker', 'workboat', 'crewboat')
# f(x_LF, x_WF, input) → ẋ_WF; input = the 8 LF inputs + first-order wave force (3, earth)
WaveRatesFn = Callable[[Sequence[float], Sequence[float], Sequence[float]], State]


@dataclass(frozen=True)
class LinearModel:
    """Linear(ized) model M ν̇ + D ν = τ for observers and controller tuning (3×3, SI)."""

    mass: FloatArray
    damping: FloatArray
    operating_speed: tuple[float, float, float]  # (m/s, m/s, rad/s), 0 where exact

    def time_constants(self) -> FloatArray:
        """Open-loop time constants 1/λ_i of M⁻¹D [s], sorted descending."""
        eig = np.linalg.eigvals(np.linalg.solve(self.mass, self.damping)).real
        return np.asarray(np.sort(1.0 / eig)[::-1], dtype=np.float64)


@dataclass(frozen=True)
class ThesisVessel:
    """Diagonal quadratic-damping model of the thesis (eq. 5.5 and 5.8)."""

    quad_damping: tuple[float, float, float]  # a_i [1/m or 1/rad]
    input_gain: tuple[float, float, float]  # b_i [1/kg or 1/(kg·m²)]
    ndof: int

    def __post_init__(self) -> None:
        """Validate: a_i <= 0, b_i >= 0 and b_i > 0 on the used DOFs."""
        if self.ndof not in (1, 3):
            raise ValueError(f'thesis vessel ndof must be 1 or 3, got {self.ndof}')
        if any(a > 0 for a in self.quad_damping) or any(b < 0 for b in self.input_gain):
            raise ValueError('thesis vessel needs a_i <= 0 (damping) and b_i >= 0 (input gain)')
        if any(b <= 0 for b in self.input_gain[: self.ndof]):
            raise ValueError(f'input gain b must be > 0 on the {self.ndof} used DOFs')

    def linearize(self, operating_speed: Sequence[float] = THESIS_OPERATING_SPEED
                  ) -> LinearModel:
        """M = diag(1/b), D = diag(2|a| u0 / b): slope of a u|u| at u0 (unused DOFs copy surge)."""
        gains = [b if b > 0 else self.input_gain[0] for b in self.input_gain]
        damps = [a if b > 0 else self.quad_damping[0]
                 for a, b in zip(self.quad_damping, self.input_gain, strict=True)]
        speeds = tuple(float(s) for s in operating_speed)
        mass = np.diag([1.0 / b for b in gains])
        damping = np.diag([2.0 * abs(a) * s / b for a, s, b in zip(damps, speeds, gains,
                                                                     strict=True)])
        return LinearModel(mass, damping, (speeds[0], speeds[1], speeds[2]))

    def rates_fn(self) -> RatesFn:
        """f(state, input) → state derivative (plain floats; see module docstring)."""
        a_u, a_v, a_r = self.quad_damping
        b_u, b_v, b_r = self.input_gain
        cos, sin = math.cos, math.sin

        def rates(x: Sequence[float], inp: Sequence[float]) -> State:
            psi, u, v, r = x[2], x[3], x[4], x[5]
            c, s = cos(psi), sin(psi)
            fn, fe, vcn, vce = inp[3], inp[4], inp[6], inp[7]
            ur = u - (c * vcn + s * vce)
            vr = v - (-s * vcn + c * vce)
            return [c * u - s * v, s * u + c * v, r,
                    a_u * ur * abs(ur) + b_u * (inp[0] + c * fn + s * fe),
                    a_v * vr * abs(vr) + b_v * (inp[1] - s * fn + c * fe),
                    a_r * r * abs(r) + b_r * (inp[2] + inp[5])]

        return rates

    def wave_rates_fn(self, operating_speed: Sequence[float]) -> WaveRatesFn:
        """First-order wave motion of the model linearized at the run's operating point.

        ν̇_w,i = −2|a_i| u_w,i ν_w,i + b_i (R(ψ_LF)ᵀ f_w)_i, η̇_w = R(ψ_LF) ν_w, with u_w the
        operating speed [m/s, m/s, rad/s] (`wave_operating_speed`: the initial relative velocity
        floored at THESIS_OPERATING_SPEED). The damping is constant for the run, so (at constant
        heading exactly) M ν_w + D_w η_w − ∫R(ψ)ᵀ f_w dt is conserved and η_w keeps the zero
        mean it is drawn with (a damping that followed |ν_r,LF| moved that mean whenever the
        vessel sped up: a rectified, second-order wave effect without restoring force; the drift
        bias of `environment` is where second-order effects belong).
        """
        speeds = [float(v) for v in operating_speed]
        if len(speeds) != 3 or not all(math.isfinite(v) and v > 0.0 for v in speeds):
            raise ValueError(f'operating_speed must be 3 finite speeds > 0 [m/s, m/s, rad/s] '
                             f'(use wave_operating_speed), got {operating_speed}')
        d_u, d_v, d_r = (2.0 * a * v for a, v in zip(self.quad_damping, speeds, strict=True))
        b_u, b_v, b_r = self.input_gain
        cos, sin = math.cos, math.sin

        def rates(lf: Sequence[float], wf: Sequence[float], inp: Sequence[float]) -> State:
            c, s = cos(lf[2]), sin(lf[2])
            u, v, r = wf[3], wf[4], wf[5]
            fn, fe, fy = inp[8], inp[9], inp[10]
            return [c * u - s * v, s * u + c * v, r,
                    d_u * u + b_u * (c * fn + s * fe),
                    d_v * v + b_v * (-s * fn + c * fe),
                    d_r * r + b_r * fy]

        return rates


def wave_operating_speed(heading: float, velocity: Sequence[float],
                         current: Sequence[float] = (0.0, 0.0)) -> tuple[float, float, float]:
    """Operating point u_w [m/s, m/s, rad/s] of a thesis vessel's first-order wave motion.

    max(|ν − R(ψ)ᵀ [v_c; 0]|, THESIS_OPERATING_SPEED) per DOF, for the body velocity ν
    (surge, sway, yaw rate) and the earth-fixed mean current v_c (north, east) at the run's start.
    """
    rel = np.asarray(velocity, dtype=np.float64) - earth_to_body(
        heading, np.array([current[0], current[1], 0.0]))
    u, v, r = (max(abs(float(x)), floor) for x, floor in zip(rel, THESIS_OPERATING_SPEED,
                                                              strict=True))
    return (u, v, r)


@dataclass(frozen=True)
class DpVessel:
    """Linear 3-DOF DP model M ν̇ + D ν_r = τ + R(ψ)ᵀ f and its thrusters (as MSS supply.m)."""

    mass: FloatArray
    damping: FloatArray
    thrusters: ThrusterConfig = field(default_factory=ThrusterConfig)

    def __post_init__(self) -> None:
        """Validate: 3×3, M symmetric positive definite."""
        if self.mass.shape != (3, 3) or self.damping.shape != (3, 3):
            raise ValueError('DP vessel M and D must be 3×3')
        if not np.allclose(self.mass, self.mass.T) or np.any(np.linalg.eigvalsh(self.mass) <= 0):
            raise ValueError('DP vessel M must be symmetric positive definite')

    @property
    def ndof(self) -> int:
        """Always 3."""
        return 3

    def linearize(self) -> LinearModel:
        """The model is linear: (M, D) exactly."""
        return LinearModel(self.mass.copy(), self.damping.copy(), (0.0, 0.0, 0.0))

    def rates_fn(self) -> RatesFn:
        """f(state, input) → state derivative (plain floats; see module docstring)."""
        m_inv = np.linalg.inv(self.mass)
        # ν̇ = M⁻¹ (g − D ν_r): precompute M⁻¹ and −M⁻¹D as nested float tuples
        mi = [[float(v) for v in row] for row in m_inv]
        md = [[float(v) for v in row] for row in -(m_inv @ self.damping)]
        (p00, p01, p02), (p10, p11, p12), (p20, p21, p22) = mi
        (q00, q01, q02), (q10, q11, q12), (q20, q21, q22) = md
        cos, sin = math.cos, math.sin

        def rates(x: Sequence[float], inp: Sequence[float]) -> State:
            psi, u, v, r = x[2], x[3], x[4], x[5]
            c, s = cos(psi), sin(psi)
            fn, fe, vcn, vce = inp[3], inp[4], inp[6], inp[7]
            ur = u - (c * vcn + s * vce)
            vr = v - (-s * vcn + c * vce)
            gx = inp[0] + c * fn + s * fe
            gy = inp[1] - s * fn + c * fe
            gn = inp[2] + inp[5]
            return [c * u - s * v, s * u + c * v, r,
                    p00 * gx + p01 * gy + p02 * gn + q00 * ur + q01 * vr + q02 * r,
                    p10 * gx + p11 * gy + p12 * gn + q10 * ur + q11 * vr + q12 * r,
                    p20 * gx + p21 * gy + p22 * gn + q20 * ur + q21 * vr + q22 * r]

        return rates

    def wave_rates_fn(self) -> WaveRatesFn:
        """First-order wave motion (force superposition) of the linear model.

        M ν̇_w + D ν_w = R(ψ_LF)ᵀ f_w, η̇_w = R(ψ_LF) ν_w (exact up to the ψ_w ν_LF coupling).
        """
        m_inv = np.linalg.inv(self.mass)
        mi = [[float(v) for v in row] for row in m_inv]
        md = [[float(v) for v in row] for row in -(m_inv @ self.damping)]
        (p00, p01, p02), (p10, p11, p12), (p20, p21, p22) = mi
        (q00, q01, q02), (q10, q11, q12), (q20, q21, q22) = md
        cos, sin = math.cos, math.sin

        def rates(lf: Sequence[float], wf: Sequence[float], inp: Sequence[float]) -> State:
            c, s = cos(lf[2]), sin(lf[2])
            u, v, r = wf[3], wf[4], wf[5]
            fn, fe = inp[8], inp[9]
            gx, gy, gn = c * fn + s * fe, -s * fn + c * fe, inp[10]
            return [c * u - s * v, s * u + c * v, r,
                    p00 * gx + p01 * gy + p02 * gn + q00 * u + q01 * v + q02 * r,
                    p10 * gx + p11 * gy + p12 * gn + q10 * u + q11 * v + q12 * r,
                    p20 * gx + p21 * gy + p22 * gn + q20 * u + q21 * v + q22 * r]

        return rates


Vessel = ThesisVessel | DpVessel

ONEDOF = ThesisVessel((ONEDOF_A, 0.0, 0.0), (ONEDOF_B, 0.0, 0.0), ndof=1)
THREEDOF = ThesisVessel(THREEDOF_A, THREEDOF_B, ndof=3)
SUPPLY = DpVessel(SUPPLY_M.copy(), SUPPLY_D.copy())
TANKER = TANKER_DESIGN.vessel()
WORKBOAT = WORKBOAT_DESIGN.vessel()
CREWBOAT = CREWBOAT_DESIGN.vessel()


def make_vessel(kind: str) -> Vessel:
    """The vessel called `kind` (one of `VESSEL_KINDS`)."""
    vessels: dict[str, Vessel] = {'onedof': ONEDOF, 'threedof': THREEDOF, 'supply': SUPPLY,
                                  'tanker': TANKER, 'workboat': WORKBOAT, 'crewboat': CREWBOAT}
    if kind not in vessels:
        raise ValueError(f'vessel must be one of {VESSEL_KINDS}, got {kind!r}')
    return vessels[kind]


def terminal_speed(quad_damping: float, input_gain: float, force: float) -> float:
    """Steady speed of u̇ = a u|u| + b τ: sign(τ) √(b|τ|/−a) (thesis eq. 5.5)."""
    return math.copysign(math.sqrt(input_gain * abs(force) / -quad_damping), force)
