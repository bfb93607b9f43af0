"""Message conversions (pose, wrench, exact stamps), QoS profiles and diagnostics, in numbers."""
from __future__ import annotations

import math

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
import pytest
from rclpy.qos import ReliabilityPolicy

from lf_predictor_ros.nodes import conversions as cv
from lf_predictor_ros.nodes import diagnostics, qos


@pytest.mark.parametrize('yaw', [0.0, 0.3, -2.0, math.pi - 1e-9, -math.pi + 1e-9, math.pi,
                                 3.0, -3.1, 1e-12])
def test_pose_round_trip_keeps_yaw_across_pi(yaw: float) -> None:
    pose = np.array([1234.5, -67.25, yaw])
    back = cv.msg_to_pose(cv.pose_to_msg(pose, 10.0))
    assert back[:2] == pytest.approx(pose[:2], abs=1e-12)
    # compare on the circle: the difference of two angles across ±π is ~2π, not ~0
    assert abs(math.remainder(back[2] - yaw, 2 * math.pi)) < 1e-12
    assert -math.pi < back[2] <= math.pi


def test_pose_quaternion_is_rotation_about_down_axis() -> None:
    msg = cv.pose_to_msg([0.0, 0.0, math.pi / 2], 0.0)
    q = msg.pose.orientation
    assert (q.w, q.x, q.y, q.z) == pytest.approx((math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)))
    assert msg.header.frame_id == 'map_ned'
    assert msg.pose.position.z == 0.0


def test_yaw_out_of_range_is_wrapped_on_the_way_back() -> None:
    back = cv.msg_to_pose(cv.pose_to_msg([0.0, 0.0, 2 * math.pi + 0.5], 0.0))
    assert back[2] == pytest.approx(0.5, abs=1e-12)
    assert cv.msg_to_pose(cv.pose_to_msg([0.0, 0.0, -math.pi], 0.0))[2] == pytest.approx(math.pi)


def test_yaw_from_non_unit_quaternion_with_small_roll_pitch() -> None:
    yaw = 2.5
    msg = cv.pose_to_msg([0.0, 0.0, 0.0], 0.0)
    # scale 3.7 and a 1e-6 rad roll/pitch perturbation: yaw must survive to ~1e-6
    scale = 3.7
    q = msg.pose.orientation
    q.w, q.z = scale * math.cos(yaw / 2), scale * math.sin(yaw / 2)
    q.x, q.y = scale * 5e-7, scale * -5e-7
    assert cv.msg_to_pose(msg)[2] == pytest.approx(yaw, abs=2e-6)
    q.x = q.y = 0.0
    assert cv.msg_to_pose(msg)[2] == pytest.approx(yaw, abs=1e-14)


def test_zero_quaternion_is_rejected() -> None:
    msg = cv.pose_to_msg([0.0, 0.0, 0.0], 0.0)
    msg.pose.orientation.w = 0.0
    with pytest.raises(ValueError, match='non-zero'):
        cv.msg_to_pose(msg)


def test_pose_shape_and_finiteness_are_checked() -> None:
    with pytest.raises(ValueError, match=r'shape \(3,\)'):
        cv.pose_to_msg(np.zeros((2, 3)), 0.0)
    with pytest.raises(ValueError, match='finite'):
        cv.pose_to_msg([0.0, math.nan, 0.0], 0.0)


def test_wrench_round_trip_and_frame() -> None:
    force = np.array([1.5e5, -2.25e4, 3.125e7])
    msg = cv.wrench_to_msg(force, 2.5)
    assert msg.header.frame_id == 'base_link_fsd'
    assert (msg.wrench.force.x, msg.wrench.force.y, msg.wrench.torque.z) == tuple(force)
    assert msg.wrench.force.z == msg.wrench.torque.x == msg.wrench.torque.y == 0.0
    np.testing.assert_array_equal(cv.msg_to_force(msg), force)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (2, 500_000_000)


def test_input_array_is_not_modified() -> None:
    pose = np.array([1.0, 2.0, 4.0])
    cv.pose_to_msg(pose, 0.0)
    np.testing.assert_array_equal(pose, [1.0, 2.0, 4.0])


@pytest.mark.parametrize(('sec', 'expected'), [
    (0.0, (0, 0)),
    (0.1, (0, 100_000_000)),
    (1e6 + 0.1, (1_000_000, 100_000_000)),
    (1_700_000_000.25, (1_700_000_000, 250_000_000)),
    (123456.999999999, (123456, 999_999_999)),
    (5.9999999999, (6, 0)),  # rounds to the next second: carry into sec
])
def test_sec_to_stamp_is_the_nearest_nanosecond(sec: float, expected: tuple[int, int]) -> None:
    stamp = cv.sec_to_stamp(sec)
    assert (stamp.sec, stamp.nanosec) == expected


def test_stamps_do_not_drift_over_many_samples() -> None:
    # 10 Hz for 30 simulated days: step k is k * 0.1 s; float scaling k * 0.1 * 1e9 would drift
    for k in (1, 3, 7, 25_920_000, 25_920_001, 25_919_999):
        stamp = cv.sec_to_stamp(k * 0.1)
        assert cv.stamp_to_ns(stamp) == k * 100_000_000


def test_stamp_round_trip_is_exact_below_two_to_the_22_seconds() -> None:
    # below 2**22 s (48 days) a float resolves 2**-30 s < 1 ns, so stamp -> sec -> stamp is exact
    rng = np.random.default_rng(7)
    for _ in range(2000):
        ns = int(rng.integers(0, 2**22 * 10**9))
        stamp = cv.ns_to_stamp(ns)
        assert cv.stamp_to_ns(cv.sec_to_stamp(cv.stamp_to_sec(stamp))) == ns


def test_stamp_to_sec_is_correctly_rounded() -> None:
    stamp = Time(sec=1_700_000_000, nanosec=123_456_789)
    assert cv.stamp_to_sec(stamp) == 1_700_000_000_123_456_789 / 10**9
    assert cv.stamp_to_sec(Time(sec=3, nanosec=1)) == 3.000000001


def test_negative_and_out_of_range_stamps_are_rejected() -> None:
    with pytest.raises(ValueError, match='negative'):
        cv.sec_to_stamp(-1e-9)
    with pytest.raises(ValueError, match='negative'):
        cv.ns_to_stamp(-1)
    with pytest.raises(ValueError, match='finite'):
        cv.sec_to_stamp(math.inf)
    with pytest.raises(ValueError, match='int32'):
        cv.sec_to_stamp(2.0**31)


def test_time_message_stamp_is_copied_exactly() -> None:
    stamp = Time(sec=42, nanosec=999_999_999)
    msg = cv.pose_to_msg([0.0, 0.0, 0.0], stamp)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (42, 999_999_999)
    assert msg.header.stamp is not stamp


def test_qos_profiles_follow_the_contract() -> None:
    pub = qos.publisher_qos()
    assert (pub.reliability, pub.depth) == (ReliabilityPolicy.RELIABLE, 10)
    sensor = qos.sensor_qos()
    assert sensor.reliability == ReliabilityPolicy.BEST_EFFORT
    assert qos.command_qos().reliability == ReliabilityPolicy.RELIABLE
    pub.depth = 1
    assert qos.publisher_qos().depth == 10


def test_diagnostic_array_formats_values() -> None:
    array = diagnostics.make_diagnostic_array(
        'sim: state', 'warn', 'no command',
        {'wave_peak_freq': 0.78539816339, 'steps': 12, 'missing': True, 'loss': math.nan,
         'tiny': 1.25e-7, 'mode': 'lockstep'},
        stamp=Time(sec=5, nanosec=7))
    (status,) = array.status
    assert status.level == DiagnosticStatus.WARN
    assert (status.name, status.message) == ('sim: state', 'no command')
    assert {kv.key: kv.value for kv in status.values} == {
        'wave_peak_freq': '0.785398', 'steps': '12', 'missing': 'true', 'loss': 'nan',
        'tiny': '1.25e-07', 'mode': 'lockstep'}
    assert (array.header.stamp.sec, array.header.stamp.nanosec) == (5, 7)
    assert diagnostics.level_byte(2) == DiagnosticStatus.ERROR
    with pytest.raises(ValueError, match='level'):
        diagnostics.level_byte('fatal')
    with pytest.raises(ValueError, match='level'):
        diagnostics.level_byte(4)


# ------------------------------------------------------------------------------ nav_msgs/Odometry
POSE_COV = np.array([[0.25, 0.01, 0.002], [0.01, 0.36, -0.003], [0.002, -0.003, 1e-4]])
TWIST_COV = np.array([[4e-4, 1e-5, 0.0], [1e-5, 9e-4, 2e-6], [0.0, 2e-6, 1e-6]])


def test_odometry_round_trip_is_exact() -> None:
    pose = np.array([1234.5, -67.25, 0.75])
    twist = np.array([0.125, -0.5, 0.0025])
    msg = cv.odometry_to_msg(Time(sec=42, nanosec=5), pose, POSE_COV, twist, TWIST_COV)
    assert (msg.header.frame_id, msg.child_frame_id) == ('map_ned', 'base_link_fsd')
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (42, 5)
    back_pose, back_pose_cov, back_twist, back_twist_cov = cv.odometry_from_msg(msg)
    assert back_pose[:2].tolist() == [1234.5, -67.25]
    assert back_pose[2] == pytest.approx(0.75, abs=1e-15)
    np.testing.assert_array_equal(back_twist, twist)
    np.testing.assert_array_equal(back_pose_cov, POSE_COV)
    np.testing.assert_array_equal(back_twist_cov, TWIST_COV)
    # twist components: linear x/y and angular z, the rest exactly 0
    t = msg.twist.twist
    assert (t.linear.x, t.linear.y, t.angular.z) == (0.125, -0.5, 0.0025)
    assert t.linear.z == t.angular.x == t.angular.y == 0.0
    assert msg.pose.pose.position.z == 0.0
    custom = cv.odometry_to_msg(3.5, pose, POSE_COV, twist, TWIST_COV, frame_id='odom',
                                child_frame_id='base_link')
    assert (custom.header.frame_id, custom.child_frame_id) == ('odom', 'base_link')
    assert (custom.header.stamp.sec, custom.header.stamp.nanosec) == (3, 500_000_000)


def test_odometry_covariance_index_placement() -> None:
    """3×3 over (x, y, yaw) → rows/cols 0, 1, 5 of the 6×6; z, roll, pitch: 1e6 on the diagonal."""
    pose_cov = np.arange(1.0, 10.0).reshape(3, 3)  # diagonal 1, 5, 9 >= 0
    msg = cv.odometry_to_msg(0.0, [0.0, 0.0, 0.0], pose_cov, [0.0, 0.0, 0.0], 2.0 * pose_cov)
    for covariance, scale in ((msg.pose.covariance, 1.0), (msg.twist.covariance, 2.0)):
        full = np.asarray(covariance).reshape(6, 6)
        expected = np.zeros((6, 6))
        for i, row in enumerate((0, 1, 5)):
            for j, col in enumerate((0, 1, 5)):
                expected[row, col] = scale * (3 * i + j + 1)
        expected[2, 2] = expected[3, 3] = expected[4, 4] = 1e6
        np.testing.assert_array_equal(full, expected)
    # row-major: flat index 6·row + col; (yaw, x) is index 30, (x, yaw) index 5
    assert msg.pose.covariance[5] == 3.0 and msg.pose.covariance[30] == 7.0
    assert msg.pose.covariance[35] == 9.0 and msg.pose.covariance[14] == cv.UNESTIMATED_VARIANCE


@pytest.mark.parametrize('yaw', [math.pi, -math.pi, math.pi - 1e-12, -math.pi + 1e-12])
def test_odometry_quaternion_of_plus_minus_180_degrees(yaw: float) -> None:
    msg = cv.odometry_to_msg(0.0, [0.0, 0.0, yaw], POSE_COV, [0.0, 0.0, 0.0], TWIST_COV)
    q = msg.pose.pose.orientation
    # ψ = ±π: w = cos(±π/2) ≈ 6e-17, z = sin(±π/2) = ±1 (q and −q are the same rotation)
    assert (q.x, q.y) == (0.0, 0.0)
    assert abs(q.w) < 1e-11 and abs(q.z) == pytest.approx(1.0, abs=1e-15)
    assert math.copysign(1.0, q.z) == math.copysign(1.0, yaw)
    back = cv.odometry_from_msg(msg)[0][2]
    assert -math.pi < back <= math.pi
    assert abs(math.remainder(back - yaw, 2 * math.pi)) < 1e-11
    if abs(yaw) == math.pi:
        assert back == math.pi  # −π comes back as +π: the range is (−π, π]


def test_odometry_bad_shapes_and_values_are_rejected() -> None:
    good = (0.0, [0.0, 0.0, 0.0], POSE_COV, [0.0, 0.0, 0.0], TWIST_COV)
    with pytest.raises(ValueError, match=r'pose must have shape \(3,\)'):
        cv.odometry_to_msg(0.0, [0.0, 0.0], POSE_COV, [0.0, 0.0, 0.0], TWIST_COV)
    with pytest.raises(ValueError, match=r'twist must have shape \(3,\)'):
        cv.odometry_to_msg(0.0, [0.0, 0.0, 0.0], POSE_COV, np.zeros(6), TWIST_COV)
    with pytest.raises(ValueError, match=r'pose_cov must have shape \(3, 3\)'):
        cv.odometry_to_msg(0.0, [0.0, 0.0, 0.0], np.eye(6), [0.0, 0.0, 0.0], TWIST_COV)
    with pytest.raises(ValueError, match=r'twist_cov must have shape \(3, 3\)'):
        cv.odometry_to_msg(0.0, [0.0, 0.0, 0.0], POSE_COV, [0.0, 0.0, 0.0], np.ones(9))
    with pytest.raises(ValueError, match='twist must be finite'):
        cv.odometry_to_msg(0.0, [0.0, 0.0, 0.0], POSE_COV, [math.nan, 0.0, 0.0], TWIST_COV)
    with pytest.raises(ValueError, match='pose_cov must be finite'):
        cv.odometry_to_msg(0.0, [0.0, 0.0, 0.0], np.full((3, 3), math.inf), [0.0, 0.0, 0.0],
                           TWIST_COV)
    with pytest.raises(ValueError, match='variances >= 0'):
        cv.odometry_to_msg(0.0, [0.0, 0.0, 0.0], -np.eye(3), [0.0, 0.0, 0.0], TWIST_COV)
    msg = cv.odometry_to_msg(*good)
    msg.twist.twist.angular.z = math.nan
    with pytest.raises(ValueError, match='twist must be finite'):
        cv.odometry_from_msg(msg)
    msg = cv.odometry_to_msg(*good)
    msg.pose.covariance[35] = math.nan
    with pytest.raises(ValueError, match='pose covariance must be finite'):
        cv.odometry_from_msg(msg)
    msg = cv.odometry_to_msg(*good)
    msg.pose.pose.orientation.w = 0.0
    msg.pose.pose.orientation.z = 0.0
    with pytest.raises(ValueError, match='non-zero'):
        cv.odometry_from_msg(msg)


def test_odometry_inputs_are_not_modified() -> None:
    pose, twist = np.array([1.0, 2.0, 4.0]), np.array([0.1, 0.2, 0.3])
    pose_cov, twist_cov = POSE_COV.copy(), TWIST_COV.copy()
    cv.odometry_to_msg(0.0, pose, pose_cov, twist, twist_cov)
    np.testing.assert_array_equal(pose, [1.0, 2.0, 4.0])
    np.testing.assert_array_equal(twist, [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(pose_cov, POSE_COV)
    np.testing.assert_array_equal(twist_cov, TWIST_COV)


def test_odometry_state_leads_the_diagnostics_and_names_the_reference_fault() -> None:
    from lf_predictor_ros.nodes.diagnostics import with_reference_and_odometry

    base = ('OK', 'trained: ok')
    ok = ('OK', '')
    assert with_reference_and_odometry(*base, ok, ok) == base
    assert with_reference_and_odometry(*base, ('WARN', 'frozen'), ok) == (
        'WARN', 'position reference frozen; trained: ok')
    # dead reckoning bridges the fault: WARN, the odometry leads and names the fault
    assert with_reference_and_odometry(*base, ('ERROR', 'jump'), ('WARN', 'dead_reckoning')) == (
        'WARN', 'dead_reckoning; position reference jump; trained: ok')
    assert with_reference_and_odometry('WARN', 'fallback: x', ok, ('ERROR', 'lost')) == (
        'ERROR', 'lost; fallback: x')
