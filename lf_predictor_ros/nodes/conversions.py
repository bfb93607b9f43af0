"""Conversions between the package's numpy conventions and ROS 2 messages.

A pose is ``[north m, east m, yaw rad]`` in ``map_ned``; a generalized force is
``[surge N, sway N, yaw N·m]`` in ``base_link_fsd`` (docs/ARCHITECTURE.md); a body velocity
(twist) is ``[surge u m/s, sway v m/s, yaw rate r rad/s]`` in ``base_link_fsd``. Heading ψ is the
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
from geometry_msgs.msg import Pose, PoseStamped, Twist, WrenchStamped
from nav_msgs.msg import Odometry
import numpy as np
from numpy.typing import ArrayLike, NDArray

from lf_predictor_ros.core.odometry import UNESTIMATED_VARIANCE  # one value for core and messages

FRAME_EARTH = 'map_ned'
FRAME_BODY = 'base_link_fsd'

NS_PER_S = 1_000_000_000  # [ns/s]
MAX_STAMP_SEC = 2**31 - 1  # [s] builtin_interfaces/Time.sec is int32

# nav_msgs/Odometry covariances are 6×6 row-major over (x, y, z, roll, pitch, yaw) (REP 103
# order; for the twist: linear x, y, z, angular x, y, z). A 3-DOF estimate fills rows/columns
# ODOM_DOF_INDEX = (x, y, yaw); the DOFs it does not estimate (z, roll, pitch) get the variance
# UNESTIMATED_VARIANCE on the diagonal (and 0 off it): a variance so large (a standard deviation
# of 1000 m, rad, m/s or rad/s) that a consumer fusing the message gives these DOFs no weight, and
# none is mistaken for a measured zero.
ODOM_DOF_INDEX = (0, 1, 5)
# The 6×6 layout of `covariance3_to_6` without the 3×3 block, and where the block's entries go in
# its 36 row-major values (read-only).
_COVARIANCE6_TEMPLATE = np.diag([0.0, 0.0, UNESTIMATED_VARIANCE, UNESTIMATED_VARIANCE,
                                 UNESTIMATED_VARIANCE, 0.0]).reshape(-1)
_COVARIANCE6_TEMPLATE.setflags(write=False)
_COVARIANCE6_BLOCK = np.array([6 * row + column for row in ODOM_DOF_INDEX
                               for column in ODOM_DOF_INDEX])


def _vector3(values: ArrayLike, what: str) -> NDArray[np.float64]:
    """Return ``values`` as a finite float array of shape (3,), or raise ValueError."""
    array = np.asarray(values, dtype=np.float64)
    if array.shape != (3,):
        raise ValueError(
            f'{what} must have shape (3,) ([north, east, yaw] or [surge, sway, yaw]), '
            f'got shape {array.shape}; pass one sample, not a series')
    if not all(map(math.isfinite, array.tolist())):  # np.all(np.isfinite(...)), per sample
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
    if isinstance(sec, float):  # the same exact rounding in integers, without Fraction's cost
        numerator, denominator = sec.as_integer_ratio()
        ns, remainder = divmod(numerator * NS_PER_S, denominator)
        twice = 2 * remainder  # round half to even, as round(Fraction)
        return ns + 1 if twice > denominator or (twice == denominator and ns % 2) else ns
    return round(Fraction(sec) * NS_PER_S)


def sec_to_stamp(sec: float) -> Time:
    """Seconds (float, ≥ 0) → ``builtin_interfaces/Time`` with exact integer nanoseconds."""
    return ns_to_stamp(sec_to_ns(sec))


def stamp_to_ns(stamp: Time) -> int:
    """``builtin_interfaces/Time`` → integer nanoseconds."""
    return sec_nanosec_to_ns(stamp.sec, stamp.nanosec)


def sec_nanosec_to_ns(sec: int, nanosec: int) -> int:
    """A stamp's ``sec`` and ``nanosec`` fields → integer nanoseconds."""
    return int(sec) * NS_PER_S + int(nanosec)


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
    msg = PoseStamped()
    msg.header.stamp = _as_stamp(stamp)
    msg.header.frame_id = frame_id
    _fill_pose(msg.pose, _vector3(pose, 'pose'))
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


def _fill_pose(target: Pose, pose: NDArray[np.float64]) -> None:
    """Write ``[north, east, yaw]`` into a ``geometry_msgs/Pose`` (z = 0, yaw quaternion)."""
    x, y, z, qx, qy, qz, qw = pose_fields(pose)
    position, orientation = target.position, target.orientation  # one property read each
    position.x = x
    position.y = y
    position.z = z
    orientation.w = qw
    orientation.x = qx
    orientation.y = qy
    orientation.z = qz


def pose_fields(pose: NDArray[np.float64]) -> tuple[float, float, float, float, float, float,
                                                    float]:
    """A checked pose ``[north, east, yaw]`` as the Pose's position x y z, orientation x y z w."""
    north, east, yaw = pose.tolist()
    return north, east, 0.0, 0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)


def odometry_fields(pose: ArrayLike, pose_cov: ArrayLike, twist: ArrayLike,
                    twist_cov: ArrayLike) -> tuple[tuple[float, ...], list[float],
                                                   tuple[float, ...], list[float]]:
    """The numbers `odometry_to_msg` writes, checked as there (ValueError), in its order.

    Pose (7, as `pose_fields`), pose covariance (36), twist (linear x y z, angular x y z) and
    twist covariance (36).
    """
    pose_array = _vector3(pose, 'pose')
    twist_array = _vector3(twist, 'twist')
    pose_values = pose_fields(pose_array)
    pose_covariance = covariance3_to_6(pose_cov, 'pose_cov')
    surge, sway, yaw_rate = twist_array.tolist()
    return (pose_values, pose_covariance, (surge, sway, 0.0, 0.0, 0.0, yaw_rate),
            covariance3_to_6(twist_cov, 'twist_cov'))


def _pose_of(source: Pose) -> NDArray[np.float64]:
    """``geometry_msgs/Pose`` → ``[north, east, yaw]`` with yaw in (−π, π]."""
    q = source.orientation
    return pose_from_fields(source.position.x, source.position.y, q.w, q.x, q.y, q.z)


def pose_from_fields(x: float, y: float, qw: float, qx: float, qy: float,
                     qz: float) -> NDArray[np.float64]:
    """``[north, east, yaw]`` from a Pose's position x, y and orientation (as ``_pose_of``)."""
    yaw = quaternion_to_yaw(qw, qx, qy, qz)
    return _vector3(np.array([x, y, yaw], dtype=np.float64), 'pose')


def msg_to_pose(msg: PoseStamped) -> NDArray[np.float64]:
    """``PoseStamped`` → pose ``[north, east, yaw]`` with yaw in (−π, π]."""
    return _pose_of(msg.pose)


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
    return force_from_fields(wrench.force.x, wrench.force.y, wrench.torque.z)


def force_from_fields(surge: float, sway: float, yaw_moment: float) -> NDArray[np.float64]:
    """Force ``[surge N, sway N, yaw N·m]`` from a Wrench's force.x, force.y, torque.z."""
    return _vector3(np.array([surge, sway, yaw_moment], dtype=np.float64), 'force')


def _covariance3(values: ArrayLike, what: str) -> NDArray[np.float64]:
    """Return ``values`` as a finite (3, 3) float array with a non-negative diagonal."""
    array = np.asarray(values, dtype=np.float64)
    if array.shape != (3, 3):
        raise ValueError(
            f'{what} must have shape (3, 3) over (x, y, yaw) or (u, v, r), got shape '
            f'{array.shape}; pass the 3-DOF block, the 6×6 message layout is built here')
    entries = array.ravel().tolist()
    if not all(map(math.isfinite, entries)):
        raise ValueError(f'{what} must be finite, got {array.tolist()}; publish a large '
                         f'variance (e.g. {UNESTIMATED_VARIANCE:g}) for a DOF you cannot trust')
    if entries[0] < 0.0 or entries[4] < 0.0 or entries[8] < 0.0:
        raise ValueError(f'{what} must have variances >= 0 on its diagonal, got '
                         f'{np.diag(array).tolist()}; check the sign of the covariance')
    return array


def covariance3_to_6(covariance: ArrayLike, what: str = 'covariance') -> list[float]:
    """3×3 covariance over (x, y, yaw) → 36 row-major values over (x, y, z, roll, pitch, yaw).

    The 3×3 goes to rows/columns `ODOM_DOF_INDEX` = (0, 1, 5); z, roll and pitch get
    `UNESTIMATED_VARIANCE` on the diagonal, every other entry is 0.
    """
    block = _covariance3(covariance, what)
    full = _COVARIANCE6_TEMPLATE.copy()
    full[_COVARIANCE6_BLOCK] = block.reshape(-1)
    values: list[float] = full.tolist()
    return values


def covariance6_to_3(values: ArrayLike, what: str = 'covariance') -> NDArray[np.float64]:
    """36 row-major values over (x, y, z, roll, pitch, yaw) → the (x, y, yaw) 3×3 block."""
    array = np.asarray(values, dtype=np.float64)
    if array.shape != (36,):
        raise ValueError(f'{what} must hold 36 values (6×6 row-major), got shape '
                         f'{array.shape}')
    block = array.reshape(6, 6)[np.ix_(ODOM_DOF_INDEX, ODOM_DOF_INDEX)]
    return _covariance3(block, what).copy()


def odometry_to_msg(
    stamp_sec: float | Time, pose: ArrayLike, pose_cov: ArrayLike, twist: ArrayLike,
    twist_cov: ArrayLike, frame_id: str = FRAME_EARTH, child_frame_id: str = FRAME_BODY,
) -> Odometry:
    """3-DOF estimate → ``nav_msgs/Odometry`` (the ``lf_odom`` layout, interfaces.md).

    ``stamp_sec``: seconds (float) or a ``builtin_interfaces/Time`` (copied exactly). ``pose``
    ``[north m, east m, yaw rad]`` in ``frame_id`` → position x, y (z = 0) and the yaw quaternion
    (w = cos ψ/2, z = sin ψ/2); ``twist`` ``[u m/s, v m/s, r rad/s]`` in ``child_frame_id`` →
    twist.linear.x, linear.y, angular.z (the rest 0). ``pose_cov`` and ``twist_cov`` (3, 3) go to
    rows/columns (0, 1, 5) of the 6×6 covariances (`covariance3_to_6`). Raises ValueError on a
    wrong shape, a non-finite value or a negative variance.
    """
    pose_array = _vector3(pose, 'pose')
    twist_array = _vector3(twist, 'twist')
    msg = Odometry()
    header, pose_part, twist_part = msg.header, msg.pose, msg.twist  # one property read each
    header.stamp = _as_stamp(stamp_sec)
    header.frame_id = frame_id
    msg.child_frame_id = child_frame_id
    _fill_pose(pose_part.pose, pose_array)
    pose_part.covariance = covariance3_to_6(pose_cov, 'pose_cov')
    surge, sway, yaw_rate = twist_array.tolist()
    linear, angular = twist_part.twist.linear, twist_part.twist.angular
    linear.x = surge
    linear.y = sway
    linear.z = 0.0
    angular.x = 0.0
    angular.y = 0.0
    angular.z = yaw_rate
    twist_part.covariance = covariance3_to_6(twist_cov, 'twist_cov')
    return msg


def _twist_of(source: Twist) -> NDArray[np.float64]:
    """``geometry_msgs/Twist`` → ``[u, v, r]`` (linear.x, linear.y, angular.z)."""
    twist = np.array([source.linear.x, source.linear.y, source.angular.z], dtype=np.float64)
    return _vector3(twist, 'twist')


def odometry_pose_from_msg(msg: Odometry) -> NDArray[np.float64]:
    """The pose ``[north, east, yaw]`` of an ``Odometry`` (yaw in (−π, π]); ValueError if bad."""
    return _pose_of(msg.pose.pose)


def odometry_twist_from_msg(msg: Odometry) -> NDArray[np.float64]:
    """The body twist ``[u, v, r]`` of an ``Odometry``; ValueError if not finite.

    The frame is not checked here: the caller compares ``msg.child_frame_id`` with the body
    frame it expects.
    """
    return _twist_of(msg.twist.twist)


def odometry_from_msg(msg: Odometry) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                               NDArray[np.float64], NDArray[np.float64]]:
    """``nav_msgs/Odometry`` → (pose (3,), pose_cov (3, 3), twist (3,), twist_cov (3, 3)).

    The inverse of `odometry_to_msg`: yaw from the quaternion in (−π, π], the covariances' (x, y,
    yaw) blocks (rows/columns 0, 1, 5). Raises ValueError on a non-finite value, a zero
    quaternion or a negative variance. Frame ids are not checked (see `odometry_twist_from_msg`).
    """
    return (odometry_pose_from_msg(msg),
            covariance6_to_3(msg.pose.covariance, 'pose covariance'),
            odometry_twist_from_msg(msg),
            covariance6_to_3(msg.twist.covariance, 'twist covariance'))
