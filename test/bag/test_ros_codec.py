"""ros_codec: message classes, CDR round trip, QoS <-> rosbag2 YAML."""
# rclpy and mcap are partly untyped.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

from geometry_msgs.msg import PoseStamped
import pytest
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosbags.rosbag2.metadata import parse_qos

from lf_predictor_ros.bag.ros_codec import (
    deserialize,
    message_class,
    offered_qos_yaml,
    qos_from_yaml,
    serialize,
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
