"""ROS side of the bag tools: message classes, CDR (de)serialization, QoS <-> rosbag2 YAML.

The MCAP writer and reader are ROS-free and deal in bytes; this module turns bytes into ROS
message objects and back with rclpy's own type support, so what is written is exactly what a
ROS publisher sends. `rosidl_runtime_py` is not a dependency: message classes are imported
from `pkg.msg` like rosidl_runtime_py.utilities.get_message does.

The estimate's messages (PoseStamped, Odometry, Float64) are also written straight to CDR, the
same bytes as `serialize` gives: replay writes them to the bag that way, and the predictor node
publishes them that way (`estimate_cdr`; a serialized publish skips rclpy's message objects and
type-support conversion, which were about a third of the node's per-sample step: docs/
BENCHMARKS.md, "Twenty-seventh session").
"""
# rclpy's QoSProfile constructor is untyped.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

from collections.abc import Sequence
import importlib
import struct
from typing import Any, NamedTuple

from builtin_interfaces.msg import Time
from numpy.typing import ArrayLike
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rclpy.serialization import deserialize_message, serialize_message
import yaml

from lf_predictor_ros.bag.mcap_writer import (
    INFINITE_DURATION_NS,
    qos_profile_dict,
    qos_profiles_yaml,
)
from lf_predictor_ros.bag.msgdefs import split_type_name
from lf_predictor_ros.nodes.conversions import odometry_fields, odometry_to_msg, pose_to_msg

_CLASS_CACHE: dict[str, type[Any]] = {}


def message_class(type_name: str) -> type[Any]:
    """The Python class of `pkg/msg/Type` (ValueError if the package is not installed)."""
    cached = _CLASS_CACHE.get(type_name)
    if cached is not None:
        return cached
    package, interface, name = split_type_name(type_name)
    try:
        module = importlib.import_module(f'{package}.{interface}')
        cls: type[Any] = getattr(module, name)
    except (ImportError, AttributeError):
        raise ValueError(f'message type {type_name} is not importable as '
                         f'{package}.{interface}.{name}; install or source the {package} '
                         'package') from None
    _CLASS_CACHE[type_name] = cls
    return cls


def type_name_of(message: Any) -> str:
    """`pkg/msg/Type` of a message instance or class."""
    cls = message if isinstance(message, type) else type(message)
    return f'{cls.__module__.split(".")[0]}/msg/{cls.__name__}'


def serialize(message: Any) -> bytes:
    """CDR bytes of a ROS message, as a publisher would send them."""
    return bytes(serialize_message(message))


def deserialize(data: bytes, type_name: str) -> Any:
    """The ROS message of type `type_name` encoded in CDR `data`."""
    return deserialize_message(data, message_class(type_name))


class StampedFields(NamedTuple):
    """Header stamp and the numbers of a PoseStamped or WrenchStamped (frame_id not kept)."""

    sec: int
    nanosec: int
    values: tuple[float, ...]  # pose: position x y z, orientation x y z w; wrench: force, torque


POSE_STAMPED = 'geometry_msgs/msg/PoseStamped'
WRENCH_STAMPED = 'geometry_msgs/msg/WrenchStamped'
_CDR_LE = b'\x00\x01\x00\x00'  # encapsulation: plain CDR, little endian, no options
_HEADER = struct.Struct('<iII')  # stamp.sec, stamp.nanosec, frame_id length (NUL included)
_BODIES = {POSE_STAMPED: struct.Struct('<7d'), WRENCH_STAMPED: struct.Struct('<6d')}


def stamped_fields(data: bytes, type_name: str) -> StampedFields:
    """Stamp and numbers of a PoseStamped / WrenchStamped in CDR ``data``.

    The common encoding (CDR little endian, ASCII frame_id, nothing after the last double) is
    read directly: the same numbers as ``deserialize`` gives, without building the message
    objects. Anything else goes through ``deserialize`` (and raises what it raises).
    """
    body = _BODIES[type_name]
    fields = _unpack_stamped(data, body)
    if fields is not None:
        return fields
    message = deserialize(data, type_name)
    stamp = message.header.stamp
    values: tuple[float, ...]
    if type_name == POSE_STAMPED:
        position, q = message.pose.position, message.pose.orientation
        values = (position.x, position.y, position.z, q.x, q.y, q.z, q.w)
    else:
        force, torque = message.wrench.force, message.wrench.torque
        values = (force.x, force.y, force.z, torque.x, torque.y, torque.z)
    return StampedFields(stamp.sec, stamp.nanosec, values)


def _unpack_stamped(data: bytes, body: struct.Struct) -> StampedFields | None:
    """Header + fixed block of doubles from plain little-endian CDR; None for anything else."""
    if len(data) < 4 + _HEADER.size or data[:4] != _CDR_LE:
        return None
    sec, nanosec, length = _HEADER.unpack_from(data, 4)
    end = 4 + _HEADER.size + length  # after the frame_id's NUL
    start = 4 + ((end - 4 + 7) & ~7)  # doubles are 8-aligned in the payload
    if length == 0 or len(data) != start + body.size or data[end - 1] != 0:
        return None
    frame_id = data[4 + _HEADER.size:end - 1]
    if not frame_id.isascii() or 0 in frame_id:
        return None
    return StampedFields(sec, nanosec, body.unpack_from(data, start))


def cdr_text(text: str) -> bytes | None:
    """The UTF-8 bytes of a string field when the direct writers below can take it, else None."""
    return text.encode('ascii') if text.isascii() and '\0' not in text else None


def pose_stamped_cdr(sec: int, nanosec: int, frame_id: bytes,
                     values: Sequence[float]) -> bytes:
    """CDR of a PoseStamped (position x y z, orientation x y z w), as `serialize` (padding 0).

    ``frame_id`` from `cdr_text`.
    """
    out = _header_cdr(sec, nanosec, frame_id)
    _align8(out)
    out += _POSE.pack(*values)
    return bytes(out)


def odometry_cdr(sec: int, nanosec: int, frame_id: bytes, child_frame_id: bytes,
                 pose: Sequence[float], pose_covariance: Sequence[float],
                 twist: Sequence[float], twist_covariance: Sequence[float]) -> bytes:
    """CDR of a nav_msgs/Odometry, as `serialize` (padding 0); string ids from `cdr_text`."""
    out = _header_cdr(sec, nanosec, frame_id)
    _align4(out)
    out += _UINT32.pack(len(child_frame_id) + 1) + child_frame_id + b'\0'
    _align8(out)
    out += _ODOMETRY_BODY.pack(*pose, *pose_covariance, *twist, *twist_covariance)
    return bytes(out)


def estimate_cdr(stamp: Time, frame_id: str, child_frame_id: str, pose: ArrayLike,
                 pose_cov: ArrayLike, twist: ArrayLike,
                 twist_cov: ArrayLike) -> tuple[bytes, bytes]:
    """One 3-DOF estimate as the CDR of its PoseStamped (lf_pose) and Odometry (lf_odom).

    The bytes `serialize` gives for `pose_to_msg` and `odometry_to_msg` of the same arguments,
    written directly (`pose_stamped_cdr`, `odometry_cdr`); frame ids the direct writers cannot
    take (`cdr_text`) go through rclpy's encoder. Raises ValueError as `odometry_to_msg` does.
    """
    frame_bytes, child_bytes = cdr_text(frame_id), cdr_text(child_frame_id)
    if frame_bytes is None or child_bytes is None:
        return (serialize(pose_to_msg(pose, stamp, frame_id)),
                serialize(odometry_to_msg(stamp, pose, pose_cov, twist, twist_cov, frame_id,
                                          child_frame_id)))
    fields = odometry_fields(pose, pose_cov, twist, twist_cov)  # checked as odometry_to_msg
    return (pose_stamped_cdr(stamp.sec, stamp.nanosec, frame_bytes, fields[0]),
            odometry_cdr(stamp.sec, stamp.nanosec, frame_bytes, child_bytes, *fields))


def float64_cdr(value: float) -> bytes:
    """CDR of a std_msgs/Float64 (NaN and ±inf too, as rclpy writes them)."""
    return _CDR_LE + _FLOAT64.pack(value)


def diagnostic_array_cdr(sec: int, nanosec: int, frame_id: str,
                         statuses: Sequence[tuple[bytes, str, str, str,
                                                  Sequence[tuple[str, str]]]]) -> bytes | None:
    """CDR of a DiagnosticArray, as `serialize` (padding 0); None if a string holds a NUL.

    ``statuses``: (level byte, name, message, hardware_id, [(key, value)]) each, as
    `nodes.diagnostics.status_fields` gives them. Strings are UTF-8, as rclpy writes them.
    """
    out = bytearray(_CDR_LE)
    out += _STAMP.pack(sec, nanosec)
    if not _put_string(out, frame_id):
        return None
    _align4(out)
    out += _UINT32.pack(len(statuses))
    for level, name, message, hardware_id, values in statuses:
        out += level
        for text in (name, message, hardware_id):
            _align4(out)
            if not _put_string(out, text):
                return None
        _align4(out)
        out += _UINT32.pack(len(values))
        for key, value in values:
            _align4(out)
            if not _put_string(out, key):
                return None
            _align4(out)
            if not _put_string(out, value):
                return None
    return bytes(out)


def _put_string(out: bytearray, text: str) -> bool:
    """Append a CDR string (the caller aligned to 4); False for a string with a NUL in it."""
    if '\0' in text:
        return False
    encoded = text.encode('utf-8')
    out += _UINT32.pack(len(encoded) + 1)
    out += encoded
    out += b'\0'
    return True


def _align4(out: bytearray) -> None:
    out += b'\0' * (-(len(out) - 4) % 4)


_STAMP = struct.Struct('<iI')
_UINT32 = struct.Struct('<I')
_POSE = struct.Struct('<7d')
_FLOAT64 = struct.Struct('<d')
_ODOMETRY_BODY = struct.Struct('<85d')  # pose 7, covariance 36, twist 6, covariance 36


def _header_cdr(sec: int, nanosec: int, frame_id: bytes) -> bytearray:
    out = bytearray(_CDR_LE)
    out += _HEADER.pack(sec, nanosec, len(frame_id) + 1)
    out += frame_id
    out += b'\0'
    return out


def _align8(out: bytearray) -> None:
    out += b'\0' * (-(len(out) - 4) % 8)


def qos_to_dict(qos: QoSProfile) -> dict[str, Any]:
    """A QoS profile as one rosbag2 v9 `offered_qos_profiles` entry."""
    return qos_profile_dict(
        history=_policy_name(qos.history),
        depth=int(qos.depth),
        reliability=_policy_name(qos.reliability),
        durability=_policy_name(qos.durability),
        deadline_ns=_duration_ns(qos.deadline),
        lifespan_ns=_duration_ns(qos.lifespan),
        liveliness=_policy_name(qos.liveliness),
        liveliness_lease_duration_ns=_duration_ns(qos.liveliness_lease_duration),
        avoid_ros_namespace_conventions=bool(qos.avoid_ros_namespace_conventions),
    )


def offered_qos_yaml(profiles: Sequence[QoSProfile]) -> str:
    """`offered_qos_profiles` channel metadata for the publishers' QoS profiles."""
    return qos_profiles_yaml([qos_to_dict(q) for q in profiles])


def publishers_qos_yaml(node: Node, topic: str) -> tuple[str, str]:
    """(`offered_qos_profiles` text, RIHS01 type hash) of the publishers `node` sees on topic."""
    infos = node.get_publishers_info_by_topic(topic)
    type_hash = str(infos[0].topic_type_hash) if infos else ''
    return offered_qos_yaml([info.qos_profile for info in infos]), type_hash


def qos_from_yaml(text: str, *, default_depth: int = 10) -> QoSProfile:
    """A publisher QoS that reproduces the recorded offers (first profile; rosbag2's rule).

    Reliability and durability come from the recording; history is keep_last `default_depth`
    (a recorded 'unknown' history cannot be requested). Empty text gives the contract's default
    publisher profile: reliable, volatile, keep_last 10.
    """
    profiles = yaml.safe_load(text) if text else None
    qos = QoSProfile(depth=default_depth, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    if not profiles:
        return qos
    first = profiles[0]
    if str(first.get('reliability')) == 'best_effort':
        qos.reliability = ReliabilityPolicy.BEST_EFFORT
    if str(first.get('durability')) == 'transient_local':
        qos.durability = DurabilityPolicy.TRANSIENT_LOCAL
    return qos


def _policy_name(policy: Any) -> str:
    """The rmw string of a policy value ('keep_last', 'reliable', 'unknown', ...)."""
    return str(policy.short_key)


def _duration_ns(duration: Duration) -> int:
    nanoseconds = int(duration.nanoseconds)
    return INFINITE_DURATION_NS if nanoseconds < 0 else nanoseconds
