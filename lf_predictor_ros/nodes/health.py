"""Input handling shared by the estimator nodes (predictor, observer).

Feeds thrust and pose messages into an `InputAligner` (message → numpy → aligner), counting
messages that do not convert (`_invalid_messages`), messages in an unexpected frame (WARN once per
topic) and exceptions caught in callbacks (ERROR, throttled), so a callback never kills the node
and `/diagnostics` can say what happened.
"""
from __future__ import annotations

from collections.abc import Callable
import traceback
from typing import TYPE_CHECKING, Any, Generic, TypeVar

from geometry_msgs.msg import PoseStamped, WrenchStamped
import numpy as np
from numpy.typing import NDArray
from rclpy.clock import Clock
from rclpy.impl.rcutils_logger import RcutilsLogger

from lf_predictor_ros.core.alignment import AlignedSample, InputAligner
from lf_predictor_ros.core.reference_checks import ReferenceChecker
from lf_predictor_ros.nodes.conversions import FRAME_BODY, msg_to_force, msg_to_pose, stamp_to_sec

FloatArray = NDArray[np.float64]
MsgT = TypeVar('MsgT', PoseStamped, WrenchStamped)


AnswerT = TypeVar('AnswerT')


class ReofferAnswers(Generic[AnswerT]):
    """Answers a re-offered sample with the output published for it (lockstep start).

    A lockstep simulator offers its first sample again until it hears an answer, and the first
    answer can be lost while publishers are still matching; an estimator that dropped the repeat
    as out of order would hang the loop. Call `answer` with every pose before it is processed
    (a pose equal in stamp and values to the one whose output was published last gets that
    output back, to publish again; any other is noted as the pose being fed), `published` with
    what was published for the pose being fed, and `forget` when something else was published or
    the state restarts.
    """

    def __init__(self) -> None:
        self._incoming: tuple[float, FloatArray] | None = None  # the pose being fed
        self._last: tuple[float, FloatArray, AnswerT] | None = None  # its pose, its output
        self.answered = 0  # re-offers answered

    def answer(self, t: float, pose: FloatArray) -> AnswerT | None:
        """The output to publish again if (t, pose) is a re-offer, else None (noted as fed)."""
        last = self._last
        if last is not None and t == last[0] and np.array_equal(pose, last[1]):
            self.answered += 1
            return last[2]
        self._incoming = (t, pose)
        return None

    def published(self, output: AnswerT) -> None:
        """``output`` was published for the pose being fed."""
        if self._incoming is not None:
            self._last = (*self._incoming, output)

    def forget(self) -> None:
        """Something else was published, or the state restarted: no re-offer to answer."""
        self._last = None


class InputHealth:
    """Mixin for an rclpy node: call `_init_input_health()` in `__init__` before any callback."""

    _invalid_messages: int
    _unexpected_frame: int
    _warned_frames: set[str]
    _callback_errors: int
    _errors_reported: int
    _last_error: str
    _traced_errors: set[tuple[str, str]]

    if TYPE_CHECKING:  # provided by rclpy's Node; declared here for the type checker only
        def get_logger(self) -> RcutilsLogger: ...

        def get_clock(self) -> Clock: ...

    def _init_input_health(self) -> None:
        self._invalid_messages = 0  # failed conversions (bad quaternion, negative stamp)
        self._unexpected_frame = 0
        self._warned_frames = set()
        self._callback_errors = 0
        self._errors_reported = 0  # errors already reported on /diagnostics
        self._last_error = ''
        self._traced_errors = set()  # (callback, exception type) whose traceback was logged

    def _check_frame(self, topic: str, frame_id: str, expected: str) -> None:
        if frame_id == expected:
            return
        self._unexpected_frame += 1
        if topic not in self._warned_frames:
            self._warned_frames.add(topic)
            self.get_logger().warning(
                f"{topic} arrives in frame '{frame_id}', expected '{expected}': used as is, "
                'counted in diagnostics (unexpected_frame); this warning is not repeated')

    def _count_error(self, where: str, error: BaseException) -> None:
        self._callback_errors += 1
        self._last_error = f'{where}: {type(error).__name__}: {error}'
        key = (where, type(error).__name__)
        if key not in self._traced_errors:  # the first of each kind with its traceback
            self._traced_errors.add(key)
            trace = ''.join(traceback.format_exception(error))
            self.get_logger().error(f'callback failed ({self._last_error}); it is caught, '
                                    f'counted and throttled from now on:\n{trace}')
            return
        self.get_logger().error(f'callback failed ({self._last_error})',
                                throttle_duration_sec=5.0)

    def _clock_seconds(self) -> float:
        """The node clock now [s] (the reference checks' dropout watch)."""
        return float(self.get_clock().now().nanoseconds) / 1e9

    def _log_reference_fault(self, checker: ReferenceChecker) -> None:
        """Log the reference's status after a fault: ERROR or WARN, throttled."""
        level, reason = checker.status()
        text = f'position reference: {reason or checker.last_reason}'
        if level == 'ERROR':  # rclpy: one severity per call site
            self.get_logger().error(text, throttle_duration_sec=5.0)
        else:
            self.get_logger().warning(text, throttle_duration_sec=5.0)

    def _clear_reference_faults(self, checker: ReferenceChecker | None, response: Any,
                                stays: str) -> Any:
        """Answer ``~/clear_reference_faults`` (std_srvs/Trigger): the checks start afresh.

        ``stays``: what the estimator keeps (said in the answer); None checker: not configured.
        """
        try:
            if checker is None:
                response.success, response.message = False, 'estimator not configured'
                return response
            faults = ' '.join(checker.faults) or 'none'
            checker.reset()
            response.success = True
            response.message = (f'reference faults cleared (were: {faults}); checks restart '
                                f'their statistics, {stays}')
            self.get_logger().info(response.message)
        except Exception as error:  # noqa: BLE001 - a service must never kill the node
            self._count_error('~/clear_reference_faults', error)
            response.success, response.message = False, f'clear failed: {error}'
        return response

    def _feed_thrust(self, msg: WrenchStamped,
                     aligner: InputAligner) -> tuple[float, FloatArray] | None:
        """Store an applied force in the aligner (zero-order hold); never raises.

        Returns (stamp [s], force) when the aligner took it (finite, in order), else None.
        """
        try:
            force = self._converted('thrust', msg, FRAME_BODY, msg_to_force)
            if force is not None:
                t = stamp_to_sec(msg.header.stamp)
                if aligner.add_force(t, force):
                    return t, force
        except Exception as error:  # noqa: BLE001 - a callback must never kill the node
            self._count_error('thrust', error)
        return None

    def _feed_pose(self, msg: PoseStamped, aligner: InputAligner, frame_id: str,
                   process: Callable[[AlignedSample], None],
                   accept: Callable[[float, FloatArray], bool] | None = None) -> None:
        """Align a measured pose and ``process`` every grid sample it completes; never raises.

        ``accept(t, pose)`` (the position-reference checks) sees every converted pose first; a
        pose it refuses never reaches the aligner.
        """
        try:
            pose = self._converted('measured_pose', msg, frame_id, msg_to_pose)
            if pose is not None:
                t = stamp_to_sec(msg.header.stamp)
                if accept is not None and not accept(t, pose):
                    return
                for sample in aligner.add_pose(t, pose):
                    process(sample)
        except Exception as error:  # noqa: BLE001 - a callback must never kill the node
            self._count_error('measured_pose', error)

    def _converted(self, topic: str, msg: MsgT, expected_frame: str,
                   convert: Callable[[MsgT], FloatArray]) -> FloatArray | None:
        """``convert(msg)`` after the frame check; None (counted invalid) if it cannot be read."""
        self._check_frame(topic, msg.header.frame_id, expected_frame)
        try:
            return convert(msg)
        except ValueError:
            self._invalid_messages += 1
            return None
