"""Build ``diagnostic_msgs/DiagnosticArray`` messages for ``/diagnostics``.

One status per node: a name (``'<node>: <what>'``), a level (OK / WARN / ERROR / STALE), a
one-line message and key/value pairs. Values are formatted for people reading
``ros2 topic echo /diagnostics`` or ``rqt_runtime_monitor``: floats with 6 significant digits,
booleans as ``true``/``false``.
"""
from __future__ import annotations

from collections.abc import Mapping
import math
from typing import NamedTuple

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from lf_predictor_ros.core.estimator import EstimatorStatus

DiagnosticValue = float | int | bool | str

_LEVELS: dict[str, bytes] = {
    'OK': DiagnosticStatus.OK,
    'WARN': DiagnosticStatus.WARN,
    'ERROR': DiagnosticStatus.ERROR,
    'STALE': DiagnosticStatus.STALE,
}


_RANK = {'OK': 0, 'WARN': 1, 'ERROR': 2, 'STALE': 3}


def worse(level: str, message: str, other_level: str, other_message: str) -> tuple[str, str]:
    """The more severe of two (level name, message) pairs; on a tie the first."""
    if _RANK[other_level.upper()] > _RANK[level.upper()]:
        return other_level, other_message
    return level, message


def with_reference_and_odometry(level: str, message: str, reference: tuple[str, str],
                                odometry: tuple[str, str]) -> tuple[str, str]:
    """Raise (level, message) by the position-reference checks and the LF odometry state.

    ``reference``: (level, reason) of the checks; ``odometry``: (level, message) of the
    odometry driver. While the odometry is not tracking it leads the message — dead reckoning
    bridges a reference fault (WARN), lost is ERROR — and names the reference fault; otherwise a
    reference fault raises the level and leads. The predictor node and ``replay`` both use it.
    """
    ref_level, ref_reason = reference
    odom_level, odom_message = odometry
    if odom_level != 'OK':
        if ref_level != 'OK':
            odom_message = f'{odom_message}; position reference {ref_reason}'
        return worse(level, message, odom_level, odom_message)[0], f'{odom_message}; {message}'
    return worse(level, message, ref_level, f'position reference {ref_reason}; {message}')


def level_byte(level: str | int | bytes) -> bytes:
    """Normalize a level given as a name ('OK', 'warn'), an int 0–3 or a byte to a byte."""
    if isinstance(level, str):
        key = level.upper()
        if key not in _LEVELS:
            raise ValueError(f'diagnostic level must be one of {sorted(_LEVELS)}, got {level!r}')
        return _LEVELS[key]
    value = level[0] if isinstance(level, bytes) and len(level) == 1 else level
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 3:
        raise ValueError(
            f'diagnostic level must be 0 (OK), 1 (WARN), 2 (ERROR) or 3 (STALE), got {level!r}')
    return bytes([value])


def format_value(value: DiagnosticValue) -> str:
    """Format one diagnostic value: floats '%.6g' (nan/inf spelled out), bools lower case."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return 'nan'
        if math.isinf(value):
            return 'inf' if value > 0 else '-inf'
        return f'{value:.6g}'
    return str(value)


def make_status(
    name: str,
    level: str | int | bytes,
    message: str,
    values: Mapping[str, DiagnosticValue] | None = None,
    hardware_id: str = '',
) -> DiagnosticStatus:
    """One ``DiagnosticStatus`` with its key/value pairs in the mapping's order."""
    fields = status_fields(name, level, message, values, hardware_id)
    status = DiagnosticStatus()
    status.level = fields.level
    status.name = fields.name
    status.message = fields.message
    status.hardware_id = fields.hardware_id
    status.values = [KeyValue(key=key, value=value) for key, value in fields.values]
    return status


class StatusFields(NamedTuple):
    """The fields of a ``DiagnosticStatus`` as `make_status` fills them."""

    level: bytes
    name: str
    message: str
    hardware_id: str
    values: list[tuple[str, str]]  # (key, formatted value)


def status_fields(
    name: str,
    level: str | int | bytes,
    message: str,
    values: Mapping[str, DiagnosticValue] | None = None,
    hardware_id: str = '',
) -> StatusFields:
    """`make_status`'s fields without the message objects (for a direct CDR writer)."""
    return StatusFields(level_byte(level), name, message, hardware_id,
                        [(str(key), format_value(value)) for key, value in (values or {}).items()])


def make_diagnostic_array(
    name: str,
    level: str | int | bytes,
    message: str,
    values: Mapping[str, DiagnosticValue] | None = None,
    stamp: Time | None = None,
    hardware_id: str = '',
) -> DiagnosticArray:
    """A ``DiagnosticArray`` holding one status; ``stamp`` defaults to zero (unset)."""
    array = DiagnosticArray()
    if stamp is not None:
        array.header.stamp = Time(sec=stamp.sec, nanosec=stamp.nanosec)
    array.status = [make_status(name, level, message, values, hardware_id)]
    return array


def _number(value: float | None) -> float:
    return math.nan if value is None else float(value)


def predictor_values(status: EstimatorStatus,
                     counters: Mapping[str, int]) -> dict[str, DiagnosticValue]:
    """Key values of the adaptive predictor's health (node and replay publish the same keys)."""
    return {
        'state': status.state,
        'wave_peak_freq': _number(status.wave_peak_freq),
        'last_loss': _number(status.last_loss),
        'train_seconds': _number(status.train_seconds),
        'model_age': _number(status.model_age),
        'buffer_fill': _number(status.buffer_fill),
        'trainings': int(status.trainings),
        'rejected_trainings': int(status.rejected_trainings),
        'overruns': int(counters.get('overruns', 0)),
        'training_errors': int(counters.get('training_errors', 0)),
        'guard_trips': int(counters.get('guard_trips', 0)),
        'rough_retirements': int(counters.get('rough_retirements', 0)),
        'segments': int(counters.get('segments', 0)),
        'trainings_without_thrust': int(counters.get('trainings_without_thrust', 0)),
        'trainings_thrust_held': int(counters.get('trainings_thrust_held', 0)),
    }


def input_values(aligner: Mapping[str, int], samples: int,
                 invalid_messages: int = 0) -> dict[str, DiagnosticValue]:
    """Key values of the input chain: messages received, samples predicted, what was dropped.

    ``poses_accepted`` / ``forces_accepted`` count the messages the aligner took (not dropped as
    invalid, out of order or outlier): on a clean feed, a publisher's count minus
    ``poses_accepted`` is what the transport (the DDS reader queue) lost.

    ``aligner`` is `InputAligner.counters.as_dict()`; ``invalid_messages`` counts messages that
    did not even decode (e.g. a zero quaternion) and are added to ``invalid``.
    """
    invalid = int(aligner.get('invalid', 0)) + invalid_messages
    out_of_order = int(aligner.get('out_of_order', 0))
    outliers = int(aligner.get('outliers', 0))
    return {
        'poses_accepted': int(aligner.get('poses', 0)),
        'forces_accepted': int(aligner.get('forces', 0)),
        'samples': int(samples),
        'dropped': invalid + out_of_order + outliers,
        'invalid': invalid,
        'out_of_order': out_of_order,
        'outliers': outliers,
        'gaps': int(aligner.get('gaps', 0)),
        'resets': int(aligner.get('resets', 0)),
        'stale_thrust': int(aligner.get('stale_force_samples', 0)),
    }
