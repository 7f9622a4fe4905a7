"""What the rclpy backend reports to the start barrier, with stand-ins for rclpy's entities
(rclpy is not installable here; docs/ros_machine.md has the check on a ROS machine)."""

from types import SimpleNamespace
from typing import Any

from rig_runtime.barrier import ReadinessReport, StartBarrier
from rig_runtime.interface import PITCH_COMMAND
from rig_runtime.qos import PROFILES, QosProfile
from rig_runtime.rclpy_backend import RclpyBackend, RclpyPublisher


def _backend(fq_name: str, endpoints: list[tuple[str, Any, QosProfile]]) -> RclpyBackend:
    backend = object.__new__(RclpyBackend)  # no rclpy.init: only endpoints() is exercised
    backend.node = SimpleNamespace(get_fully_qualified_name=lambda: fq_name)
    backend._endpoints = endpoints
    return backend


def test_counts_not_gids_and_the_barrier_decides_on_them() -> None:
    writer = RclpyPublisher(
        SimpleNamespace(get_subscription_count=lambda: 1),
        PITCH_COMMAND.name,
        "sensor_msgs/msg/JointState",
        PROFILES["stream"],
    )
    reader = SimpleNamespace(topic_name=PITCH_COMMAND.name, get_publisher_count=lambda: 1)
    gen = _backend("/generator", [("writer", writer, PROFILES["stream"])]).endpoints()
    act = _backend("/sim_actuator", [("reader", reader, PROFILES["stream"])]).endpoints()
    assert gen[0].matched is None and gen[0].matched_count == 1 and gen[0].kind == "writer"
    assert act[0].topic == PITCH_COMMAND.name and act[0].matched_count == 1
    assert not act[0].transient_local and act[0].reliable
    barrier = StartBarrier(["sim_actuator"])
    barrier.update(ReadinessReport("/sim_actuator", True, endpoints=tuple(act)))
    assert barrier.pending(ReadinessReport("/generator", True, endpoints=tuple(gen))) == []
    lonely = RclpyPublisher(
        SimpleNamespace(get_subscription_count=lambda: 0),
        PITCH_COMMAND.name,
        "sensor_msgs/msg/JointState",
        PROFILES["stream"],
    )
    gen = _backend("/generator", [("writer", lonely, PROFILES["stream"])]).endpoints()
    assert barrier.pending(ReadinessReport("/generator", True, endpoints=tuple(gen))) == [
        "/generator: its writer of /pitch/command has matched 0 of 1 member endpoints"
    ]
