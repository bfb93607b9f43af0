"""QoS profiles of the interface contract (shared/reference/interfaces.md, "QoS").

- Publishers: reliable, keep_last 10. A reliable writer matches both reliable and best-effort
  readers, so every subscriber (a DP stack, ``ros2 topic echo``, rosbag2) receives our data.
- Subscribers to measurements and estimates (poses, applied thrust): the sensor-data profile
  (best effort, keep_last 5, volatile). A best-effort reader matches any writer, including a bag
  player or a sensor driver that publishes best effort.
- Subscribers to commands (``thrust_command``): reliable, keep_last 10. A command must not be
  dropped silently; lockstep simulation counts on every command arriving. A best-effort command
  publisher does not match: publish commands reliably (every node in this package does).

Functions return a fresh profile each call so that no caller can mutate a shared one.
"""
from __future__ import annotations

from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)

PUBLISHER_DEPTH = 10  # [messages] keep_last depth of every publisher (interfaces.md)
COMMAND_DEPTH = 10  # [messages] keep_last depth of command subscribers


def _profile(
    reliability: ReliabilityPolicy, depth: int, durability: DurabilityPolicy,
) -> QoSProfile:
    """A keep_last profile (QoSProfile's constructor takes untyped **kwargs)."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=reliability,
        durability=durability)


def publisher_qos() -> QoSProfile:
    """Profile of every publisher: reliable, keep_last 10, volatile."""
    return _profile(ReliabilityPolicy.RELIABLE, PUBLISHER_DEPTH, DurabilityPolicy.VOLATILE)


def sensor_qos() -> QoSProfile:
    """Profile of measurement subscribers: ROS 2 sensor data (best effort, keep_last 5)."""
    sensor = qos_profile_sensor_data
    return _profile(sensor.reliability, sensor.depth, sensor.durability)


def command_qos() -> QoSProfile:
    """Profile of command subscribers: reliable, keep_last 10, volatile."""
    return _profile(ReliabilityPolicy.RELIABLE, COMMAND_DEPTH, DurabilityPolicy.VOLATILE)
