"""Nonlinear passive DP observer with wave filtering (Fossen & Strand 1999; anchors §4).

Continuous-time observer (Fossen 2011, §11.4.1; MSS "Passive DP wave filter", ``exPassiveObs.m``):

    ξ̂̇ = A_w ξ̂ + K1 ỹ                      (wave model, ξ = [ξ1; ξ2], η_w = C_w ξ = ξ2)
    η̂̇ = R(y_ψ) ν̂ + K2 ỹ
    b̂̇ = −T⁻¹ b̂ + K3 ỹ                      (slowly varying environmental bias)
    M ν̂̇ = −D ν̂ + R(y_ψ)ᵀ b̂ + τ + R(y_ψ)ᵀ K4 ỹ
    ỹ = y − η̂ − C_w ξ̂                      (heading component wrapped to (−π, π])

with A_w = [[0, I], [−Ω², −2ΛΩ]], Ω = diag(ω0), Λ = diag(λ), and per DOF i (Fossen & Strand
1999, eq. 36–38)

    K1 = [diag(−2(ζn − λ) ωc/ω0); diag(2 ω0 (ζn − λ))],  K2 = diag(ωc),  ζn > λ, ωc > ω0,

which make the y → η̂ loop (for K3 = K4 = 0) exactly the notch
(s² + 2λω0 s + ω0²)/(s² + 2ζn ω0 s + ω0²) in series with ωc/(s + ωc). K3, K4 follow the
tuning rule 1/T ≪ K3/K4 < ω0 < ωc; `bias_gains` gives the anchors' scaling of the MSS values.

Discretization: R(y_ψ) is held over a sample (zero-order hold on y and τ), so within a step the
observer is linear time-invariant; it is stepped with the exact ZOH solution
x⁺ = e^{Ah} x + ∫₀ʰ e^{As} ds B u (Van Loan's augmented matrix exponential), stable for any
sample time. When every gain has equal surge and sway entries (one ω0 for all DOFs, the
anchors' K3/K4), the observer is invariant to rotating its earth-frame states, so it is stepped in
coordinates rotated by R(y_ψ)ᵀ with one constant transition matrix (same result, no matrix
exponential per sample). The heading innovation is wrapped by feeding the effective heading
measurement
η̂_ψ + ξ̂2_ψ + wrap(y_ψ − η̂_ψ − ξ̂2_ψ), so η̂_ψ stays continuous internally.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import expm

from lf_predictor_ros.core.estimator import EstimatorStatus, check_ndof
from lf_predictor_ros.core.heading import wrap_angle

FloatArray = NDArray[np.float64]
GRAVITY = 9.81  # [m/s²]
_YAW = 2  # index of heading in a pose
TRANSITION_CACHE = 4096  # cached (heading, step) transitions before the cache is cleared


@dataclass(frozen=True)
class ObserverGains:
    """Diagonal observer gains, one entry per DOF (length ndof).

    Attributes:
        wave_peak_freq: ω0 [rad/s] of the wave model A_w.
        wave_damping: λ [-] of the wave model.
        k1_position: gain of ỹ into ξ1 (upper block of K1) [s].
        k1_velocity: gain of ỹ into ξ2 (lower block of K1) [rad/s].
        k2: gain of ỹ into η̂ [rad/s] (= ωc).
        k3: gain of ỹ into b̂ [N/(m·s)], [N·m/(rad·s)] for yaw.
        k4: gain of ỹ into M ν̂̇ [N/m], [N·m/rad] for yaw.
        bias_time: bias time constants T [s].
    """

    wave_peak_freq: FloatArray
    wave_damping: FloatArray
    k1_position: FloatArray
    k1_velocity: FloatArray
    k2: FloatArray
    k3: FloatArray
    k4: FloatArray
    bias_time: FloatArray


def bias_gains(
    mass: float, length: float, ndof: int = 3, gravity: float = GRAVITY
) -> tuple[FloatArray, FloatArray]:
    """Return (K3, K4) diagonals scaled to a vessel of mass [kg] and length [m] (anchors §4).

    MSS ``exPassiveObs.m`` uses K4 = diag(0.1, 0.1, 0.01), K3 = 0.1 K4 in the non-dimensional
    (bis) system; in SI that is K4 = diag(0.1 mg/L, 0.1 mg/L, 0.01 mgL) and
    K3 = 0.1 √(g/L) K4.
    """
    check_ndof(ndof)
    if mass <= 0.0 or length <= 0.0 or gravity <= 0.0:
        raise ValueError('mass [kg], length [m] and gravity [m/s²] must all be > 0')
    k4 = np.array([0.1 * mass * gravity / length, 0.1 * mass * gravity / length,
                   0.01 * mass * gravity * length])[:ndof]
    k3 = 0.1 * np.sqrt(gravity / length) * k4
    return k3, k4


def _per_dof(value: ArrayLike, ndof: int, name: str) -> FloatArray:
    """Broadcast a scalar or take the first ndof entries of a length-ndof/3 vector."""
    arr = np.atleast_1d(np.asarray(value, dtype=np.float64))
    if arr.size == 1:
        return np.full(ndof, float(arr[0]))
    if arr.ndim != 1 or arr.size not in (ndof, 3):
        raise ValueError(f'{name} must be a scalar or have {ndof} (or 3) entries, got {arr.shape}')
    if not np.all(np.isfinite(arr)):
        raise ValueError(f'{name} must be finite, got {arr}')
    return arr[:ndof].copy()


def observer_gains(
    wave_peak_freq: ArrayLike,
    *,
    k3: ArrayLike,
    k4: ArrayLike,
    ndof: int = 3,
    wave_damping: ArrayLike = 0.1,
    relative_damping: ArrayLike = 1.0,
    cutoff_ratio: ArrayLike = 1.2,
    bias_time: ArrayLike = 1000.0,
) -> ObserverGains:
    """Gains of Fossen & Strand (1999) from ω0, λ, ζn and ωc = cutoff_ratio · ω0.

    Args:
        wave_peak_freq: ω0 [rad/s], scalar or per DOF.
        k3: bias gain diagonal (see `bias_gains`).
        k4: velocity-injection gain diagonal (see `bias_gains`).
        ndof: 1 (surge) or 3.
        wave_damping: λ of the wave model [-] (0.1 fits JONSWAP, anchors §3).
        relative_damping: ζn of the notch poles [-], > λ (MSS: 1).
        cutoff_ratio: ωc/ω0 [-], > 1 (MSS: 1.1–1.3).
        bias_time: T [s] (MSS: 1000).
    """
    check_ndof(ndof)
    w0 = _per_dof(wave_peak_freq, ndof, 'wave_peak_freq')
    lam = _per_dof(wave_damping, ndof, 'wave_damping')
    zeta = _per_dof(relative_damping, ndof, 'relative_damping')
    ratio = _per_dof(cutoff_ratio, ndof, 'cutoff_ratio')
    t_bias = _per_dof(bias_time, ndof, 'bias_time')
    k3_arr = _per_dof(k3, ndof, 'k3')
    k4_arr = _per_dof(k4, ndof, 'k4')
    if np.any(w0 <= 0.0):
        raise ValueError(f'wave_peak_freq must be > 0 rad/s, got {w0}')
    if np.any(lam <= 0.0) or np.any(zeta <= lam):
        raise ValueError(f'need 0 < λ < ζn (Fossen & Strand 1999), got λ={lam}, ζn={zeta}')
    if np.any(ratio <= 1.0):
        raise ValueError(f'cutoff_ratio ωc/ω0 must be > 1 (ωc > ω0), got {ratio}')
    if np.any(t_bias <= 0.0) or np.any(k3_arr < 0.0) or np.any(k4_arr < 0.0):
        raise ValueError('bias_time must be > 0 s and k3, k4 >= 0')
    omega_c = ratio * w0  # [rad/s]
    return ObserverGains(
        wave_peak_freq=w0,
        wave_damping=lam,
        k1_position=-2.0 * (zeta - lam) * omega_c / w0,
        k1_velocity=2.0 * w0 * (zeta - lam),
        k2=omega_c,
        k3=k3_arr,
        k4=k4_arr,
        bias_time=t_bias,
    )


def _rotation(heading: float, ndof: int) -> FloatArray:
    """R(ψ) of Fossen 2011 eq. 2.21 restricted to 3 DOF; 1 for the 1-DOF vessel."""
    if ndof == 1:
        return np.ones((1, 1))
    c, s = np.cos(heading), np.sin(heading)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _vessel_matrix(value: ArrayLike, ndof: int, name: str) -> FloatArray:
    """M or D as (ndof, ndof); accepts a scalar for 1 DOF and a 3×3 for either."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        if ndof != 1:
            raise ValueError(f'{name} must be a 3×3 matrix for ndof=3, got a scalar')
        return arr.reshape(1, 1).copy()
    if arr.shape == (3, 3):
        return arr[:ndof, :ndof].copy()
    if arr.shape == (ndof, ndof):
        return arr.copy()
    raise ValueError(f'{name} must be a scalar (1 DOF) or 3×3, got shape {arr.shape}')


def system_matrices(
    gains: ObserverGains, mass: FloatArray, damping: FloatArray, heading: float,
    innovation: bool = True,
) -> tuple[FloatArray, FloatArray]:
    """Continuous (A, B) of the observer for a held heading; x = [ξ1, ξ2, η, b, ν], u = [y, τ].

    The homogeneous part A is also the estimation-error dynamics (Fossen & Strand 1999, eq. 22),
    so its eigenvalues are the observer poles. ``innovation=False``: the model alone (every
    gain K1–K4 zero, y has no effect), for dead reckoning.
    """
    n = mass.shape[0]
    rot = _rotation(heading, n)
    m_inv = np.linalg.inv(mass)
    eye = np.eye(n)
    w0 = np.diag(gains.wave_peak_freq)
    lam = np.diag(gains.wave_damping)
    # Columns of the innovation ỹ = y − η − ξ2 expressed in states and input.
    gain_blocks = [
        np.diag(gains.k1_position),
        np.diag(gains.k1_velocity),
        np.diag(gains.k2),
        np.diag(gains.k3),
        m_inv @ rot.T @ np.diag(gains.k4),
    ]
    a = np.zeros((5 * n, 5 * n))
    blk = [slice(i * n, (i + 1) * n) for i in range(5)]
    xi1, xi2, eta, bias, nu = blk
    a[xi1, xi2] = eye
    a[xi2, xi1] = -(w0 @ w0)
    a[xi2, xi2] = -2.0 * lam @ w0
    a[eta, nu] = rot
    a[bias, bias] = -np.diag(1.0 / gains.bias_time)
    a[nu, nu] = -m_inv @ damping
    a[nu, bias] = m_inv @ rot.T
    b = np.zeros((5 * n, 2 * n))
    for row, gain in zip(blk, gain_blocks if innovation else [], strict=innovation):
        a[row, eta] -= gain
        a[row, xi2] -= gain
        b[row, :n] = gain
    b[nu, n:] = m_inv
    return a, b


def _zoh(a: FloatArray, b: FloatArray, step: float) -> tuple[FloatArray, FloatArray]:
    """Exact zero-order-hold discretization via the augmented matrix exponential (Van Loan)."""
    n_x, n_u = b.shape
    aug = np.zeros((n_x + n_u, n_x + n_u))
    aug[:n_x, :n_x] = a
    aug[:n_x, n_x:] = b
    phi = expm(aug * step)
    return phi[:n_x, :n_x], phi[:n_x, n_x:]


class PassiveObserver:
    """Fossen & Strand (1999) passive observer as an `LfEstimator`; returns η̂ (wrapped yaw).

    For ndof = 1 it runs on surge only with scalar (or the [0, 0] entry of 3×3) M and D.
    """

    def __init__(
        self,
        ndof: int,
        sample_time: float,
        wave_peak_freq: float,
        mass_matrix: ArrayLike,
        damping_matrix: ArrayLike,
        *,
        k3: ArrayLike,
        k4: ArrayLike,
        wave_damping: float = 0.1,
        relative_damping: float = 1.0,
        cutoff_ratio: float = 1.2,
        bias_time: float = 1000.0,
        heading_resolution: float = 0.0,
    ) -> None:
        """Set up the observer; M [kg, kg·m²] and D [N·s/m, N·m·s] are the model it assumes.

        ``heading_resolution`` [rad]: rounding of the heading in R(ψ) for the cached transition
        matrices of a non-isotropic observer (0: exact; see `_transition`).
        """
        if not (math.isfinite(heading_resolution) and heading_resolution >= 0.0):
            raise ValueError(f'heading_resolution must be >= 0 rad, got {heading_resolution}')
        self.heading_resolution = float(heading_resolution)
        self.ndof = check_ndof(ndof)
        if not np.isfinite(sample_time) or sample_time <= 0.0:
            raise ValueError(f'sample_time must be > 0 s, got {sample_time}')
        self.sample_time = float(sample_time)
        self._mass = _vessel_matrix(mass_matrix, self.ndof, 'mass_matrix')
        self._damping = _vessel_matrix(damping_matrix, self.ndof, 'damping_matrix')
        if np.any(np.linalg.eigvalsh(0.5 * (self._mass + self._mass.T)) <= 0.0):
            raise ValueError('mass_matrix must be positive definite: check units and signs')
        self._tuning = {
            'k3': k3, 'k4': k4, 'ndof': self.ndof, 'wave_damping': wave_damping,
            'relative_damping': relative_damping, 'cutoff_ratio': cutoff_ratio,
            'bias_time': bias_time,
        }
        self.gains = observer_gains(wave_peak_freq, **self._tuning)  # type: ignore[arg-type]
        self._state: FloatArray | None = None
        self._last_t: float | None = None
        self._transitions: dict[tuple[float, float, bool], tuple[FloatArray, FloatArray]] = {}

    @property
    def wave_peak_freq(self) -> float:
        """ω0 of the wave model [rad/s] (surge entry)."""
        return float(self.gains.wave_peak_freq[0])

    def set_wave_peak_freq(self, wave_peak_freq: float) -> None:
        """Retune the wave model and K1, K2 to a new ω0 [rad/s]; the state is kept."""
        self.gains = observer_gains(wave_peak_freq, **self._tuning)  # type: ignore[arg-type]
        self._transitions = {}

    def system_matrix(self, heading: float = 0.0) -> FloatArray:
        """Continuous error-dynamics matrix A at a heading [rad]; eigenvalues are the poles."""
        return system_matrices(self.gains, self._mass, self._damping, heading)[0]

    def _block(self, index: int) -> FloatArray:
        if self._state is None:
            return np.zeros(3)
        out = np.zeros(3)
        out[: self.ndof] = self._state[index * self.ndof: (index + 1) * self.ndof]
        return out

    @property
    def velocity(self) -> FloatArray:
        """ν̂ (3,): body-frame LF velocity [m/s, m/s, rad/s]."""
        return self._block(4)

    @property
    def bias(self) -> FloatArray:
        """b̂ (3,): earth-frame bias force [N, N, N·m]."""
        return self._block(3)

    @property
    def wave_motion(self) -> FloatArray:
        """η̂_w = C_w ξ̂ (3,): estimated wave-frequency motion [m, m, rad]."""
        return self._block(1)

    def _isotropic(self) -> bool:
        """True if all gains are equal in surge and sway (rotation-invariant observer)."""
        if self.ndof == 1:
            return True
        g = self.gains
        vectors = (g.wave_peak_freq, g.wave_damping, g.k1_position, g.k1_velocity, g.k2, g.k3,
                   g.k4, g.bias_time)
        return all(bool(np.isclose(v[0], v[1], rtol=1e-12, atol=0.0)) for v in vectors)

    def _step(self, state: FloatArray, inputs: FloatArray, heading: float, step: float,
              innovation: bool = True) -> FloatArray:
        """Exact ZOH step; in rotated coordinates when the observer is rotation invariant."""
        n = self.ndof
        if n == 1 or not self._isotropic():
            phi, gamma = self._transition(heading, step, innovation)
            return np.asarray(phi @ state + gamma @ inputs, dtype=np.float64)
        rot = _rotation(heading, n)
        blocks = state.reshape(5, n)
        rotated = blocks @ rot  # each block b → Rᵀ b (row-vector form)
        u_rot = np.concatenate([inputs[:n] @ rot, inputs[n:]])
        rotated[4] = blocks[4]  # ν̂ is already body-fixed
        phi, gamma = self._transition(0.0, step, innovation)
        new = (phi @ rotated.reshape(-1) + gamma @ u_rot).reshape(5, n)
        out = new @ rot.T  # back to earth frame: b → R b
        out[4] = new[4]
        return np.asarray(out.reshape(-1), dtype=np.float64)

    def _transition(self, heading: float, step: float,
                    innovation: bool = True) -> tuple[FloatArray, FloatArray]:
        """ZOH matrices for R(heading) held over ``step``, cached per rounded heading.

        A non-isotropic observer needs a matrix exponential per heading. With
        ``heading_resolution`` > 0 the heading is rounded to it (e.g. 1e-3 rad, the gyro noise),
        so a station-keeping run reuses a few hundred cached matrices instead of one exponential
        per sample; 0 (default) is exact.
        """
        resolution = self.heading_resolution
        held = heading if resolution == 0.0 else round(heading / resolution) * resolution
        key = (held, step, innovation)
        cached = self._transitions.get(key)
        if cached is None:
            if len(self._transitions) >= TRANSITION_CACHE:
                self._transitions.clear()
            a, b = system_matrices(self.gains, self._mass, self._damping, held, innovation)
            cached = _zoh(a, b, step)
            self._transitions[key] = cached
        return cached

    def _initial_state(
        self, measured: FloatArray, force: FloatArray, heading: float
    ) -> FloatArray:
        """η̂ = y, ξ̂ = ν̂ = 0, b̂ = −R τ (bias balancing the applied force at rest)."""
        n = self.ndof
        state = np.zeros(5 * n)
        state[2 * n: 3 * n] = measured
        state[3 * n: 4 * n] = -_rotation(heading, n) @ force
        return state

    def update(self, t: float, pose: FloatArray, force: FloatArray) -> FloatArray:
        """Propagate the observer to time t [s] with y = pose (3,), τ = force (3,); return η̂."""
        n = self.ndof
        measured = np.array(pose, dtype=np.float64)[:n]
        tau = np.array(force, dtype=np.float64)[:n]
        if not (np.all(np.isfinite(measured)) and np.all(np.isfinite(tau))):
            raise ValueError('pose and force must be finite: skip samples with sensor dropouts')
        heading = float(measured[_YAW]) if n == 3 else 0.0
        if self._state is None or self._last_t is None:
            self._state = self._initial_state(measured, tau, heading)
            self._last_t = float(t)
            return self.estimate()
        elapsed = float(t) - self._last_t
        step = elapsed if elapsed > 0.0 else self.sample_time
        step = round(step / 1e-9) * 1e-9  # stable cache key for a jittery clock
        if n == 3:
            predicted = self._state[2 * n + _YAW] + self._state[n + _YAW]
            measured[_YAW] = predicted + wrap_angle(float(measured[_YAW] - predicted))
        self._state = self._step(self._state, np.concatenate([measured, tau]), heading, step)
        self._last_t = float(t)
        return self.estimate()

    def coast(self, t: float, force: FloatArray) -> FloatArray:
        """Dead reckoning (no pose at t, thrust τ still applied): the model alone; returns η̂.

        The classical observer's dead reckoning: the measurement is replaced by the observer's
        own output η̂ + C_w ξ̂ throughout (every gain K1–K4 zero: the model alone, exact ZOH
        step): η̂ integrates ν̂, ν̂ follows M ν̂̇ = −D ν̂ + Rᵀ b̂ + τ, the bias b̂ only decays
        (−T⁻¹ b̂). Raises ValueError before the first pose or on a non-finite force.
        """
        n = self.ndof
        tau = np.array(force, dtype=np.float64)[:n]
        if self._state is None or self._last_t is None:
            raise ValueError('the observer has no state to dead reckon from: give it a pose first')
        if not np.all(np.isfinite(tau)):
            raise ValueError('force must be finite to dead reckon')
        elapsed = float(t) - self._last_t
        step = round((elapsed if elapsed > 0.0 else self.sample_time) / 1e-9) * 1e-9
        heading = float(self._state[2 * n + _YAW]) if n == 3 else 0.0
        self._state = self._step(self._state, np.concatenate([np.zeros(n), tau]), heading,
                                 step, innovation=False)
        self._last_t = float(t)
        return self.estimate()

    def estimate(self) -> FloatArray:
        """η̂ (3,) with yaw wrapped to (−π, π]."""
        eta = self._block(2)
        if self.ndof == 3:
            eta[_YAW] = wrap_angle(float(eta[_YAW]))
        return eta

    def reset(self) -> None:
        """Forget the state; the next sample re-initializes it."""
        self._state = None
        self._last_t = None

    def status(self) -> EstimatorStatus:
        """'ok' with ω0, or 'warming_up' before the first sample."""
        return EstimatorStatus(
            state='ok' if self._state is not None else 'warming_up',
            wave_peak_freq=self.wave_peak_freq,
            message=f'passive observer, ω0 = {self.wave_peak_freq:.3f} rad/s',
        )
