"""rclpy backend: the same node API on a ROS 2 Jazzy machine.

Deliberately thin: names, parameters, QoS and message construction are done by the shared
runtime; this file maps them onto rclpy. It cannot run on the development machines (rclpy is
not on PyPI); the README's "Checking on a ROS 2 machine" section gives the commands that
exercise it (``RIG_RUNTIME_BACKEND=rclpy``).

Differences a node may see: primitive sequences of received messages are ``array.array``
rather than numpy arrays (``np.asarray(msg.position)`` works on both); anything assigned to
a sequence field may be a numpy array on both.
"""

from collections.abc import Callable
from typing import Any

import numpy as np

from .barrier import Endpoint
from .messages import normalize_type_name
from .qos import QosProfile


def _message_class(type_name: str) -> Any:
    from rosidl_runtime_py.utilities import get_message

    return get_message(normalize_type_name(type_name))


def _rclpy_qos(profile: QosProfile) -> Any:
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if profile.keep_all else HistoryPolicy.KEEP_LAST,
        depth=max(profile.depth, 1),
        reliability=ReliabilityPolicy.RELIABLE
        if profile.reliability == "reliable"
        else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL
        if profile.durability == "transient_local"
        else DurabilityPolicy.VOLATILE,
    )


class RclpyPublisher:
    def __init__(self, publisher: Any, topic: str, type_name: str, profile: QosProfile) -> None:
        self._publisher = publisher
        self.topic = topic
        self.type_name = type_name
        self.profile = profile

    def publish(self, msg: Any) -> None:
        self._publisher.publish(msg)

    def publish_raw(self, data: bytes) -> None:
        self._publisher.publish(data)

    def subscription_count(self) -> int:
        return int(self._publisher.get_subscription_count())


class RclpyBackend:
    name = "rclpy"

    def __init__(self, node_name: str, namespace: str) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        if not rclpy.ok():
            rclpy.init(args=None)
        self._rclpy = rclpy
        self.node = rclpy.create_node(node_name, namespace=namespace)
        self._executor = SingleThreadedExecutor()
        self._executor.add_node(self.node)
        self._endpoints: list[tuple[str, Any, QosProfile]] = []

    def create_publisher(self, topic: str, type_name: str, qos: QosProfile) -> RclpyPublisher:
        cls = _message_class(type_name)
        pub = self.node.create_publisher(cls, topic, _rclpy_qos(qos))
        publisher = RclpyPublisher(pub, topic, normalize_type_name(type_name), qos)
        self._endpoints.append(("writer", publisher, qos))
        return publisher

    def create_subscription(
        self,
        topic: str,
        type_name: str,
        callback: Callable[[Any], None],
        qos: QosProfile,
        raw: bool = False,
    ) -> Any:
        cls = _message_class(type_name)
        if raw:
            deliver: Callable[[Any], None] = lambda data: callback(  # noqa: E731
                (bytes(data), self.now_ns())
            )
        else:
            deliver = callback
        sub = self.node.create_subscription(cls, topic, deliver, _rclpy_qos(qos), raw=raw)
        sub.type_name = normalize_type_name(type_name)
        self._endpoints.append(("reader", sub, qos))
        return sub

    def create_timer(self, period_s: float, callback: Callable[[], None]) -> Any:
        return self.node.create_timer(period_s, callback)

    def new_message(self, type_name: str, **fields: Any) -> Any:
        msg = _message_class(type_name)()
        for key, value in fields.items():
            if isinstance(value, np.ndarray):
                value = value.tolist()
            setattr(msg, key, value)
        return msg

    def spin_once(self, timeout_s: float) -> None:
        self._executor.spin_once(timeout_sec=timeout_s)

    def now_ns(self) -> int:
        return int(self.node.get_clock().now().nanoseconds)

    def match_signature(self) -> tuple[object, ...]:
        """Matched counts per reader and writer (rclpy names no matched endpoints)."""
        return tuple(e.matched_count for e in self.endpoints())

    def endpoints(self) -> list[Endpoint]:
        """Readers and writers with matched counts: rclpy does not name the matched endpoints
        (their GIDs), so the start barrier compares counts (barrier.py)."""
        out = []
        for i, (kind, entity, qos) in enumerate(self._endpoints):
            if kind == "writer":
                count = int(entity._publisher.get_subscription_count())
            else:
                count = int(entity.get_publisher_count())
            out.append(
                Endpoint(
                    topic=entity.topic if kind == "writer" else entity.topic_name,
                    kind=kind,
                    gid=f"{self.node.get_fully_qualified_name()}#{kind}{i}",
                    reliable=qos.reliability == "reliable",
                    transient_local=qos.durability == "transient_local",
                    matched=None,
                    matched_count=count,
                )
            )
        return out

    def topic_types(self) -> dict[str, tuple[str, QosProfile | None]]:
        """Topics with their type and the QoS offered by their first publisher."""
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy

        result: dict[str, tuple[str, QosProfile | None]] = {}
        for name, types in self.node.get_topic_names_and_types():
            profile = None
            for info in self.node.get_publishers_info_by_topic(name):
                q = info.qos_profile
                profile = QosProfile(
                    "best_effort" if q.reliability == ReliabilityPolicy.BEST_EFFORT else "reliable",
                    "transient_local"
                    if q.durability == DurabilityPolicy.TRANSIENT_LOCAL
                    else "volatile",
                    0 if q.history == HistoryPolicy.KEEP_ALL else int(q.depth),
                )
                break
            result[name] = (types[0], profile)
        return result

    def close(self) -> None:
        self._executor.remove_node(self.node)
        self.node.destroy_node()
        if self._rclpy.ok():
            self._rclpy.try_shutdown()
