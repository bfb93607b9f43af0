"""Conversions between the package's numpy conventions and ROS 2 messages.

A pose is ``[north m, east m, yaw rad]`` in ``map_ned``; a generalized force is
``[surge N, sway N, yaw N·m]`` in ``base_link_fsd`` (docs/ARCHITECTURE.md). Heading ψ is the
rotation about the down axis, so the quaternion is ``w = cos(ψ/2), z = sin(ψ/2)``
(interfaces.md "Frames and units"; Fossen 2011 §2.2.2, unit quaternions).

Time stamps are converted through integer nanoseconds so that no float rounding accumulates:
``sec_to_stamp`` gives the nanosecond nearest to the exact binary value of the float, and
``stamp_to_sec`` the float nearest to the exact stamp (Python's int / int is correctly rounded).

No node lives here: only message types, numpy and the standard library.
"""
from __future__ import annotations

from fractions import Fraction
import math

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, WrenchStamped
import numpy as np
from numpy.typing import ArrayLike, NDArray

FRAME_EARTH = 'map_ned'
FRAME_BODY = 'base_link_fsd'

NS_PER_S = 1_000_000_000  # [ns/s]
MAX_STAMP_SEC = 2**31 - 1  # [s] builtin_interfaces/Time.sec is int32



def _vector3(values: ArrayLike, what: str) -> NDArray[np.float64]:
    """Return ``values`` as a finite float array of shape (3,), or raise ValueError."""
    array = np.asarray(values, dtype=np.float64)
    if array.shape != (3,):
        raise ValueError(
            f'{what} must have shape (3,) ([north, east, yaw] or [surge, sway, yaw]), '
            f'got shape {array.shape}; pass one sample, not a series')
    if not np.all(np.isfinite(array)):
        raise ValueError(f'{what} must be finite, got {array.tolist()}; drop or repair the sample')
    return array


def ns_to_stamp(ns: int) -> Time:
    """Build a ``builtin_interfaces/Time`` from integer nanoseconds (≥ 0)."""
    if ns < 0:
        raise ValueError(f'a stamp must not be negative, got {ns} ns; ROS time starts at 0')
    sec, nanosec = divmod(int(ns), NS_PER_S)
    if sec > MAX_STAMP_SEC:
        raise ValueError(
            f'a stamp must be below 2**31 s (int32 seconds), got {sec} s; check the time source')
    return Time(sec=sec, nanosec=nanosec)


def sec_to_ns(sec: float) -> int:
    """Seconds → the nearest integer nanosecond of the float's exact value (no scaling error)."""
    if not math.isfinite(sec):
        raise ValueError(f'a time must be finite, got {sec}')
    if sec < 0.0:
        raise ValueError(f'a stamp must not be negative, got {sec} s; ROS time starts at 0')
    return round(Fraction(sec) * NS_PER_S)


def sec_to_stamp(sec: float) -> Time:
    """Seconds (float, ≥ 0) → ``builtin_interfaces/Time`` with exact integer nanoseconds."""
    return ns_to_stamp(sec_to_ns(sec))


def stamp_to_ns(stamp: Time) -> int:
    """``builtin_interfaces/Time`` → integer nanoseconds."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def stamp_to_sec(stamp: Time) -> float:
    """``builtin_interfaces/Time`` → seconds, the float nearest to the exact stamp."""
    return stamp_to_ns(stamp) / NS_PER_S  # int / int is correctly rounded in Python


def _as_stamp(stamp: float | Time) -> Time:
    if isinstance(stamp, Time):
        return Time(sec=stamp.sec, nanosec=stamp.nanosec)
    return sec_to_stamp(float(stamp))


def pose_to_msg(pose: ArrayLike, stamp: float | Time, frame_id: str = FRAME_EARTH) -> PoseStamped:
    """Pose ``[north, east, yaw]`` → ``PoseStamped`` (z = 0, quaternion about the down axis).

    ``stamp`` is seconds (float) or a ``builtin_interfaces/Time`` (copied exactly).
    """
    north, east, yaw = _vector3(pose, 'pose')
    msg = PoseStamped()
    msg.header.stamp = _as_stamp(stamp)
    msg.header.frame_id = frame_id
    msg.pose.position.x = float(north)
    msg.pose.position.y = float(east)
    msg.pose.position.z = 0.0
    msg.pose.orientation.w = math.cos(0.5 * yaw)
    msg.pose.orientation.x = 0.0
    msg.pose.orientation.y = 0.0
    msg.pose.orientation.z = math.sin(0.5 * yaw)
    return msg


def quaternion_to_yaw(w: float, x: float, y: float, z: float) -> float:
    """Yaw [rad] in (−π, π] of a quaternion, not necessarily unit (ZYX Euler angles).

    ψ = atan2(2(wz + xy), w² + x² − y² − z²) (Fossen 2011 eq. 2.57 with the normalization
    w² + x² + y² + z² kept in place of 1, so any positive scale cancels).
    """
    norm_sq = w * w + x * x + y * y + z * z
    if not math.isfinite(norm_sq) or norm_sq < 1e-300:
        raise ValueError(
            f'orientation quaternion must be finite and non-zero, got (w={w}, x={x}, y={y}, '
            f'z={z}); the publisher must fill pose.orientation')
    yaw = math.atan2(2.0 * (w * z + x * y), w * w + x * x - y * y - z * z)  # in [−π, π]
    return math.pi if yaw <= -math.pi else yaw


def msg_to_pose(msg: PoseStamped) -> NDArray[np.float64]:
    """``PoseStamped`` → pose ``[north, east, yaw]`` with yaw in (−π, π]."""
    q = msg.pose.orientation
    yaw = quaternion_to_yaw(q.w, q.x, q.y, q.z)
    pose = np.array([msg.pose.position.x, msg.pose.position.y, yaw], dtype=np.float64)
    return _vector3(pose, 'pose')


def wrench_to_msg(
    force: ArrayLike, stamp: float | Time, frame_id: str = FRAME_BODY,
) -> WrenchStamped:
    """Force ``[surge N, sway N, yaw N·m]`` → ``WrenchStamped`` (force.x, force.y, torque.z)."""
    surge, sway, yaw_moment = _vector3(force, 'force')
    msg = WrenchStamped()
    msg.header.stamp = _as_stamp(stamp)
    msg.header.frame_id = frame_id
    msg.wrench.force.x = float(surge)
    msg.wrench.force.y = float(sway)
    msg.wrench.force.z = 0.0
    msg.wrench.torque.x = 0.0
    msg.wrench.torque.y = 0.0
    msg.wrench.torque.z = float(yaw_moment)
    return msg


def msg_to_force(msg: WrenchStamped) -> NDArray[np.float64]:
    """``WrenchStamped`` → force ``[surge N, sway N, yaw N·m]``."""
    wrench = msg.wrench
    force = np.array([wrench.force.x, wrench.force.y, wrench.torque.z], dtype=np.float64)
    return _vector3(force, 'force')
