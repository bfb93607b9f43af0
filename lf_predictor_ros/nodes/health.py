"""Input-health bookkeeping shared by the estimator nodes (predictor, observer).

Counts messages in an unexpected frame (WARN once per topic) and exceptions caught in callbacks
(ERROR, throttled), so a callback never kills the node and `/diagnostics` can say what happened.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from rclpy.impl.rcutils_logger import RcutilsLogger


class InputHealth:
    """Mixin for an rclpy node: call `_init_input_health()` in `__init__` before any callback."""

    _unexpected_frame: int
    _warned_frames: set[str]
    _callback_errors: int
    _errors_reported: int
    _last_error: str

    if TYPE_CHECKING:  # provided by rclpy's Node; declared here for the type checker only
        def get_logger(self) -> RcutilsLogger: ...

    def _init_input_health(self) -> None:
        self._unexpected_frame = 0
        self._warned_frames = set()
        self._callback_errors = 0
        self._errors_reported = 0  # errors already reported on /diagnostics
        self._last_error = ''

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
        self.get_logger().error(f'callback failed ({self._last_error})',
                                throttle_duration_sec=5.0)
