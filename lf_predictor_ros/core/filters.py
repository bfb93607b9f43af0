"""Wave filter: notch at the wave peak frequency in series with a low-pass (thesis §4.2.2).

Continuous-time design (Fossen 2011, §11.3.2 "notch filtering"; thesis Fig. 4.8):

- Notch, width ζ_p and depth d = ζ_z / ζ_p (gain at ω0 equals d):

      h_n(s) = (s² + 2 ζ_z ω0 s + ω0²) / (s² + 2 ζ_p ω0 s + ω0²)

  MSS ``notchFilter.m`` is the special case ζ_p = 1, i.e. the denominator (s + ω0)², with
  ζ_z = 0.01–0.1.
- Low-pass: 2nd-order Butterworth at ω_LP = ω0 + offset (thesis Fig. 4.8: offset 0.2 rad/s),

      h_lp(s) = ω_LP² / (s² + √2 ω_LP s + ω_LP²)

  Second order rather than MSS's first order: it removes measurement noise above the wave band at
  40 dB/decade, stays maximally flat in the LF band (no ripple, < 0.01 dB below 0.05 rad/s) and
  adds only two poles of phase lag for the causal baseline. Options for the tuned baselines
  (`benchmark.baseline_tuning`): ``lowpass_order=1`` is MSS's first order ω_LP/(s + ω_LP) (half
  the lag), ``lowpass_offset=None`` drops the low-pass (notch only: the least lag).

The series h = h_lp · h_n is discretized with the bilinear (Tustin) transform pre-warped at ω0,
s = K (z − 1)/(z + 1) with K = ω0 / tan(ω0 T/2), so the notch zeros land exactly on
z = exp(±j ω0 T) for any sample time T (Oppenheim & Schafer, §7.1.2). Filters are returned as
second-order sections (scipy SOS layout, shape (n_sections, 6)).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import signal

FloatArray = NDArray[np.float64]

DEFAULT_NOTCH_ZETA = 0.5  # ζ_p [-]: notch width; -3 dB band ≈ 2 ζ_p ω0 wide
DEFAULT_NOTCH_DEPTH = 0.05  # ζ_z/ζ_p [-]: gain at ω0 (0.05 = -26 dB)
DEFAULT_LOWPASS_OFFSET = 0.2  # [rad/s] ω_LP = ω0 + offset (thesis Fig. 4.8)
DEFAULT_LOWPASS_ORDER = 2  # Butterworth order of the low-pass (1 or 2)
LOWPASS_ORDERS = (1, 2)
_BUTTERWORTH_DAMPING = 1.0 / np.sqrt(2.0)  # ζ of a 2nd-order Butterworth [-]


def _check_design(
    wave_peak_freq: float,
    sample_time: float,
    notch_zeta: float,
    notch_depth: float,
    lowpass_offset: float | None,
    lowpass_order: int = DEFAULT_LOWPASS_ORDER,
) -> None:
    """Raise ValueError naming the broken rule of a wave-filter design."""
    if not np.isfinite(sample_time) or sample_time <= 0.0:
        raise ValueError(f'sample_time must be a positive number of seconds, got {sample_time}')
    nyquist = np.pi / sample_time  # [rad/s]
    if not np.isfinite(wave_peak_freq) or not 0.0 < wave_peak_freq < nyquist:
        raise ValueError(
            f'wave_peak_freq must lie in (0, π/sample_time) = (0, {nyquist:.4g}) rad/s, got '
            f'{wave_peak_freq}: estimate ω0 again or sample faster'
        )
    if not np.isfinite(notch_zeta) or notch_zeta <= 0.0:
        raise ValueError(f'notch_zeta (notch width ζ_p) must be > 0, got {notch_zeta}')
    if not np.isfinite(notch_depth) or not 0.0 <= notch_depth < 1.0:
        raise ValueError(
            f'notch_depth (gain at ω0, ζ_z/ζ_p) must be in [0, 1), got {notch_depth}: '
            'use e.g. 0.05 for -26 dB'
        )
    if lowpass_offset is not None and (not np.isfinite(lowpass_offset) or lowpass_offset <= 0.0):
        raise ValueError(
            f'lowpass_offset must be > 0 rad/s (ω_LP = ω0 + offset) or None (no low-pass), got '
            f'{lowpass_offset}'
        )
    if lowpass_order not in LOWPASS_ORDERS:
        raise ValueError(f'lowpass_order must be one of {LOWPASS_ORDERS}, got {lowpass_order}')


def continuous_wave_filter(
    wave_peak_freq: float,
    *,
    notch_zeta: float = DEFAULT_NOTCH_ZETA,
    notch_depth: float = DEFAULT_NOTCH_DEPTH,
    lowpass_offset: float | None = DEFAULT_LOWPASS_OFFSET,
    lowpass_order: int = DEFAULT_LOWPASS_ORDER,
) -> tuple[FloatArray, FloatArray]:
    """Return (b, a) of the continuous notch · Butterworth low-pass, highest power of s first.

    ``lowpass_offset=None``: the notch alone; ``lowpass_order=1``: a first-order low-pass.
    """
    if not np.isfinite(wave_peak_freq) or wave_peak_freq <= 0.0:
        raise ValueError(f'wave_peak_freq must be > 0 rad/s, got {wave_peak_freq}')
    _check_design(wave_peak_freq, np.pi / (2.0 * wave_peak_freq), notch_zeta, notch_depth,
                  lowpass_offset, lowpass_order)  # any sample time with ω0 below Nyquist
    w0 = wave_peak_freq
    zeta_zero = notch_depth * notch_zeta
    notch_num = np.array([1.0, 2.0 * zeta_zero * w0, w0**2])
    notch_den = np.array([1.0, 2.0 * notch_zeta * w0, w0**2])
    if lowpass_offset is None:
        return notch_num, notch_den
    w_lp = w0 + lowpass_offset
    if lowpass_order == 1:
        return np.polymul(notch_num, [w_lp]), np.polymul(notch_den, [1.0, w_lp])
    lp_num = np.array([w_lp**2])
    lp_den = np.array([1.0, 2.0 * _BUTTERWORTH_DAMPING * w_lp, w_lp**2])
    return np.polymul(notch_num, lp_num), np.polymul(notch_den, lp_den)


def design_wave_filter(
    wave_peak_freq: float,
    sample_time: float,
    *,
    notch_zeta: float = DEFAULT_NOTCH_ZETA,
    notch_depth: float = DEFAULT_NOTCH_DEPTH,
    lowpass_offset: float | None = DEFAULT_LOWPASS_OFFSET,
    lowpass_order: int = DEFAULT_LOWPASS_ORDER,
) -> FloatArray:
    """Design the discrete notch + low-pass wave filter as SOS (thesis Alg. 4.1 lines 25–26).

    Args:
        wave_peak_freq: notch frequency ω0 [rad/s], below the Nyquist frequency π/sample_time.
        sample_time: sample period T [s].
        notch_zeta: notch width ζ_p (relative damping of the notch poles) [-].
        notch_depth: gain of the notch at ω0, ζ_z/ζ_p, in [0, 1) [-].
        lowpass_offset: ω_LP − ω0 [rad/s]; None for no low-pass (the notch alone).
        lowpass_order: 2 (Butterworth, the default) or 1 (ω_LP/(s + ω_LP)).

    Returns:
        SOS array (2, 6): notch and low-pass, unity DC gain ((1, 6), the notch alone, with
        ``lowpass_offset=None``; a first-order low-pass is padded to a second-order section).
    """
    _check_design(wave_peak_freq, sample_time, notch_zeta, notch_depth, lowpass_offset,
                  lowpass_order)
    b, a = continuous_wave_filter(
        wave_peak_freq,
        notch_zeta=notch_zeta,
        notch_depth=notch_depth,
        lowpass_offset=lowpass_offset,
        lowpass_order=lowpass_order,
    )
    zeros, poles, gain = signal.tf2zpk(b, a)
    # Tustin pre-warped at ω0: s = K (z-1)/(z+1), K = ω0/tan(ω0 T/2); scipy uses K = 2 fs.
    warp = wave_peak_freq / np.tan(wave_peak_freq * sample_time / 2.0)  # [1/s]
    zd, pd, kd = signal.bilinear_zpk(zeros, poles, gain, warp / 2.0)
    sos: FloatArray = np.asarray(signal.zpk2sos(zd, pd, kd), dtype=np.float64)
    return sos


def frequency_response(
    sos: FloatArray, omega: ArrayLike, sample_time: float
) -> NDArray[np.complex128]:
    """Complex response of a discrete SOS filter at angular frequencies omega [rad/s]."""
    if sample_time <= 0.0:
        raise ValueError(f'sample_time must be > 0 s, got {sample_time}')
    omega_arr = np.atleast_1d(np.asarray(omega, dtype=np.float64))
    _, response = signal.sosfreqz(sos, worN=omega_arr * sample_time)
    return np.asarray(response, dtype=np.complex128)


def settling_samples(sos: FloatArray, tolerance: float = 1e-3) -> int:
    """Samples until the slowest pole has decayed to `tolerance` (|p|^n = tolerance)."""
    poles = np.concatenate([np.roots(section[3:]) for section in np.asarray(sos)])
    radius = float(np.max(np.abs(poles)))
    if radius >= 1.0:
        raise ValueError(f'filter is not stable (pole radius {radius:.6f} >= 1): redesign it')
    return int(np.ceil(np.log(tolerance) / np.log(radius)))


def zero_phase(y: ArrayLike, sos: FloatArray) -> FloatArray:
    """Forward-backward (zero-phase) filtering of y along axis 0 (thesis §4.2.2).

    Initial conditions by Gustafsson's method (Gustafsson 1996, IEEE Trans. Signal Processing
    44(4); ``scipy.signal.filtfilt(method='gust')``): the forward and backward initial states are
    chosen so that forward-backward and backward-forward filtering agree, with no padding.
    Why this one: on seeded drift + wave series (σ_LF 1 m, σ_WF 0.7 m, dt 0.1 s; 10 series each
    at ω0 = 0.3, 0.8, 1.3 rad/s, test_filters.py) its error over the first and last 10 s is
    0.20 m RMS against 0.28 m for odd padding of one settling time, it is the most even over ω0
    and both ends in a wider comparison, and it has no padding length to tune. Odd-reflection
    padding (sosfiltfilt) reflects about the edge sample, which carries the wave component;
    with a padding of one settling time that inflates the edge error, and the short default
    padding depends on the sample time. The input is not modified.

    Args:
        y: series (n,) or (n, channels), n >= 2.
        sos: filter from `design_wave_filter`.

    Returns:
        Filtered series of the same shape: squared magnitude response, zero phase.
    """
    data = np.asarray(y, dtype=np.float64)
    if data.ndim not in (1, 2) or data.shape[0] < 2:
        raise ValueError(f'zero_phase needs shape (n,) or (n, channels) with n >= 2, got '
                         f'{data.shape}')
    if not np.all(np.isfinite(data)):
        raise ValueError('zero_phase got NaN or inf samples: drop or interpolate them first')
    b, a = signal.sos2tf(_check_sos(sos))
    out: FloatArray = np.asarray(
        signal.filtfilt(b, a, data, axis=0, method='gust'), dtype=np.float64
    )
    return out


@dataclass(frozen=True)
class _StateSpace:
    """Discrete state space of an SOS cascade whose state is the stacked DF2T section states."""

    a: FloatArray
    b: FloatArray
    c: FloatArray
    d: float


def _sos_step(sos: FloatArray, state: FloatArray, u: FloatArray) -> tuple[FloatArray, FloatArray]:
    """One DF2T step of an SOS cascade; state (n_sections, 2, channels), u (channels,)."""
    new_state = np.empty_like(state)
    x = u
    for i, (b0, b1, b2, _, a1, a2) in enumerate(sos):
        out = b0 * x + state[i, 0]
        new_state[i, 0] = b1 * x - a1 * out + state[i, 1]
        new_state[i, 1] = b2 * x - a2 * out
        x = out
    return x, new_state



def low_pass_step(state: ArrayLike, value: ArrayLike,
                  weight: float | ArrayLike) -> NDArray[np.float64]:
    """One first-order low-pass step, state + w·(value − state) entry by entry, a new array.

    ``weight`` w in [0, 1]: one number for every entry, or one per entry. Plain floats: for
    the few entries of a pose or a twist on the predict path, without numpy's per-call cost.
    """
    old = np.asarray(state, dtype=np.float64).tolist()
    new = np.asarray(value, dtype=np.float64).tolist()
    weights = [float(weight)] * len(old) if isinstance(weight, (int, float)) else \
        np.asarray(weight, dtype=np.float64).tolist()
    return np.array([a + w * (b - a) for a, w, b in zip(old, weights, new, strict=True)],
                    dtype=np.float64)

def _sos_step_lists(coefficients: list[list[float]], state: list[list[list[float]]],
                    x: list[float]) -> tuple[list[float], list[list[list[float]]]]:
    """`_sos_step` of one sample in plain floats on nested lists (state: section, 2, channel).

    The same operations in the same order, without numpy's per-call cost.
    """
    new_state = []
    for (b0, b1, b2, _, a1, a2), (first, second) in zip(coefficients, state, strict=True):
        out = [b0 * xi + si for xi, si in zip(x, first, strict=True)]
        new_state.append([[b1 * xi - a1 * oi + si for xi, oi, si in zip(x, out, second,
                                                                        strict=True)],
                          [b2 * xi - a2 * oi for xi, oi in zip(x, out, strict=True)]])
        x = out
    return x, new_state


def _state_space(sos: FloatArray) -> _StateSpace:
    """Build (A, B, C, D) of the cascade by probing the linear DF2T step with unit vectors."""
    n_states = 2 * sos.shape[0]
    a = np.zeros((n_states, n_states))
    c = np.zeros(n_states)
    for j in range(n_states):
        unit = np.zeros((n_states, 1))
        unit[j, 0] = 1.0
        out, nxt = _sos_step(sos, unit.reshape(-1, 2, 1), np.zeros(1))
        a[:, j] = nxt.reshape(-1)
        c[j] = out[0]
    out, nxt = _sos_step(sos, np.zeros((sos.shape[0], 2, 1)), np.ones(1))
    return _StateSpace(a=a, b=nxt.reshape(-1), c=c, d=float(out[0]))


@dataclass(frozen=True)
class RetunePlan:
    """New coefficients and what `CausalFilter.retune` needs of them alone (issue 13, cost).

    The observability matrix and the Markov parameters of the new cascade depend on its
    coefficients only, not on the filter's history: made beforehand (`plan_retune`, e.g. in the
    job that found the new ω0, in another process), they are not computed on the predict path.
    The state fitted from them is the same to the bit as from the coefficients alone.
    """

    sos: FloatArray
    state_space: _StateSpace
    observability: FloatArray  # (order, n_states): rows C A^k, k < order
    markov: tuple[FloatArray, ...]  # C A^i B for i < order - 1
    steady_state: FloatArray  # sosfilt_zi(sos): the state after a unit step, per section


def plan_retune(sos: ArrayLike) -> RetunePlan:
    """`RetunePlan` of ``sos`` (normalized sections, shape (n_sections, 6))."""
    checked = _check_sos(np.asarray(sos, dtype=np.float64))
    ss = _state_space(checked)
    order = 2 * checked.shape[0]
    n_states = ss.a.shape[0]
    obs = np.zeros((order, n_states))
    power = np.eye(n_states)
    for k in range(order):
        obs[k] = ss.c @ power
        power = ss.a @ power
    markov = tuple(ss.c @ np.linalg.matrix_power(ss.a, i) @ ss.b for i in range(order - 1))
    steady = signal.sosfilt_zi(checked)
    for array in (checked, obs, ss.a, ss.b, ss.c, steady, *markov):
        array.setflags(write=False)
    return RetunePlan(sos=checked, state_space=ss, observability=obs, markov=markov,
                      steady_state=steady)


def _check_sos(sos: FloatArray) -> FloatArray:
    arr = np.array(sos, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 6 or arr.shape[0] < 1:
        raise ValueError(f'sos must have shape (n_sections, 6), got {arr.shape}')
    if not np.allclose(arr[:, 3], 1.0):
        raise ValueError('sos sections must be normalized (a0 = 1): use scipy.signal.zpk2sos')
    return arr


class CausalFilter:
    """Streaming sample-by-sample SOS filter over `n_channels` channels.

    Equivalent to ``scipy.signal.sosfilt`` with ``zi = sosfilt_zi(sos) * x[0]``: the state is
    initialized to steady state on the first sample, so a filter switched on at a constant input
    outputs that input with no start-up jump.
    """

    def __init__(self, sos: FloatArray, n_channels: int) -> None:
        """Create an uninitialized filter; the first `filter` call sets steady state."""
        if n_channels < 1:
            raise ValueError(f'n_channels must be >= 1, got {n_channels}')
        self._sos = _check_sos(sos)
        self._coefficients: list[list[float]] = self._sos.tolist()  # per-sample step
        self._n_channels = n_channels
        # the DF2T section states as nested lists (section, 2, channel): `_sos_step_lists`
        self._state: list[list[list[float]]] | None = None
        # the newest inputs and outputs (lists of n_channels floats), for `retune`
        self._inputs: list[list[float]] = []
        self._outputs: list[list[float]] = []
        self._zi: FloatArray | None = None  # sosfilt_zi of the coefficients, once needed

    @property
    def sos(self) -> FloatArray:
        """The current filter coefficients (a copy)."""
        return self._sos.copy()

    @property
    def n_channels(self) -> int:
        """Number of channels filtered in parallel."""
        return self._n_channels

    @property
    def initialized(self) -> bool:
        """True once the first sample has set the state."""
        return self._state is not None

    def reset(self) -> None:
        """Forget the state; the next sample re-initializes to steady state."""
        self._state = None
        self._inputs = []
        self._outputs = []

    def _steady_state(self) -> FloatArray:
        """``sosfilt_zi`` of the coefficients, computed once per set of them.

        A restart (`reset`, a new data segment) then designs nothing on the predict path, nor
        does the first sample after a planned `retune` (`RetunePlan.steady_state`).
        """
        if self._zi is None:
            self._zi = signal.sosfilt_zi(self._sos)
        return self._zi

    def filter(self, x: FloatArray) -> FloatArray:
        """Filter one sample x (n_channels,) and return the output (n_channels,)."""
        u = np.array(x, dtype=np.float64).reshape(-1)
        if u.shape != (self._n_channels,):
            raise ValueError(f'sample must have shape ({self._n_channels},), got {u.shape}')
        return np.array(self.filter_values(u.tolist()), dtype=np.float64)

    def filter_values(self, values: list[float]) -> list[float]:
        """`filter` of one sample given as n_channels floats; the output as a new list.

        The same numbers as `filter`, without its arrays (the predict path's cascade).
        """
        if len(values) != self._n_channels:
            raise ValueError(f'sample must have shape ({self._n_channels},), got '
                             f'({len(values)},)')
        if self._state is None:
            zi = self._steady_state()  # steady state for a unit step input
            self._state = (zi[:, :, None] * np.array(values, dtype=np.float64)).tolist()
        out, self._state = _sos_step_lists(self._coefficients, self._state, values)
        self._remember(list(values), out)
        return list(out)

    def filter_rows(self, rows: list[list[float]]) -> list[list[float]]:
        """`filter` of every row (n_channels floats) in order; the outputs as lists.

        The same numbers as one `filter` call per row, without two arrays per sample.
        """
        if not rows:
            return []
        outputs = [self.filter(np.array(rows[0], dtype=np.float64)).tolist()]
        if len(rows) == 1:
            return outputs
        assert self._state is not None  # set by the first filter() call
        state = self._state
        coefficients = self._coefficients
        for row in rows[1:]:
            if len(row) != self._n_channels:
                raise ValueError(f'sample must have shape ({self._n_channels},), got '
                                 f'({len(row)},)')
            out, state = _sos_step_lists(coefficients, state, row)
            outputs.append(out)
        self._state = state
        order = 2 * self._sos.shape[0]
        for row, out in list(zip(rows[1:], outputs[1:], strict=True))[-order:]:
            self._remember([float(v) for v in row], list(out))
        return outputs

    def _remember(self, u: list[float], y: list[float]) -> None:
        """Keep the newest input and output rows (lists no caller holds: no copies needed)."""
        order = 2 * self._sos.shape[0]
        self._inputs.append(u)
        self._outputs.append(y)
        if len(self._inputs) > order:
            del self._inputs[0]
            del self._outputs[0]

    def retune(self, sos: FloatArray | RetunePlan) -> None:
        """Switch to new coefficients while keeping the output continuous.

        The new state is the one for which the new filter, fed the last N inputs, would have
        produced the last N outputs of the old filter (N = filter order): the new recursion
        continues the actual output history instead of restarting. Before N samples exist, the
        new filter starts in steady state at the last output. A `RetunePlan` (`plan_retune`)
        gives the same state with less work here.
        """
        plan, new_sos = (sos, sos.sos) if isinstance(sos, RetunePlan) else (None, _check_sos(sos))
        self._sos = new_sos
        self._coefficients = new_sos.tolist()
        self._zi = plan.steady_state if plan is not None else None
        if self._state is None:
            return
        order = 2 * new_sos.shape[0]
        if len(self._inputs) < order:
            zi = self._steady_state()
            last = np.array(self._outputs[-1], dtype=np.float64)
            self._state = (zi[:, :, None] * last).tolist()
            self._inputs = self._inputs[-1:]
            self._outputs = self._outputs[-1:]
            return
        if plan is None:
            plan = plan_retune(new_sos)
        self._state = self._fit_state(plan, order).tolist()

    def _fit_state(self, plan: RetunePlan, order: int) -> FloatArray:
        """State matching the stored I/O history for the plan's filter (least squares)."""
        ss, obs = plan.state_space, plan.observability
        u_hist = np.array(self._inputs[-order:])  # (N, channels), oldest first
        y_hist = np.array(self._outputs[-order:])
        # y_k = C A^k z0 + D u_k + Σ_{j<k} C A^(k-1-j) B u_j
        forced = np.zeros_like(y_hist)
        for k in range(order):
            forced[k] = ss.d * u_hist[k]
            for j in range(k):
                forced[k] += plan.markov[k - 1 - j] * u_hist[j]
        z0, *_ = np.linalg.lstsq(obs, y_hist - forced, rcond=None)  # (n_states, channels)
        z = z0
        for k in range(order):
            z = ss.a @ z + np.outer(ss.b, u_hist[k])
        return np.asarray(z.reshape(plan.sos.shape[0], 2, -1), dtype=np.float64)
