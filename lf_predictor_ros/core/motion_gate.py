"""Motion gate: blend a holding and a moving filter by how fast the vessel moves (issue 13).

A learned filter fitted on a window of station keeping is the best filter for holding position,
but nothing in that window tells it how to follow a setpoint move or a turn: it lags them. The
ramp-invariant network (``PredictorParams.ramp_invariant``, ``network._relative_regressors_numpy``)
follows any constant-velocity motion without lag by construction, and pays for it while the
vessel holds still (more wave-band motion in its estimate). The motion gate runs both and
publishes, per DOF,

    ŷ = ŷ_hold + g · (ŷ_move − ŷ_hold),      g = r² / (1 + r²),   r = s² / (k · s̄²)

where s is the LF velocity of the moving filter's estimate, low-passed with time constant
``GATE_TIME``, and s̄² the median of s² over the last ``GATE_WINDOW`` (the training window's
length): the velocity the filter sees while the vessel does what it usually does. The median,
not the mean, so that a move that fills less than half the window does not raise the scale and
close the gate on itself. A velocity well above that opens the gate (g → 1: a move), one at or
below it keeps it nearly shut (g ≤ 1/(1 + k²) at s² ≤ s̄²). The square of r makes the gate
sharper than r/(1 + r): in a DP loop every bit of the moving filter let in while holding shows
as wave-band thrust (closed-loop probe in docs/BENCHMARKS.md: with r/(1 + r) the mean gain while
holding was 0.08–0.12, with r² 0.03–0.05). The gate learns its scale from the data; nothing
about the vessel is assumed.

Constants chosen on tuning seed 1 only (open loop, fair recordings of rao_supply, rao_swell,
supply_closed_loop and threedof_open_loop; docs/BENCHMARKS.md "Motion gate").

With ``PredictorParams.motion_gate_smoothing`` T > 0 the gated output is
ŷ_hold + g · LP_T(ŷ_move − ŷ_hold), LP_T a first-order low-pass: the twin's estimate carries
more wave motion than the holding network's (it follows any ramp, so it cannot learn to ignore
the slow part of a wave group), and in a DP loop whatever the gate lets through of it shows as
wave-band thrust. A move or a turn changes the difference slowly, so the low-pass keeps it.

The gate stays shut until its history holds ``GATE_MIN_FILL`` of the window. With
``PredictorParams.motion_gate_fade_in`` F > 0 its gains are then multiplied by a ramp from 0 to
1 over F (the gain g of the module's formula, times min(1, n / (F / h)) for the n-th sample
since the warm-up ended): that end falls wherever it falls, in a move as easily as in calm, and
without the ramp the gain steps from 0 to 1 there and the whole twin offset reaches the output
in one sample.

With ``PredictorParams.motion_gate_validation`` the data decide, per DOF, whether the gate may
act at all (`gate_validated`): at every new target window (the zero-phase LF targets of the last
training window, thesis §4.2.2) the gated output the gate *would* have published is compared
with the holding network's output; the gate acts on a DOF only while its output was the closer
of the two on the last window. It starts shut: a gate that has not yet been shown to help on
this vessel (a start-up, a vessel that never moves) publishes the holding network alone.
"""
from __future__ import annotations

import bisect
import math

import numpy as np
from numpy.typing import NDArray

from lf_predictor_ros.core.heading import wrap_angle, wrap_pose

FloatArray = NDArray[np.float64]

# Time constant of the low-pass on the moving estimate's per-sample step [s].
GATE_TIME = 10.0
# k: the gate is half open when s² = k · s̄², s̄² the median of s². For a Gaussian velocity the
# median of s² is 0.455 × its mean, so k = 9 opens the gate half at s² ≈ 4 × the mean square [-].
GATE_RATIO = 9.0
# Length of the history that sets the usual velocity s̄ [s] (the default training window).
GATE_WINDOW = 1200.0
# The gate stays shut until its history holds this fraction of GATE_WINDOW: a median of a few
# samples is no measure of the usual motion (right after start, the first samples would open
# it fully) [-].
GATE_MIN_FILL = 0.25


def gate_gain(velocity_sq: FloatArray, usual_sq: FloatArray, ratio: float = GATE_RATIO,
              ) -> FloatArray:
    """The gain g = r² / (1 + r²), r = s² / (k·s̄²), per DOF, in [0, 1].

    0 where s² = 0 (no motion, or nothing seen yet), 1 where s² > 0 = s̄².
    """
    s2 = np.asarray(velocity_sq, dtype=np.float64)
    scale = ratio * np.asarray(usual_sq, dtype=np.float64)
    square = np.square(s2)
    denominator = square + np.square(scale)
    with np.errstate(invalid='ignore', divide='ignore'):
        gain = np.where(denominator > 0.0, square / denominator, 0.0)
    return np.asarray(np.clip(gain, 0.0, 1.0), dtype=np.float64)


def dead_zoned(gain: FloatArray, dead_zone: float) -> FloatArray:
    """The gain with a dead zone a in [0, 1): clip((g − a) / (1 − a), 0, 1) (a = 0: g itself).

    Shuts the small gains of a vessel holding position (``PredictorParams.motion_gate_dead_zone``:
    the twin's wave motion would leak through them into the thrust) and leaves a move (g → 1)
    alone. The input is not modified. Scratch probe on the tuning seeds: docs/BENCHMARKS.md,
    "a dead zone on the gain".
    """
    if not 0.0 <= dead_zone < 1.0:
        raise ValueError(f'the dead zone must be in [0, 1), got {dead_zone!r}')
    g = np.asarray(gain, dtype=np.float64)
    if g.ndim != 1:
        return np.asarray(np.clip((g - dead_zone) / (1.0 - dead_zone), 0.0, 1.0),
                          dtype=np.float64)
    # one gain per DOF: np.clip of each value (NaN stays NaN, −0 stays −0)
    scaled = [(v - dead_zone) / (1.0 - dead_zone) for v in g.tolist()]
    return np.array([0.0 if v < 0.0 else 1.0 if v > 1.0 else v for v in scaled],
                    dtype=np.float64)


def moving_offset(holding: FloatArray, moving: FloatArray, ndof: int) -> FloatArray:
    """The offset moving − holding on the first ``ndof`` entries (yaw wrapped), shape (ndof,)."""
    return wrap_pose(np.asarray(moving, dtype=np.float64)[:ndof]
                     - np.asarray(holding, dtype=np.float64)[:ndof], ndof)


def shifted(holding: FloatArray, offset: FloatArray, ndof: int) -> FloatArray:
    """The pose holding + offset on the first ``ndof`` entries (yaw wrapped), a new array."""
    out = np.array(holding, dtype=np.float64)
    out[:ndof] += np.asarray(offset, dtype=np.float64)[:ndof]
    return wrap_pose(out, ndof)


def blend(holding: FloatArray, moving: FloatArray, gain: FloatArray, ndof: int) -> FloatArray:
    """Holding + g·(moving − holding) on the first ``ndof`` entries (yaw difference wrapped).

    Poses are [north m, east m, yaw rad] (3 DOF) or [north m, …] (1 DOF: only north blended);
    the inputs are not modified.
    """
    return shifted(holding, np.asarray(gain, dtype=np.float64)[:ndof]
                   * moving_offset(holding, moving, ndof), ndof)


def gate_validated(holding: FloatArray, gated: FloatArray, targets: FloatArray,
                   previous: NDArray[np.bool_], min_samples: int) -> NDArray[np.bool_]:
    """Per DOF, whether the gated output was closer to the targets than the holding output.

    ``holding``, ``gated``, ``targets``: (m, ndof), row i the two outputs predicted for the
    instant of target i (yaw differences wrapped when ndof is 3). True where the mean squared
    error of ``gated`` is below that of ``holding``; ``previous`` (a copy) when fewer than
    ``min_samples`` finite rows are given. The inputs are not modified.
    """
    h = np.asarray(holding, dtype=np.float64)
    g = np.asarray(gated, dtype=np.float64)
    y = np.asarray(targets, dtype=np.float64)
    if h.shape != g.shape or h.shape != y.shape or h.ndim != 2:
        raise ValueError(f'holding, gated and targets must be (m, ndof) alike, got {h.shape}, '
                         f'{g.shape} and {y.shape}')
    ndof = h.shape[1]
    finite = np.all(np.isfinite(h) & np.isfinite(g) & np.isfinite(y), axis=1)
    if np.count_nonzero(finite) < max(1, min_samples):
        return np.array(previous, dtype=bool)
    error_hold = np.mean(wrap_pose(h[finite] - y[finite], ndof) ** 2, axis=0)
    error_gated = np.mean(wrap_pose(g[finite] - y[finite], ndof) ** 2, axis=0)
    return np.asarray(error_gated < error_hold, dtype=bool)


class MotionGate:
    """The gain g of the module docstring, updated once per predictor sample."""

    def __init__(self, ndof: int, sample_time: float, time_constant: float = GATE_TIME,
                 window: float = GATE_WINDOW, ratio: float = GATE_RATIO,
                 fade_in: float = 0.0) -> None:
        """Create for ``ndof`` DOFs at ``sample_time`` [s]; times in s (all > 0).

        ``fade_in`` [s] ≥ 0: the gains rise from 0 over this time once the warm-up is over
        (module docstring; 0: at once).
        """
        if ndof not in (1, 3):
            raise ValueError(f'MotionGate needs ndof 1 or 3, got {ndof!r}')
        for name, value in (('sample_time', sample_time), ('time_constant', time_constant),
                            ('window', window), ('ratio', ratio)):
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'MotionGate {name} must be finite and > 0, got {value!r}')
        if not (math.isfinite(fade_in) and fade_in >= 0.0):
            raise ValueError(f'MotionGate fade_in must be finite and >= 0 s, got {fade_in!r}')
        self.ndof = ndof
        self.ratio = ratio
        self._fade_samples = int(round(fade_in / sample_time))
        self._alpha = min(1.0, sample_time / time_constant)
        self._squares = np.zeros((max(1, int(round(window / sample_time))), ndof))
        self._min_count = max(1, int(math.ceil(GATE_MIN_FILL * self._squares.shape[0])))
        self.reset()

    def reset(self) -> None:
        """Forget everything: the motion seen and the usual velocity (a new vessel or sea)."""
        self.restart()
        self._count = 0  # filled rows of the ring buffer ``_squares``
        self._opened = 0  # samples since the warm-up ended, up to the fade-in's length
        self._index = 0  # next row to write
        # the filled rows of ``_squares`` per DOF, sorted (NaN left out and counted): their
        # median without sorting the window at every sample
        self._sorted: list[list[float]] = [[] for _ in range(self.ndof)]
        self._nans = [0] * self.ndof

    def restart(self) -> None:
        """A new data segment (after a gap): the velocity restarts, the usual velocity stays.

        What the vessel usually does outlives a gap in the poses; an empty history would make
        the first motion after the gap look unusual and open the gate.
        """
        self._last: FloatArray | None = None
        self._velocity = np.zeros(self.ndof)

    def update(self, moving: FloatArray) -> FloatArray:
        """Add the moving filter's newest estimate (a pose); return g per DOF (shape (ndof,))."""
        value = np.asarray(moving, dtype=np.float64)[:self.ndof]
        if not all(math.isfinite(v) for v in value.tolist()):
            return np.zeros(self.ndof)  # no motion evidence: hold the holding filter
        if self._last is not None:
            step = value - self._last
            if self.ndof == 3:  # wrap_pose of one pose, without its copy and checks
                step[2] = wrap_angle(float(step[2]))
            self._velocity = self._velocity + self._alpha * (step - self._velocity)
        self._last = value
        square = self._velocity ** 2
        self._store(square.tolist())
        if self._count < self._min_count:
            return np.zeros(self.ndof)
        gain = _gate_gain_floats(square.tolist(), self._usual(), self.ratio)
        if self._opened < self._fade_samples:  # motion_gate_fade_in: the ramp
            self._opened += 1
            gain = gain * (self._opened / self._fade_samples)
        return gain

    def _store(self, square: list[float]) -> None:
        """Write one row of squares into the ring buffer and the sorted columns."""
        size = self._squares.shape[0]
        row = self._squares[self._index]
        if self._count == size:  # the oldest row leaves the window
            for dof, old in enumerate(row.tolist()):
                if math.isnan(old):
                    self._nans[dof] -= 1
                else:
                    column = self._sorted[dof]
                    del column[bisect.bisect_left(column, old)]
        row[:] = square
        for dof, new in enumerate(square):
            if math.isnan(new):
                self._nans[dof] += 1
            else:
                bisect.insort(self._sorted[dof], new)
        self._index = (self._index + 1) % size
        self._count = min(self._count + 1, size)

    def _usual(self) -> list[float]:
        """s̄² per DOF: ``np.median(self._squares[:self._count], axis=0)``, value for value."""
        usual = []
        for column, nans in zip(self._sorted, self._nans, strict=True):
            half = len(column) // 2
            if nans:
                usual.append(math.nan)
            elif len(column) % 2:
                usual.append(column[half])
            else:  # an even count: the mean of the two middle values, as np.median
                usual.append((column[half - 1] + column[half]) / 2)
        return usual


def _gate_gain_floats(velocity_sq: list[float], usual_sq: list[float], ratio: float
                      ) -> FloatArray:
    """`gate_gain` of one sample per DOF, value for value, without numpy's overhead."""
    gain = []
    for s2, usual in zip(velocity_sq, usual_sq, strict=True):
        square = s2 * s2
        scale = ratio * usual
        denominator = square + scale * scale
        value = square / denominator if denominator > 0.0 else 0.0
        # np.clip(value, 0, 1): NaN stays NaN
        gain.append(0.0 if value < 0.0 else 1.0 if value > 1.0 else value)
    return np.array(gain, dtype=np.float64)
