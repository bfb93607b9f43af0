"""ros_codec: message classes, CDR round trip, QoS <-> rosbag2 YAML."""
# rclpy and mcap are partly untyped.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

import math

from geometry_msgs.msg import PoseStamped, WrenchStamped
import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosbags.rosbag2.metadata import parse_qos

from lf_predictor_ros.bag import ros_codec
from lf_predictor_ros.bag.ros_codec import (
    deserialize,
    message_class,
    offered_qos_yaml,
    qos_from_yaml,
    serialize,
    stamped_fields,
    type_name_of,
)

pytestmark = pytest.mark.filterwarnings('ignore::DeprecationWarning:lark.*')


def test_message_class_and_type_name() -> None:
    assert message_class('geometry_msgs/msg/PoseStamped') is PoseStamped
    assert type_name_of(PoseStamped()) == 'geometry_msgs/msg/PoseStamped'
    with pytest.raises(ValueError, match='not importable as nope_msgs.msg.Thing'):
        message_class('nope_msgs/msg/Thing')


def test_cdr_round_trip() -> None:
    pose = PoseStamped()
    pose.header.frame_id = 'map_ned'
    pose.pose.position.x = -12.5
    data = serialize(pose)
    assert isinstance(data, bytes) and len(data) == 84  # 4 encapsulation + 80 payload
    assert deserialize(data, 'geometry_msgs/msg/PoseStamped') == pose


def test_qos_round_trip_through_rosbag2_yaml() -> None:
    offered = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5,
                         reliability=ReliabilityPolicy.BEST_EFFORT,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    text = offered_qos_yaml([offered])
    (parsed,) = parse_qos(text)  # rosbags' reading of the same text
    assert (parsed.reliability.name, parsed.durability.name, parsed.depth) == (
        'BEST_EFFORT', 'TRANSIENT_LOCAL', 5)
    replay = qos_from_yaml(text)
    assert replay.reliability == ReliabilityPolicy.BEST_EFFORT
    assert replay.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert replay.depth == 10
    default = qos_from_yaml('')
    assert (default.reliability, default.durability, default.depth) == (
        ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE, 10)


@pytest.mark.parametrize('frame_id',
                         ['', 'a', 'map_ned', 'base_link_fsd', 'ab_cdefgh', 'nöt ascii'])
def test_stamped_fields_reads_the_numbers_deserialize_reads(frame_id: str) -> None:
    # The direct CDR read (ASCII frame ids) and the deserialize fallback give the same bits.
    pose = PoseStamped()
    pose.header.stamp.sec, pose.header.stamp.nanosec = -3, 999_999_999
    pose.header.frame_id = frame_id
    pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = 1e-300, -2.5, math.nan
    q = pose.pose.orientation
    q.x, q.y, q.z, q.w = 0.1, -0.0, math.inf, 0.3
    data = serialize(pose)
    fields = stamped_fields(data, 'geometry_msgs/msg/PoseStamped')
    direct = ros_codec._unpack_stamped(data, ros_codec._BODIES['geometry_msgs/msg/PoseStamped'])
    assert (direct is None) == (not frame_id.isascii())
    assert (fields.sec, fields.nanosec) == (-3, 999_999_999)
    assert [v.hex() for v in fields.values] == [
        v.hex() for v in (1e-300, -2.5, math.nan, 0.1, -0.0, math.inf, 0.3)]
    wrench = WrenchStamped()
    wrench.header.stamp.sec = 7
    wrench.header.frame_id = frame_id
    wrench.wrench.force.x, wrench.wrench.torque.z = 3.25, -1e5
    fields = stamped_fields(serialize(wrench), 'geometry_msgs/msg/WrenchStamped')
    assert (fields.sec, fields.nanosec) == (7, 0)
    assert fields.values == (3.25, 0.0, 0.0, 0.0, 0.0, -1e5)


def test_stamped_fields_of_a_truncated_message_raises() -> None:
    data = serialize(PoseStamped())
    with pytest.raises(Exception):  # noqa: B017, PT011 - rclpy raises plain exceptions
        stamped_fields(data[:-8], 'geometry_msgs/msg/PoseStamped')


@pytest.mark.parametrize('frame_id', ['', 'map_ned', 'abc'])
def test_direct_cdr_writers_decode_to_the_messages_of_the_converters(frame_id: str) -> None:
    # replay writes its estimates with these: rclpy must read back the converters' messages.
    from std_msgs.msg import Float64

    from lf_predictor_ros.nodes.conversions import (
        odometry_fields,
        odometry_to_msg,
        pose_fields,
        pose_to_msg,
        sec_to_stamp,
    )

    pose, twist = np.array([3.5, -2.25, -3.1]), np.array([0.5, -0.125, 0.01])
    pose_cov = np.diag([0.25, 0.5, 0.001])
    pose_cov[0, 1] = pose_cov[1, 0] = -1e-3
    twist_cov = np.diag([0.4, 0.4, 1e-4])
    stamp = sec_to_stamp(123.4)
    text = ros_codec.cdr_text(frame_id)
    assert text is not None
    data = ros_codec.pose_stamped_cdr(stamp.sec, stamp.nanosec, text, pose_fields(pose))
    expected = serialize(pose_to_msg(pose, stamp, frame_id))
    assert len(data) == len(expected)
    assert deserialize(data, 'geometry_msgs/msg/PoseStamped') == pose_to_msg(pose, stamp,
                                                                             frame_id)
    child = ros_codec.cdr_text('base_link_fsd')
    assert child is not None
    data = ros_codec.odometry_cdr(stamp.sec, stamp.nanosec, text, child,
                                  *odometry_fields(pose, pose_cov, twist, twist_cov))
    message = odometry_to_msg(stamp, pose, pose_cov, twist, twist_cov, frame_id,
                              'base_link_fsd')
    assert len(data) == len(serialize(message))
    assert deserialize(data, 'nav_msgs/msg/Odometry') == message
    assert ros_codec.float64_cdr(0.8125) == serialize(Float64(data=0.8125))
    for value in (math.nan, math.inf, -math.inf):  # rclpy takes these too, with the same bytes
        assert ros_codec.float64_cdr(value) == serialize(Float64(data=value))
    assert ros_codec.cdr_text('nörd') is None and ros_codec.cdr_text('a\0b') is None


@pytest.mark.parametrize('frame_id', ['map_ned', 'nörd'])  # direct writers / rclpy's encoder
def test_estimate_cdr_decodes_to_the_converters_messages(frame_id: str) -> None:
    # the predictor node publishes these bytes and replay writes them: both must read back as
    # pose_to_msg's and odometry_to_msg's messages.
    from lf_predictor_ros.nodes.conversions import odometry_to_msg, pose_to_msg, sec_to_stamp

    pose, twist = np.array([-12.5, 7.25, 3.0]), np.array([0.25, -0.5, -0.02])
    pose_cov = np.diag([0.3, 0.2, 0.002])
    pose_cov[0, 2] = pose_cov[2, 0] = 1e-4
    twist_cov = np.diag([0.1, 0.2, 1e-5])
    stamp = sec_to_stamp(86_400.25)
    lf_data, odom_data = ros_codec.estimate_cdr(stamp, frame_id, 'base_link_fsd', pose,
                                                pose_cov, twist, twist_cov)
    pose_msg = pose_to_msg(pose, stamp, frame_id)
    odom_msg = odometry_to_msg(stamp, pose, pose_cov, twist, twist_cov, frame_id,
                               'base_link_fsd')
    assert len(lf_data) == len(serialize(pose_msg))
    assert len(odom_data) == len(serialize(odom_msg))
    assert deserialize(lf_data, 'geometry_msgs/msg/PoseStamped') == pose_msg
    assert deserialize(odom_data, 'nav_msgs/msg/Odometry') == odom_msg
    assert deserialize(odom_data, 'nav_msgs/msg/Odometry').pose.pose.position.x == -12.5


def test_estimate_cdr_refuses_what_odometry_to_msg_refuses() -> None:
    from lf_predictor_ros.nodes.conversions import sec_to_stamp

    stamp, cov = sec_to_stamp(1.0), np.eye(3)
    with pytest.raises(ValueError, match='pose must be finite'):
        ros_codec.estimate_cdr(stamp, 'map_ned', 'base_link_fsd', [0.0, math.nan, 0.0], cov,
                               np.zeros(3), cov)
    with pytest.raises(ValueError, match='twist must have shape'):
        ros_codec.estimate_cdr(stamp, 'map_ned', 'base_link_fsd', np.zeros(3), cov,
                               np.zeros(2), cov)


def test_diagnostic_array_cdr_decodes_to_make_diagnostic_array() -> None:
    from builtin_interfaces.msg import Time

    from lf_predictor_ros.nodes.diagnostics import make_diagnostic_array, status_fields

    stamp = Time(sec=360, nanosec=100_000_000)
    for values in ({}, {'state': 'trained', 'wave_peak_freq': 0.8001, 'ok': True, 'n': 3,
                        'note': 'ω0 from the fit', 'x': math.nan}):
        for level, message in (('OK', 'trained: loss 0.0057, ω0 0.800'), ('ERROR', ''),
                               ('WARN', 'a')):
            fields = status_fields('replay: lf predictor', level, message, values)
            data = ros_codec.diagnostic_array_cdr(stamp.sec, stamp.nanosec, '', [fields])
            assert data is not None
            expected = make_diagnostic_array('replay: lf predictor', level, message, values,
                                             stamp=stamp)
            assert len(data) == len(serialize(expected))
            assert deserialize(data, 'diagnostic_msgs/msg/DiagnosticArray') == expected
    nul = status_fields('a', 'OK', 'b\0c')
    assert ros_codec.diagnostic_array_cdr(0, 0, '', [nul]) is None
