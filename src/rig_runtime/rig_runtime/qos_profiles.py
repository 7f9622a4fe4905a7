"""The interface contract's QoS profiles (qos.py) as rclpy ``QoSProfile`` constants, for node
modules: ``self.create_publisher(..., STREAM_QOS)``. Imports rclpy (graph processes only).
"""

from rclpy.qos import QoSProfile

from .interface import Topic
from .qos import PROFILES, to_rclpy_qos

__all__ = [
    "DEFAULT_QOS",
    "EVENTS_QOS",
    "LATCHED_QOS",
    "QOS_BY_NAME",
    "SENSOR_QOS",
    "STREAM_QOS",
    "topic_qos",
]

QOS_BY_NAME: dict[str, QoSProfile] = {name: to_rclpy_qos(p) for name, p in PROFILES.items()}
DEFAULT_QOS = QOS_BY_NAME["default"]  # reliable, volatile, keep-last 10
SENSOR_QOS = QOS_BY_NAME["sensor"]  # best effort, volatile, keep-last 5
LATCHED_QOS = QOS_BY_NAME["latched"]  # reliable, transient-local, keep-last 1
STREAM_QOS = QOS_BY_NAME["stream"]  # reliable, volatile, keep-all
EVENTS_QOS = QOS_BY_NAME["events"]  # reliable, volatile, keep-last 1000


def topic_qos(topic: Topic) -> QoSProfile:
    """The profile the interface contract gives ``topic``."""
    return QOS_BY_NAME[topic.qos]
