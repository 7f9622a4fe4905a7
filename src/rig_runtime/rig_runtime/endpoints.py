"""The runtime's typed endpoints: rclpy publishers and ``raw=True`` subscriptions that send and
take the serialized CDR of the runtime's messages (rosbags dataclasses with numpy sequences,
messages.py), counting what passes for the flow report (flow.py) and the start barrier.

rclpy's message conversion is skipped where it costs the most (bench/transport.py measures it).
"""

from dataclasses import dataclass
from typing import Any

from . import ros_environment
from .barrier import Endpoint
from .messages import (
    cdr_stamp_ns,
    normalize_type_name,
    serialize,
    stamp_to_ns,
    starts_with_header,
)
from .qos import QosProfile, from_rclpy_qos

__all__ = [
    "CdrEndpoint",
    "CdrPublisher",
    "CdrSubscription",
    "MessagePublisher",
    "MessageSubscription",
    "endpoint_record",
    "message_class",
    "offered_topics",
    "type_name_of",
]

PROFILE_BLOCKING_S = 60  # the writers' max_blocking_time in fastdds_profiles.xml


def message_class(type_name: str) -> Any:
    """The generated rclpy message class of a ROS type name (``sensor_msgs/msg/JointState``),
    imported from its package as ``from sensor_msgs.msg import JointState`` would."""
    import importlib

    pkg, kind, name = normalize_type_name(type_name).split("/")
    try:
        return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    except (ImportError, AttributeError) as exc:
        raise ImportError(
            f"no Python package for {type_name} ({pkg}): {ros_environment.INSTALL_RCLPY} ({exc})"
        ) from exc


def type_name_of(msg_class: type) -> str:
    """The ROS type name of a generated rclpy message class (``sensor_msgs/msg/JointState``
    for ``sensor_msgs.msg.JointState``: its module is ``sensor_msgs.msg._joint_state``)."""
    pkg, kind = msg_class.__module__.split(".")[:2]
    return f"{pkg}/{kind}/{msg_class.__name__}"


@dataclass(eq=False)
class CdrEndpoint:
    """What a reader or writer of the runtime's messages is: its rclpy entity (``handle``),
    resolved topic, ROS type name and QoS profile."""

    handle: Any  # rclpy.publisher.Publisher | rclpy.subscription.Subscription
    topic: str
    type_name: str
    profile: QosProfile
    # Its flow (flow.py): messages passed, and the last one's CDR bytes (its stamp is read only
    # when the flow is reported, not per message).
    count: int = 0
    last: bytes | None = None
    last_message: Any = None  # an endpoint of rclpy messages: the last one

    def __post_init__(self) -> None:
        # A reliable keep-all endpoint of stamped messages: its flow is reported.
        self.streams = (
            self.profile.keep_all
            and self.profile.reliability == "reliable"
            and starts_with_header(self.type_name)
        )

    def passed(self, data: bytes) -> None:
        """Count a message (its CDR bytes) through this endpoint."""
        self.count += 1
        self.last = data

    @property
    def stamp_ns(self) -> int:
        """The header stamp of the last stream message passed (0: none, or not a stream)."""
        if not self.streams:
            return 0
        if self.last_message is not None:  # an endpoint of rclpy messages
            return stamp_to_ns(self.last_message.header.stamp)
        return cdr_stamp_ns(self.last) if self.last is not None else 0


class CdrPublisher(CdrEndpoint):
    """An rclpy publisher of the runtime's messages: ``publish(msg)`` sends their CDR bytes."""

    def publish(self, msg: Any) -> None:
        self.publish_raw(serialize(msg))

    def publish_raw(self, data: bytes) -> None:
        try:
            self.handle.publish(bytes(data))
        except Exception as exc:  # rclpy's RCLError: say which writer and why it gave up
            raise RuntimeError(
                f"publishing on {self.topic} failed: a reader has not acknowledged for "
                f"{PROFILE_BLOCKING_S} s (Fast DDS's max_blocking_time), or it is gone: {exc}"
            ) from exc
        self.passed(data)

    def subscription_count(self) -> int:
        return int(self.handle.get_subscription_count())

    def matched_count(self) -> int:
        return self.subscription_count()


class CdrSubscription(CdrEndpoint):
    """An rclpy ``raw=True`` subscription delivering runtime messages (or the bytes)."""

    polled_at: int = -1  # its count at the last flow report (FlowReport.take_undelivered)
    undelivered: int = 0  # samples the flow report found held undelivered and took

    def publisher_count(self) -> int:
        return int(self.handle.get_publisher_count())

    def matched_count(self) -> int:
        return self.publisher_count()


class MessagePublisher(CdrPublisher):
    """An rclpy publisher of rclpy messages (a node's events, status and diagnostics, where
    rclpy's conversion costs nothing that matters), counted and reported like the CDR ones."""

    def publish(self, msg: Any) -> None:
        try:
            self.handle.publish(msg)
        except Exception as exc:  # as CdrPublisher.publish_raw
            raise RuntimeError(f"publishing on {self.topic} failed: {exc}") from exc
        self.count += 1
        self.last_message = msg

    def publish_raw(self, data: bytes) -> None:
        raise TypeError(f"{self.topic}: a publisher of rclpy messages takes messages, not CDR")


class MessageSubscription(CdrSubscription):
    """An rclpy subscription delivering rclpy messages, counted and reported like the CDR
    ones."""

    def took(self, msg: Any) -> None:
        self.count += 1
        self.last_message = msg


def endpoint_record(entity: CdrEndpoint, kind: str, gid: str, count: int) -> Endpoint:
    """The start barrier's record of an endpoint (barrier.py)."""
    return Endpoint(
        topic=entity.topic,
        kind=kind,
        gid=gid,
        reliable=entity.profile.reliability == "reliable",
        transient_local=entity.profile.durability == "transient_local",
        matched_count=count,
    )


def offered_topics(node: Any) -> dict[str, tuple[str, QosProfile | None]]:
    """The topics of the rclpy ``node``'s graph with at least one publisher: name -> (type
    name, QoS offered by the first). A topic known only from its readers has no offered QoS
    yet, and a recorder that guessed one could ask for reliable from a best-effort writer and
    never be matched."""
    result: dict[str, tuple[str, QosProfile | None]] = {}
    for name, types in node.get_topic_names_and_types():
        for info in node.get_publishers_info_by_topic(name):
            result[name] = (types[0], from_rclpy_qos(info.qos_profile))
            break
    return result
