"""Position-reference checks (DP class practice): frozen, jump, drift, dropout.

A DP system does not take a position reference on trust: class rules (e.g. DNV-RU-SHIP Pt.6
Ch.3, IMO MSC/Circ.645) expect each reference to be tested for a frozen signal, jumps and
outliers, slow drift, and loss, and a failed reference to be flagged and kept out of the
estimate. `ReferenceChecker` runs those tests on the measured pose stream before the aligner
(so a rejected sample never enters the aligner, the predictor's buffers or a training):

- **frozen** (every pose): the whole pose vector bit-identical for ≥ `frozen_time` s (and ≥ 3
  samples) → rejected while identical, ERROR.
- **no wave motion** (blocks of `motion_wave_periods` wave periods 2π/ω0): the detrended RMS
  motion of every estimated DOF below `motion_ratio` × the median of the last clean blocks (wave
  motion was seen before) → rejected until the motion returns, ERROR.
- **jump** (every pose): innovation against a robust local prediction (least-squares line through
  the last accepted poses) beyond `jump_gate` robust σ (MAD of the recent innovations) +
  `jump_floor` → rejected, WARN. A step that persists `jump_confirm` s with consistent samples is
  taken as the new level: ERROR, data restart (counted as `step`).
- **drift** (every aligned sample): the exponential mean (time constant `drift_time_constant`) of
  the innovation against the predictor's own prediction beyond `drift_limit` → latched: every
  later pose is rejected until `reset()` (the operator re-selects the reference), ERROR.
- **dropout** (the caller's clock): no pose for more than `dropout_timeout` s → ERROR while it
  lasts, counted once per dropout (a stamp gap of that length in the stream is counted too).

A detected frozen, no-motion, drift or step fault also asks the caller to restart the data
segment (`Verdict.restart`): the samples that arrived during the detection delay are then dropped
from the predictor's buffers, so no training window spans the fault (the network in service
stays). Only the estimated DOFs (`ndof`: north for 1, north/east/yaw for 3) are tested, except
the frozen test, which compares the whole vector (a stuck receiver repeats all of it).

Limits of a single reference (measured, not hidden): the predictor works in coordinates relative
to the newest measurement and retrains every Δ, so it follows a slow drift of its only reference:
on the supply vessel a 5 cm/s ramp moved the mean innovation by < 0.05 m and an accelerating one
(0.002 m/s²) by < 0.4 m before the retrained network absorbed it, against a clean-hour maximum of
0.09 m (the default limit 0.5 m keeps 5× margin). A constant-rate drift is indistinguishable from
vessel motion under an unknown current; only a second, independent reference (or dead reckoning
on a vessel model) exposes it. The drift test catches a reference that leaves the prediction
faster than the model can follow. The jump test needs 30 accepted innovations for its scale:
until then only the aligner's speed limit guards against outliers.

Conventions: times [s] (message stamps, or the caller's clock for the dropout watch), poses
``[north m, east m, yaw rad]``; nothing here raises on data. Stamps that do not increase: a pose
stamped exactly at the last checked stamp (a re-published sample, e.g. a lockstep simulator
offering its first sample again) passes untested and changes nothing (the aligner drops it as
out of order); a pose stamped earlier (a simulator reset, a bag loop, one late message) restarts
the local tests (line, motion block, pending step) from it. Before this, two poses with one stamp
made the local line's time spread zero, and every later pose failed with ZeroDivisionError.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field, fields, replace
import math
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from lf_predictor_ros.core.field_meta import field_doc
from lf_predictor_ros.core.filters import low_pass_step
from lf_predictor_ros.core.heading import wrap_angle
from lf_predictor_ros.core.row_buffer import RowBuffer

FloatArray = NDArray[np.float64]
Level = Literal['OK', 'WARN', 'ERROR']

FAULTS = ('frozen', 'no_wave_motion', 'jump', 'step', 'drift', 'dropout')
FIT_SAMPLES = 4  # accepted poses behind the local line prediction
SCALE_SAMPLES = 300  # innovations behind the robust (MAD) scale of the jump gate
MIN_SCALE_SAMPLES = 30  # innovations needed before the jump gate acts
GATE_REFRESH = 10  # accepted innovations between two recomputations of the gate
MAD_TO_SIGMA = 1.4826  # σ of a normal distribution per median absolute deviation
MIN_FROZEN_SAMPLES = 3  # identical samples before `frozen_time` can declare a freeze
MOTION_MEMORY = 10  # clean blocks behind the wave-motion reference
MIN_MOTION_BLOCKS = 2  # clean blocks needed before the no-wave-motion test acts
MIN_BLOCK_SAMPLES = 8  # samples a block needs to be judged
EVENT_HOLD = 10.0  # [s of stamps] a jump or step stays in the status this long
DEFAULT_WAVE_PERIOD = 2.0 * math.pi / math.sqrt(0.25 * 1.4)  # [s] before ω0 is known (10.6 s)


@dataclass(frozen=True)
class ReferenceCheckSettings:
    """Thresholds of the position-reference checks (see the module docstring); validated."""

    reference_checks: bool = field(default=True, metadata=field_doc(
        'run the position-reference checks (frozen, no wave motion, jump, drift, dropout)'))
    frozen_time: float = field(default=3.0, metadata=field_doc(
        'a pose repeated bit-identically this long is frozen', 's'))
    motion_wave_periods: float = field(default=6.0, metadata=field_doc(
        'block length of the no-wave-motion test, in wave periods 2π/ω0', ''))
    motion_ratio: float = field(default=0.1, metadata=field_doc(
        'no wave motion: block motion below this fraction of the clean blocks', ''))
    jump_gate: float = field(default=6.0, metadata=field_doc(
        'jump gate: innovation against the local prediction in robust σ (plus jump_floor)', ''))
    jump_floor: tuple[float, ...] = field(default=(0.5, 0.5, 0.02), metadata=field_doc(
        'jump gate floor per DOF (north, east, yaw)', 'm, m, rad'))
    jump_rate: tuple[float, ...] = field(default=(1.0, 1.0, 0.02), metadata=field_doc(
        'jump gate growth per second since the last accepted pose beyond the usual spacing '
        '(the wave motion a stale local prediction misses)', 'm/s, m/s, rad/s'))
    jump_confirm: float = field(default=2.0, metadata=field_doc(
        'a step that persists this long (consistent samples) is taken as the new level', 's'))
    drift_time_constant: float = field(default=120.0, metadata=field_doc(
        'time constant of the mean innovation against the prediction (drift test)', 's'))
    drift_limit: tuple[float, ...] = field(default=(0.5, 0.5, 0.03), metadata=field_doc(
        'drift limit on the mean innovation per DOF (north, east, yaw)', 'm, m, rad'))
    dropout_timeout: float = field(default=3.0, metadata=field_doc(
        'no measured pose for longer than this is a dropout', 's'))

    def __post_init__(self) -> None:
        """Coerce numbers and check every rule; the message says what to change."""
        if not isinstance(self.reference_checks, bool):
            raise ValueError(f'reference_checks must be true or false, got '
                             f'{self.reference_checks!r}')
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == 'reference_checks':
                continue
            if f.name in ('jump_floor', 'jump_rate', 'drift_limit'):
                values = _three_positive(f.name, value)
                object.__setattr__(self, f.name, values)
                continue
            number = _positive(f.name, value)
            object.__setattr__(self, f.name, number)
        if not self.motion_ratio < 1.0:
            raise ValueError(f'motion_ratio must lie in (0, 1), got {self.motion_ratio}')
        if self.motion_wave_periods < 2.0:
            raise ValueError(f'motion_wave_periods must be ≥ 2 wave periods (a shorter block '
                             f'cannot tell waves from noise), got {self.motion_wave_periods}')

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        """Names of all settings, in declaration order."""
        return tuple(f.name for f in fields(cls))


def _positive(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            not math.isfinite(float(value)) or not float(value) > 0.0:
        raise ValueError(f'{name} must be a positive finite number, got {value!r}')
    return float(value)


def _three_positive(name: str, value: Any) -> tuple[float, ...]:
    if isinstance(value, (str, bytes)) or not hasattr(value, '__len__') or len(value) != 3:
        raise ValueError(f'{name} must be three positive numbers (north m, east m, yaw rad), '
                         f'got {value!r}')
    return tuple(_positive(name, v) for v in value)


@dataclass(frozen=True)
class Verdict:
    """What to do with one pose or grid sample.

    ``accepted``: pass it on (aligner / predictor). ``restart``: a fault was just detected whose
    detection delay let faulty samples through; drop the buffered data (new segment) before
    anything else. ``fault``: the test that rejected it (None when accepted). ``gap``: a stamp
    gap longer than ``dropout_timeout`` (a dropout) precedes this pose: the caller must not
    bridge it by interpolation (start a new data segment), so no made-up sample enters training.
    """

    accepted: bool
    restart: bool = False
    fault: str | None = None
    gap: bool = False


ACCEPT = Verdict(True)


class ReferenceChecker:
    """Stateful position-reference checks of one pose stream (see the module docstring)."""

    def __init__(self, settings: ReferenceCheckSettings, ndof: int) -> None:
        if ndof not in (1, 3):
            raise ValueError(f'ndof must be 1 or 3, got {ndof!r}')
        self.settings = settings
        self.ndof = ndof
        self.counters: dict[str, int] = {name: 0 for name in FAULTS}
        self.rejected = 0  # poses rejected by any test
        self._last_arrival: float | None = None
        self._in_dropout = False
        self._dropout_counted = False
        self.reset()

    # ---- state ------------------------------------------------------------------------------

    def renewed(self, settings: ReferenceCheckSettings, ndof: int) -> ReferenceChecker:
        """A checker with other settings (or ndof): statistics restart, counters carry on."""
        checker = ReferenceChecker(settings, ndof)
        checker.counters = dict(self.counters)
        checker.rejected = self.rejected
        return checker

    def reset(self) -> None:
        """Clear every fault and learned statistic (counters are kept): a fresh reference."""
        # accepted (stamp, estimated DOFs as floats), oldest first
        self._fit: deque[tuple[float, list[float]]] = deque(maxlen=FIT_SAMPLES)
        # |innovation| ring buffer (rows in arrival order modulo SCALE_SAMPLES: the median does
        # not depend on the order) and its filled rows
        self._scale_buf = np.zeros((SCALE_SAMPLES, self.ndof))
        self._scale_count = 0
        self._scale_next = 0
        self._gate_cache: list[float] | None = None
        self._since_gate = 0
        self._pending: list[tuple[float, list[float]]] = []  # consecutive jump rejections
        self._same_since: float | None = None
        self._same_count = 0
        self._last_raw: tuple[tuple[int, ...], list[float]] | None = None  # shape, values
        self._frozen = False
        self._block = _PoseBlock(self.ndof)  # the current wave-motion block
        self._motion_history: deque[FloatArray] = deque(maxlen=MOTION_MEMORY)
        self._no_motion = False
        self._drift_mean: FloatArray | None = None
        self._drift_time = 0.0  # [s] integrated into the mean so far
        self._drift_last_t: float | None = None
        self._drift_step = 0.0  # [s] spacing of the last ordinary checked sample
        self._drift = False
        self._events: dict[str, float] = {}  # fault → stamp of its last occurrence
        self._last_t: float | None = None
        self.last_reason = ''

    @property
    def faults(self) -> tuple[str, ...]:
        """Faults active now (frozen, no_wave_motion, drift), in FAULTS order."""
        active = {'frozen': self._frozen, 'no_wave_motion': self._no_motion,
                  'drift': self._drift, 'dropout': self._in_dropout}
        return tuple(name for name in FAULTS if active.get(name, False))

    @property
    def drift_mean(self) -> FloatArray | None:
        """Current mean innovation against the prediction (ndof,), None before any."""
        return None if self._drift_mean is None else self._drift_mean.copy()

    # ---- sensor-rate checks -----------------------------------------------------------------

    def check_pose(self, t: float, pose: FloatArray,
                   wave_peak_freq: float | None = None) -> Verdict:
        """Test one measured pose (finite, shape (3,)) stamped t; see the module docstring."""
        if not self.settings.reference_checks:
            return ACCEPT
        pose = np.asarray(pose, dtype=np.float64)
        if self._last_t is not None and t <= self._last_t:
            if t == self._last_t:
                return ACCEPT  # a repeated stamp: nothing new to test (the aligner drops it)
            self._block.clear()  # time went backwards: the local tests restart from this pose
            self._fit.clear()
            self._pending = []
        gap = self._last_t is not None and t - self._last_t > self.settings.dropout_timeout
        if gap:
            if not self._dropout_counted:  # a gap in the stamps the clock watch did not see
                self.counters['dropout'] += 1
            self._block.clear()
            self._fit.clear()
            self._pending = []
        self._dropout_counted = False
        self._last_t = t
        verdict = self._check_pose_tests(t, pose, wave_peak_freq)
        return replace(verdict, gap=True) if gap else verdict

    def _check_pose_tests(self, t: float, pose: FloatArray,
                          wave_peak_freq: float | None) -> Verdict:
        if self._drift:
            return self._reject('drift', 'drift latched: reference deselected until reset')
        restart = self._check_frozen(t, pose)
        if self._frozen:
            return self._reject('frozen', f'pose identical for {t - (self._same_since or t):.1f}'
                                ' s (frozen reference)', restart)
        y = self._dofs(pose)
        verdict = self._check_jump(t, y)
        if verdict is not None and not verdict.accepted:
            return verdict
        step_restart = verdict is not None and verdict.restart
        motion_restart = self._check_motion(t, y, wave_peak_freq)
        if self._no_motion:
            return self._reject('no_wave_motion', 'no wave motion over '
                                f'{self.settings.motion_wave_periods:g} wave periods where '
                                'waves were seen before (frozen or smoothed reference)',
                                motion_restart)
        if not (step_restart or motion_restart):
            return ACCEPT
        return Verdict(True, restart=True, fault='step' if step_restart else None)

    def _dofs(self, pose: FloatArray) -> FloatArray:
        return np.array(pose[:self.ndof], dtype=np.float64)

    def _reject(self, fault: str, reason: str, restart: bool = False) -> Verdict:
        self.rejected += 1
        self.last_reason = f'{fault}: {reason}'
        if self._last_t is not None:
            self._events[fault] = self._last_t
        return Verdict(False, restart=restart, fault=fault)

    def _check_frozen(self, t: float, pose: FloatArray) -> bool:
        """Update the identical-value run; True when a freeze is detected at this sample."""
        raw = (pose.shape, pose.ravel().tolist())
        last = self._last_raw
        # np.array_equal on plain floats: same shape, every entry == (NaN never equal)
        if last is not None and raw[0] == last[0] and \
                all(a == b for a, b in zip(raw[1], last[1], strict=True)):
            self._same_count += 1
        else:
            self._last_raw = raw
            self._same_since, self._same_count = t, 1
            self._frozen = False
            return False
        assert self._same_since is not None
        if not self._frozen and self._same_count >= MIN_FROZEN_SAMPLES and \
                t - self._same_since >= self.settings.frozen_time:
            self._frozen = True
            self.counters['frozen'] += 1
            return True
        return False

    def _innovation(self, t: float, y: list[float]) -> list[float] | None:
        """Innovation: y minus the line through the last accepted poses (None: too few).

        Plain float arithmetic in numpy's order (means summed front to back); the two dot
        products stay numpy's: the vectorized result, bit for bit, without its overhead.
        """
        fit = self._fit
        n = len(fit)
        if n < 2:
            return None
        ref = fit[-1][1]
        times = [s - t for s, _ in fit]
        rel = [[v - r for v, r in zip(values, ref, strict=True)] for _, values in fit]
        if self.ndof == 3:
            for row in rel:
                row[2] = wrap_angle(row[2])
        # least-squares line a + b·(s − t) through (times, rel); its value at t is a
        t_sum = 0.0
        for s in times:
            t_sum += s
        t_mean = t_sum / n
        rel_sum = list(rel[0])
        for row in rel[1:]:
            rel_sum = [a + b for a, b in zip(rel_sum, row, strict=True)]
        rel_mean = [a / n for a in rel_sum]
        dt = np.array([s - t_mean for s in times])
        centred = np.array([[v - m for v, m in zip(row, rel_mean, strict=True)] for row in rel])
        norm = float(dt @ dt)
        if norm <= 0.0:  # one stamp only (check_pose never lets a repeated stamp in)
            return None
        slope = (dt @ centred).tolist()
        innovation = [(v - r) - (m - b / norm * t_mean)
                      for v, r, m, b in zip(y, ref, rel_mean, slope, strict=True)]
        if self.ndof == 3:
            innovation[2] = wrap_angle(innovation[2])
        return innovation

    def _gate(self) -> list[float] | None:
        """Jump gate per DOF; the MAD is refreshed every GATE_REFRESH innovations (cost)."""
        if self._scale_count < MIN_SCALE_SAMPLES:
            return None
        if self._gate_cache is None or self._since_gate >= GATE_REFRESH:
            scale = MAD_TO_SIGMA * np.median(self._scale_buf[:self._scale_count], axis=0)
            floor = np.array(self.settings.jump_floor[:self.ndof])
            self._gate_cache = (self.settings.jump_gate * scale + floor).tolist()
            self._since_gate = 0
        return self._gate_cache

    def _stale_allowance(self, t: float) -> list[float]:
        """Gate widening for a stale local prediction (jump_rate × excess time since acceptance).

        The excess time is the time since the last accepted pose beyond the usual pose spacing
        (the median spacing of the local fit's poses). After a rejection the line is not
        updated, so without this a run of rejections during fast wave motion feeds itself until
        the 'step' test restarts the data (seen in the DDS demo: two false 1 m steps in 1800 s);
        a real outlier of metres stays far outside.
        """
        if len(self._fit) < 2:
            return [0.0] * self.ndof
        times = [s for s, _ in self._fit]
        steps = sorted(b - a for a, b in zip(times, times[1:], strict=False))
        half = len(steps) // 2
        if any(math.isnan(step) for step in steps):
            spacing = math.nan  # as np.median
        elif len(steps) % 2:
            spacing = steps[half]
        else:  # np.median of an even count: the mean of the two middle values
            spacing = (steps[half - 1] + steps[half]) / 2
        excess = max(0.0, t - times[-1] - spacing)
        return [rate * excess for rate in self.settings.jump_rate[:self.ndof]]

    def _check_jump(self, t: float, y: FloatArray) -> Verdict | None:
        """None: accepted and learned from; a Verdict otherwise (rejection or a new level)."""
        values = y.tolist()
        innovation = self._innovation(t, values)
        gate = self._gate()
        if gate is not None:
            gate = [g + a for g, a in zip(gate, self._stale_allowance(t), strict=True)]
        if innovation is not None and gate is not None and \
                any(abs(v) > g for v, g in zip(innovation, gate, strict=True)):
            self._pending.append((t, values))
            if t - self._pending[0][0] >= self.settings.jump_confirm and \
                    len(self._pending) >= MIN_FROZEN_SAMPLES and \
                    self._consistent(np.array(gate)):
                return self._new_level(t)
            self.counters['jump'] += 1
            size = float(np.max(np.abs(np.array(innovation)) / np.array(gate)))
            return self._reject('jump', f'innovation {size:.1f} × the gate against the local '
                                'prediction (outlier)')
        self._pending = []
        self._fit.append((t, values))
        if innovation is not None:
            row = self._scale_next
            self._scale_buf[row] = [abs(v) for v in innovation]
            self._scale_next = (row + 1) % SCALE_SAMPLES
            self._scale_count = min(self._scale_count + 1, SCALE_SAMPLES)
            self._since_gate += 1
        return None

    def _consistent(self, gate: FloatArray) -> bool:
        """The pending (rejected) samples agree among themselves: a step, not a burst."""
        values = np.array([v for _, v in self._pending])
        spread = np.abs(values - np.median(values, axis=0))
        if self.ndof == 3:
            spread[:, 2] = np.abs(wrap_angle(values[:, 2] - float(np.median(values[:, 2]))))
        return bool(np.all(spread <= gate))

    def _new_level(self, t: float) -> Verdict:
        """Accept a persistent step: re-seed the local prediction on the new samples."""
        self.counters['step'] += 1
        jump = float(np.max(np.abs(np.array(self._pending[-1][1][:2]) -
                                   np.array(self._fit[-1][1][:2])))) if self._fit else math.nan
        self.last_reason = (f'step: the reference stepped by {jump:.2f} m and stayed for '
                            f'{self.settings.jump_confirm:g} s: taken as the new level, data '
                            'restarted')
        self._events['step'] = t
        self._fit.clear()
        for sample in self._pending[-FIT_SAMPLES:]:
            self._fit.append(sample)
        self._pending = []
        self._block.clear()
        return Verdict(True, restart=True, fault='step')

    def _check_motion(self, t: float, y: FloatArray, wave_peak_freq: float | None) -> bool:
        """Add to the current block; at its end judge it. True when no motion is detected now."""
        self._block.append(t, y)
        period = 2.0 * math.pi / wave_peak_freq if wave_peak_freq and wave_peak_freq > 0 \
            else DEFAULT_WAVE_PERIOD
        if t - self._block.start < self.settings.motion_wave_periods * period or \
                self._block.size < MIN_BLOCK_SAMPLES:
            return False
        motion = _detrended_rms(*self._block.arrays(), self.ndof)
        self._block.clear()
        was = self._no_motion
        if len(self._motion_history) >= MIN_MOTION_BLOCKS:
            reference = np.median(np.array(self._motion_history), axis=0)
            self._no_motion = bool(np.all(motion < self.settings.motion_ratio * reference))
        if not self._no_motion and not self._frozen:
            self._motion_history.append(motion)
        if self._no_motion and not was:
            self.counters['no_wave_motion'] += 1
            return True
        return False

    # ---- grid-rate check against the predictor ---------------------------------------------

    def check_sample(self, t: float, pose: FloatArray, predicted: FloatArray | None) -> Verdict:
        """Drift test of one aligned sample against the prediction made for t (None: none).

        On detection the drift latches: this and every later pose are rejected until `reset`.
        """
        if not self.settings.reference_checks or predicted is None:
            return ACCEPT
        if self._drift:
            return self._reject('drift', 'drift latched: reference deselected until reset')
        measured = np.asarray(pose, dtype=np.float64)[:self.ndof].tolist()
        reference = np.asarray(predicted, dtype=np.float64)[:self.ndof].tolist()
        innovation = [a - b for a, b in zip(measured, reference, strict=True)]
        if self.ndof == 3:
            innovation[2] = wrap_angle(innovation[2])
        dt = 0.0 if self._drift_last_t is None else max(0.0, t - self._drift_last_t)
        if dt > self.settings.dropout_timeout:
            # across a dropout the first sample counts as one ordinary sample, not as the whole
            # gap (it would weigh one innovation, made right after a restart, as the mean)
            dt = self._drift_step
        self._drift_step = dt
        self._drift_last_t = t
        tau = self.settings.drift_time_constant
        if self._drift_mean is None:
            self._drift_mean = np.array(innovation, dtype=np.float64)
        else:
            self._drift_mean = low_pass_step(self._drift_mean, innovation, min(1.0, dt / tau))
        self._drift_time += dt
        if self._drift_time >= tau and any(
                abs(m) > limit for m, limit in zip(self._drift_mean.tolist(),
                                                   self.settings.drift_limit[:self.ndof],
                                                   strict=True)):
            self._drift = True
            self.counters['drift'] += 1
            size = ', '.join(f'{v:.3g}' for v in self._drift_mean)
            self._last_t = t if self._last_t is None else self._last_t
            return self._reject('drift', f'mean innovation against the prediction [{size}] '
                                f'over {tau:g} s beyond the limit '
                                f'{list(self.settings.drift_limit[:self.ndof])} (slow drift)',
                                restart=True)
        return ACCEPT

    # ---- dropout (caller's clock) -----------------------------------------------------------

    def seen(self, now: float) -> None:
        """A pose message arrived at ``now`` (the caller's clock): ends a dropout."""
        self._last_arrival = now
        self._in_dropout = False

    def silent_for(self, now: float) -> float | None:
        """Seconds since the last pose (caller's clock); flags and counts a dropout."""
        if self._last_arrival is None or not self.settings.reference_checks:
            return None
        silence = now - self._last_arrival
        if silence > self.settings.dropout_timeout and not self._in_dropout:
            self._in_dropout = True
            self._dropout_counted = True  # the stamp gap of the next pose is the same dropout
            self.counters['dropout'] += 1
        return silence

    # ---- status -----------------------------------------------------------------------------

    def status(self) -> tuple[Level, str]:
        """Level and reason of the reference now (OK when nothing is wrong)."""
        now = self._last_t
        if self._in_dropout and self._last_arrival is not None:
            return 'ERROR', (f'dropout: no measured pose for more than '
                             f'{self.settings.dropout_timeout:g} s')
        if self._drift or self._frozen or self._no_motion:
            return 'ERROR', self.last_reason
        recent = [name for name, stamp in self._events.items()
                  if now is not None and now - stamp <= EVENT_HOLD]
        if 'step' in recent:
            return 'ERROR', self.last_reason
        if 'jump' in recent:
            return 'WARN', f'jump: {self.counters["jump"]} pose(s) rejected as outliers'
        return 'OK', ''

    def values(self) -> dict[str, int | str]:
        """Diagnostic key values: ``ref_<fault>`` counters, rejections and active faults."""
        out: dict[str, int | str] = {f'ref_{name}': count for name, count in
                                     self.counters.items()}
        out['ref_rejected'] = self.rejected
        out['ref_faults'] = ' '.join(self.faults) or 'none'
        return out


class _PoseBlock:
    """The poses of a wave-motion block as growing arrays (stamps (n,), poses (n, ndof)).

    A block spans several wave periods of every measured pose (thousands at 100 Hz); built as
    a list of (t, pose) it cost 3.7–8.4 ms in the one callback that judged it
    (docs/BENCHMARKS.md, sixty-seventh session).
    """

    def __init__(self, ndof: int) -> None:
        self._times = RowBuffer()
        self._values = RowBuffer((ndof,))

    @property
    def size(self) -> int:
        """Poses held."""
        return len(self._times)

    @property
    def start(self) -> float:
        """The first pose's stamp [s] (the block is not empty)."""
        return float(self._times.view()[0])

    def append(self, t: float, y: FloatArray) -> None:
        """Add one pose (ndof values) stamped t."""
        self._times.append(t)
        self._values.append(y)

    def arrays(self) -> tuple[FloatArray, FloatArray]:
        """Copies of the stamps (n,) and poses (n, ndof) held, oldest first."""
        return self._times.view().copy(), self._values.view().copy()

    def clear(self) -> None:
        """Forget the poses."""
        self._times.clear()
        self._values.clear()


def _detrended_rms(times: FloatArray, values: FloatArray, ndof: int) -> FloatArray:
    """Per-DOF RMS of a block after removing its least-squares line (heading unwrapped).

    ``times`` (n,) and ``values`` (n, ndof), the caller's own copies (the heading column of
    ``values`` is unwrapped in place).
    """
    if ndof == 3:
        values[:, 2] = values[0, 2] + np.unwrap(values[:, 2] - values[0, 2])
    design = np.column_stack([np.ones_like(times), times - times.mean()])
    coef, *_ = np.linalg.lstsq(design, values, rcond=None)
    residual = values - design @ coef
    return np.asarray(np.sqrt(np.mean(residual ** 2, axis=0)), dtype=np.float64)
