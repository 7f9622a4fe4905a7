"""Named QoS profiles of the interface contract (docs/design.md §3-§4).

Plain data, so that the interface contract imports without rclpy (offline fits, launch
files); :func:`to_rclpy_qos` gives the rclpy ``QoSProfile`` a node creates its endpoints with.

- ``default``: reliable, volatile, keep-last 10 (ROS 2's default profile).
- ``sensor``: best effort, volatile, keep-last 5 (ROS 2's sensor-data profile).
- ``latched``: reliable, transient-local, keep-last 1 (a late subscriber gets the last sample).
- ``stream``: reliable, volatile, keep-all. For sample streams that must not lose a sample
  (simulation, recording): a slow reader back-pressures the writer instead of dropping.
  On the wire it is "reliable + volatile", so it matches ROS 2 default-QoS peers.
- ``events``: reliable, volatile, keep-last 1000 ("reliable, deep": segment events).
"""

from dataclasses import dataclass, replace
from typing import Any, Literal

Reliability = Literal["reliable", "best_effort"]
Durability = Literal["volatile", "transient_local"]


@dataclass(frozen=True)
class QosProfile:
    reliability: Reliability
    durability: Durability
    depth: int  # 0 = keep all

    @property
    def keep_all(self) -> bool:
        return self.depth == 0

    def to_rosbags_qos(self) -> Any:
        """The offered-QoS record rosbag2 keeps per topic (metadata.yaml, MCAP channel)."""
        from rosbags.interfaces import (
            Qos,
            QosDurability,
            QosHistory,
            QosLiveliness,
            QosReliability,
            QosTime,
        )

        never = QosTime(sec=2147483647, nsec=4294967295)
        return Qos(
            history=QosHistory.KEEP_ALL if self.keep_all else QosHistory.KEEP_LAST,
            depth=self.depth,
            reliability=QosReliability.RELIABLE
            if self.reliability == "reliable"
            else QosReliability.BEST_EFFORT,
            durability=QosDurability.TRANSIENT_LOCAL
            if self.durability == "transient_local"
            else QosDurability.VOLATILE,
            deadline=never,
            lifespan=never,
            liveliness=QosLiveliness.AUTOMATIC,
            liveliness_lease_duration=never,
            avoid_ros_namespace_conventions=False,
        )


PROFILES: dict[str, QosProfile] = {
    "default": QosProfile("reliable", "volatile", 10),
    "sensor": QosProfile("best_effort", "volatile", 5),
    "latched": QosProfile("reliable", "transient_local", 1),
    "stream": QosProfile("reliable", "volatile", 0),
    "events": QosProfile("reliable", "volatile", 1000),
}


def from_rclpy_qos(qos: Any) -> QosProfile:
    """The profile of an rclpy ``QoSProfile`` (read by its policies' names, so that this module
    still imports without rclpy)."""
    keep_all = getattr(qos.history, "name", "") == "KEEP_ALL"
    return QosProfile(
        "best_effort" if getattr(qos.reliability, "name", "") == "BEST_EFFORT" else "reliable",
        "transient_local"
        if getattr(qos.durability, "name", "") == "TRANSIENT_LOCAL"
        else "volatile",
        0 if keep_all else int(qos.depth),
    )


def resolve_qos(qos: Any, depth: int | None = None) -> QosProfile:
    """A profile by name, as given, from an rclpy ``QoSProfile`` or, as rclpy takes it, a
    history depth (reliable, volatile, keep-last); optionally with another history depth."""
    if isinstance(qos, QosProfile):
        profile = qos
    elif isinstance(qos, int) and not isinstance(qos, bool):
        profile = QosProfile("reliable", "volatile", max(qos, 1))
    elif not isinstance(qos, str):
        profile = from_rclpy_qos(qos)
    else:
        try:
            profile = PROFILES[qos]
        except KeyError:
            raise ValueError(f"unknown QoS profile {qos!r}; known: {sorted(PROFILES)}") from None
    return profile if depth is None else replace(profile, depth=depth)


def to_rclpy_qos(profile: QosProfile) -> Any:
    """The rclpy ``QoSProfile`` of a profile (imports rclpy: graph processes only)."""
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
