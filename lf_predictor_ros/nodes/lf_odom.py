"""Drive an ``LfStateEstimator`` from aligned samples and thrust stamps (predictor node, replay).

ROS-free glue shared by the predictor node and ``replay`` so both publish the same ``lf_pose`` /
``lf_odom`` stream and the same odometry diagnostics (issue 14):

- **tracking**: every aligned sample that passed the position-reference checks goes to
  ``LfStateEstimator.update``; its ``OdometryEstimate`` (stamp t + sample_time) is published on
  ``lf_pose`` and ``lf_odom``. While tracking its pose is the predictor's LF pose, bit for bit.
- **dead reckoning**: a thrust message stamped ``dead_reckoning_after`` or more after the last
  sample that went to ``update`` (poses silent, or rejected by the checks) calls
  ``LfStateEstimator.coast`` for the thrust stamp + ``sample_time`` (the thrust held over the
  next sample; the stamp rule of every estimate: the time it is valid for, so a lockstep
  simulator is answered as while tracking), at most once per ``sample_time``. Its estimate is
  published the same way. ``coast`` returns None once ``dead_reckoning_timeout`` has passed
  (mode 'lost'): nothing is published.
- **reacquisition**: the first samples after the dropout go through ``update`` like any other,
  so the odometry's plausibility gate and reacquire blend apply (a new data segment restarts the
  predictor's segment; the odometry keeps its state across it).
- **time order**: a sample whose estimate would not be newer than one already published (the
  dead-reckoned estimate for the same instant, or poses delivered late in a burst after the
  silence) still feeds the predictor, its buffers and the odometry but is not published
  (``late_samples``): published stamps always increase; a new segment that starts
  ``backward_jump`` or more before the last estimate (simulator reset, bag loop) restarts the
  odometry's timeline (``odom_time_jumps``; calibration and vessel memory kept).

Nothing here raises on data: the caller catches what ``LfStateEstimator`` raises.
"""
from __future__ import annotations

import math

from lf_predictor_ros.core.lf_state import LfStateEstimator
from lf_predictor_ros.core.odometry import OdometryEstimate
from lf_predictor_ros.nodes.diagnostics import DiagnosticValue
from lf_predictor_ros.nodes.health import FloatArray

# Tolerance on stamp comparisons [s].
STAMP_EPS = 1e-9


def dead_reckoning_silence(dead_reckoning_after: float, sample_time: float) -> float:
    """The pose silence [s] that starts dead reckoning: the setting, 0 = 2 × sample_time.

    Raises ValueError (with what to do) when a non-zero setting is shorter than one sample.
    """
    if not (math.isfinite(dead_reckoning_after) and dead_reckoning_after >= 0.0):
        raise ValueError('dead_reckoning_after must be a finite number >= 0 s (0 = 2 × '
                         f'sample_time), got {dead_reckoning_after}')
    if dead_reckoning_after == 0.0:
        return 2.0 * sample_time
    if dead_reckoning_after < sample_time:
        raise ValueError(f'dead_reckoning_after ({dead_reckoning_after} s) must be >= '
                         f'sample_time ({sample_time} s) or 0 (= 2 × sample_time): a shorter '
                         'silence happens between any two samples')
    return dead_reckoning_after


class OdomDriver:
    """Decides when to ``update`` and when to ``coast`` (see the module docstring)."""

    def __init__(self, state: LfStateEstimator, dead_reckoning_after: float,
                 backward_jump: float) -> None:
        """``dead_reckoning_after`` as resolved by `dead_reckoning_silence` [s]."""
        self.state = state
        self.dead_reckoning_after = dead_reckoning_after
        self.backward_jump = backward_jump
        self.counters = {'late_samples': 0, 'time_jumps': 0, 'coasts': 0,
                         'commands_invalid': 0, 'commands_out_of_order': 0}
        self.reset()

    def reset(self) -> None:
        """Forget the timeline (after ``LfStateEstimator.reset`` or a new estimator)."""
        self._last_sample_t: float | None = None  # grid time of the last update [s]
        self._last_coast_t: float | None = None  # thrust stamp of the last coast [s]
        self._odom_stamp: float | None = None  # newest stamp the odometry has seen [s]
        self._last_thrust_t: float | None = None

    @property
    def sample_time(self) -> float:
        """The state estimator's sample time [s]."""
        return self.state.sample_time

    def update(self, t: float, pose: FloatArray, force: FloatArray,
               segment_start: bool) -> tuple[FloatArray | None, OdometryEstimate | None]:
        """One accepted sample: (predictor LF pose, estimate to publish or None).

        The LF pose is None for a late sample (its estimate was refused by the odometry). The
        caller has already called ``restart_segment`` for a segment start.
        """
        h = self.sample_time
        stamp = t + h
        # not newer than an estimate already published (dead-reckoned for the same instant, or
        # later): the state takes the sample, nothing is published, stamps stay increasing
        late = self._odom_stamp is not None and stamp <= self._odom_stamp + STAMP_EPS
        if late and segment_start and stamp < (self._odom_stamp or 0.0) - self.backward_jump:
            self.state.odometry.restart()  # time went backwards: a new timeline
            self.counters['time_jumps'] += 1
            self._odom_stamp = self._last_coast_t = None
            late = False
        self._last_sample_t = t
        lf_pose, estimate = self.state.update(t, pose, force)  # it learns from a late one too
        if late:
            self.counters['late_samples'] += 1
            return None, None
        self._odom_stamp = stamp if self._odom_stamp is None else max(self._odom_stamp, stamp)
        return lf_pose, estimate

    def command(self, t: float, force: FloatArray) -> None:
        """A DP controller command stamped t (``thrust_command``): logged for its gains.

        A non-finite stamp or force is counted (``commands_invalid``) and dropped, one not newer
        than the last command too (``commands_out_of_order``).
        """
        try:
            accepted = self.state.command(t, force)
        except ValueError:
            self.counters['commands_invalid'] += 1
            return
        if not accepted:
            self.counters['commands_out_of_order'] += 1

    def thrust(self, t: float, force: FloatArray) -> OdometryEstimate | None:
        """An accepted thrust stamped t: the dead-reckoned estimate to publish, or None."""
        if not math.isfinite(t):
            return None
        if self._last_thrust_t is None or t > self._last_thrust_t:
            self._last_thrust_t = t
        if self._last_sample_t is None or \
                t - self._last_sample_t < self.dead_reckoning_after - STAMP_EPS:
            return None
        if self._last_coast_t is not None and \
                t < self._last_coast_t + self.sample_time - STAMP_EPS:
            return None
        stamp = t + self.sample_time  # valid for t + h, like every tracked estimate
        if self._odom_stamp is not None and stamp <= self._odom_stamp:
            return None
        self._last_coast_t = t
        self.counters['coasts'] += 1
        estimate = self.state.coast(stamp, force)
        self._odom_stamp = stamp
        return estimate

    # ---- diagnostics ---------------------------------------------------------------------

    def dead_reckoning_time(self) -> float:
        """Seconds since the last accepted fix at the newest thrust stamp (0 while tracking)."""
        if self._last_thrust_t is None:
            return 0.0
        return self.state.odometry.dead_reckoning_time(self._last_thrust_t)

    def status(self) -> tuple[str, str]:
        """(level, message) of the odometry: OK tracking, WARN dead reckoning, ERROR lost."""
        odometry = self.state.odometry
        timeout = odometry.params.dead_reckoning_timeout
        if odometry.mode == 'lost':
            return 'ERROR', (f'lost: no accepted position reference for > {timeout:g} s: not '
                             'publishing')
        if odometry.mode == 'dead_reckoning':
            reckoner = self.state.memory.reckoner if self.state.memory is not None \
                else 'constant_velocity'
            return 'WARN', (f'dead_reckoning for {self.dead_reckoning_time():.1f} s on thrust '
                            f'with the {reckoner} reckoner (no accepted position reference; '
                            f'stops after {timeout:g} s)')
        return 'OK', ''

    def values(self) -> dict[str, DiagnosticValue]:
        """Diagnostic key values of the odometry."""
        odometry = self.state.odometry
        memory = self.state.memory
        values: dict[str, DiagnosticValue] = {
            'odom_mode': odometry.mode,
            'dead_reckoning_time': self.dead_reckoning_time(),
            'reckoner': odometry.reckoner,
            'odom_calibrated': odometry.calibrated,
            'vessel_memory': memory is not None,
            'vessel_memory_error': self.state.memory_error or '',
            'vessel_memory_note': memory.message if memory is not None else '',
            'thrust_gain_source': (memory.known_gain or 'fitted') if memory is not None else '',
            'dead_reckoning_after': self.dead_reckoning_after,
            'dead_reckoning_timeout': odometry.params.dead_reckoning_timeout,
        }
        values.update({f'odom_{name}': int(count) for name, count in odometry.counters.items()})
        values.update({f'odom_{name}': int(count) for name, count in self.counters.items()})
        return values
