"""Bag topics as numpy series, for reports, metrics and tests (no node).

`read_series(bag, topics)` turns each topic into a `Series`: log (receive) times, header stamps
and an `(n, k)` value array in the package's conventions (docs/ARCHITECTURE.md):

| type                               | values                               |
|------------------------------------|--------------------------------------|
| geometry_msgs/msg/PoseStamped      | `[north m, east m, yaw rad]`         |
| geometry_msgs/msg/WrenchStamped    | `[surge N, sway N, yaw N·m]`         |
| std_msgs/msg/Float64               | `[data]`                             |

A type without a header (Float64) takes its log time as stamp. Messages are decoded with
rclpy's type support (`ros_codec`), so the numbers are exactly those a subscriber would see;
times go through integer nanoseconds (`nodes.conversions.stamp_to_sec`), so a stamp written
from a float second comes back as the same float.

`read_diagnostics(bag)` flattens `/diagnostics` into `(stamp, status name, {key: value})`.

A missing topic or a topic of an unsupported type raises `BagError` (a ValueError) naming it.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
import os
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lf_predictor_ros.bag.mcap_reader import BagError, BagReader
from lf_predictor_ros.bag.ros_codec import deserialize
from lf_predictor_ros.nodes.conversions import (
    NS_PER_S,
    msg_to_force,
    msg_to_pose,
    stamp_to_sec,
)

__all__ = ['DIAGNOSTICS_TYPE', 'SUPPORTED_TYPES', 'BagError', 'Series', 'read_diagnostics',
           'read_series']

POSE_TYPE = 'geometry_msgs/msg/PoseStamped'
WRENCH_TYPE = 'geometry_msgs/msg/WrenchStamped'
FLOAT_TYPE = 'std_msgs/msg/Float64'
DIAGNOSTICS_TYPE = 'diagnostic_msgs/msg/DiagnosticArray'

BagSource = str | os.PathLike[str] | BagReader


def _float_values(message: Any) -> NDArray[np.float64]:
    return np.array([float(message.data)], dtype=np.float64)


# type name -> (number of value columns, message -> values, has a header)
_EXTRACTORS: dict[str, tuple[int, Callable[[Any], NDArray[np.float64]], bool]] = {
    POSE_TYPE: (3, msg_to_pose, True),
    WRENCH_TYPE: (3, msg_to_force, True),
    FLOAT_TYPE: (1, _float_values, False),
}
SUPPORTED_TYPES = tuple(_EXTRACTORS)


@dataclass(frozen=True)
class Series:
    """One topic as arrays (float64, in log-time order)."""

    topic: str
    log_time: NDArray[np.float64]  # (n,) receive/log time [s]
    stamp: NDArray[np.float64]  # (n,) header stamp [s] (= log_time for types without header)
    values: NDArray[np.float64]  # (n, k), see the module docstring

    def __len__(self) -> int:
        """Number of messages."""
        return int(self.log_time.shape[0])


class _OpenReader:
    """Context manager: use a given BagReader as is, or open (and later close) a path."""

    def __init__(self, source: BagSource) -> None:
        self._source = source
        self._owned: BagReader | None = None

    def __enter__(self) -> BagReader:
        if isinstance(self._source, BagReader):
            return self._source
        self._owned = BagReader(self._source)
        return self._owned

    def __exit__(self, *exc: object) -> None:
        if self._owned is not None:
            self._owned.close()


def _check_topics(reader: BagReader, topics: Sequence[str],
                  allowed: Sequence[str]) -> dict[str, str]:
    """Topic -> type for `topics`; BagError for a missing topic or an unsupported type."""
    available = reader.topics()
    missing = [topic for topic in topics if topic not in available]
    if missing:
        raise BagError(f'topic(s) {missing} not in bag {str(reader.path)!r}; it has '
                       f'{sorted(available)}')
    for topic in topics:
        if available[topic] not in allowed:
            raise BagError(f'topic {topic!r} in bag {str(reader.path)!r} has type '
                           f'{available[topic]}, expected one of {list(allowed)}')
    return {topic: available[topic] for topic in topics}


def read_series(path_or_reader: BagSource, topics: Sequence[str]) -> dict[str, Series]:
    """Read `topics` of a bag (path or open BagReader) into `Series`, keyed by topic.

    Raises BagError for a missing topic (listing the bag's topics), an unsupported type, or a
    message that does not decode / holds a non-finite value.
    """
    with _OpenReader(path_or_reader) as reader:
        types = _check_topics(reader, list(topics), SUPPORTED_TYPES)
        log_ns: dict[str, list[int]] = {topic: [] for topic in types}
        stamps: dict[str, list[float]] = {topic: [] for topic in types}
        rows: dict[str, list[NDArray[np.float64]]] = {topic: [] for topic in types}
        for message in reader.messages(list(types)):
            _, extract, has_header = _EXTRACTORS[types[message.topic]]
            decoded = _decode(message.data, types[message.topic], message.topic)
            try:
                rows[message.topic].append(extract(decoded))
            except ValueError as err:
                raise BagError(f'message on {message.topic!r} at log time '
                               f'{message.log_time_ns} ns is invalid: {err}') from None
            log_ns[message.topic].append(message.log_time_ns)
            stamps[message.topic].append(stamp_to_sec(decoded.header.stamp) if has_header
                                         else message.log_time_ns / NS_PER_S)
        return {topic: _to_series(topic, log_ns[topic], stamps[topic], rows[topic],
                                  _EXTRACTORS[types[topic]][0]) for topic in types}


def _decode(data: bytes, type_name: str, topic: str) -> Any:
    try:
        return deserialize(data, type_name)
    except Exception as err:  # rclpy raises plain exceptions on malformed CDR
        raise BagError(f'a message on {topic!r} does not decode as {type_name} ({err}); the '
                       'bag is corrupt or the topic type is wrong') from None


def _to_series(topic: str, log_ns: list[int], stamps: list[float],
               rows: list[NDArray[np.float64]], width: int) -> Series:
    values = np.array(rows, dtype=np.float64).reshape(len(rows), width)
    return Series(topic=topic,
                  log_time=np.array([t / NS_PER_S for t in log_ns], dtype=np.float64),
                  stamp=np.array(stamps, dtype=np.float64),
                  values=values)


def read_diagnostics(path_or_reader: BagSource,
                     topic: str = '/diagnostics') -> list[tuple[float, str, dict[str, str]]]:
    """`(stamp [s], status name, {key: value})` for every DiagnosticStatus on `topic`.

    The stamp is the array's header stamp, or its log time when the header stamp is zero.
    """
    with _OpenReader(path_or_reader) as reader:
        _check_topics(reader, [topic], [DIAGNOSTICS_TYPE])
        result: list[tuple[float, str, dict[str, str]]] = []
        for message in reader.messages([topic]):
            array = _decode(message.data, DIAGNOSTICS_TYPE, topic)
            stamp = stamp_to_sec(array.header.stamp)
            if stamp == 0.0:
                stamp = message.log_time_ns / NS_PER_S
            for status in array.status:
                values = {str(kv.key): str(kv.value) for kv in status.values}
                result.append((stamp, str(status.name), values))
        return result
