"""The rig's rclpy Node in one process (the PyPI wheels): what it reports to the start barrier,
its parameters (rclpy parameters with descriptors, checked by the runtime's rules), its logs on
/rosout, and the runtime's message objects."""

import dataclasses
import logging
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
import rclpy.node

from rig_runtime.barrier import StartBarrier
from rig_runtime.interface import PITCH_COMMAND
from rig_runtime.node import Node
from rig_runtime.params import Parameter, ParameterError
from rig_runtime.ros_environment import ArgumentError
from rig_testing.processes import graph_env, join_graph

PARAMS = [
    Parameter("fs", 200.0, "sample rate [Hz]", min=1.0, max=10000.0),
    Parameter("count", 3, "how many", min=0),
    Parameter("names", [], "names", element_type=str),
    Parameter("mode", "a", "mode", choices=("a", "b"), read_only=False),
    Parameter("gain", 1.0, "a live gain", min=0.0, max=2.0, read_only=False),
]


@pytest.fixture
def rclpy_env(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    join_graph(graph_env(), monkeypatch.setenv)
    yield


def test_counts_not_gids_and_the_barrier_decides_on_them(rclpy_env: None) -> None:
    gen = Node("generator", argv=[])
    act = Node("sim_actuator", argv=[])
    try:
        assert isinstance(gen, rclpy.node.Node)  # the rig's Node is an rclpy node
        pub = gen.create_publisher(PITCH_COMMAND.type, PITCH_COMMAND.name, PITCH_COMMAND.qos)
        act.create_subscription(
            PITCH_COMMAND.type, PITCH_COMMAND.name, lambda m: None, PITCH_COMMAND.qos
        )
        assert gen.spin_until(lambda: pub.subscription_count() == 1, 10.0)
        assert act.spin_until(lambda: act.readiness_report().endpoints[-1].matched_count == 1, 10.0)
        report = gen.readiness_report()
        (writer,) = [e for e in report.endpoints if e.topic == PITCH_COMMAND.name]
        assert writer.matched_count == 1 and writer.kind == "writer"
        (reader,) = act.readiness_report().endpoints[-1:]
        assert reader.topic == PITCH_COMMAND.name and reader.reliable
        assert not reader.transient_local
        barrier = StartBarrier(["sim_actuator"])
        barrier.update(act.readiness_report())
        assert barrier.pending(report) == []
        # The same writer before it matched: the barrier holds the start on the count.
        unmatched = dataclasses.replace(writer, matched_count=0)
        early = dataclasses.replace(
            report, endpoints=tuple(unmatched if e is writer else e for e in report.endpoints)
        )
        assert barrier.pending(early) == [
            "/generator: its writer of /pitch/command has matched 0 of 1 member endpoints"
        ]
    finally:
        gen.close()
        act.close()


def test_messages_are_the_runtime_s_own_on_both_ends(rclpy_env: None) -> None:
    """Published as the runtime's CDR, received as the same dataclass with numpy arrays."""
    talker = Node("talker", argv=[])
    listener = Node("listener", argv=[])
    got: list[Any] = []
    try:
        listener.create_subscription(
            "sensor_msgs/msg/JointState", "/chatter", got.append, qos_profile="stream"
        )
        pub = talker.create_publisher(
            "sensor_msgs/msg/JointState", "/chatter", qos_profile="stream"
        )
        assert talker.spin_until(lambda: pub.subscription_count() == 1, 10.0)
        msg = talker.new_message("sensor_msgs/msg/JointState", name=["pitch"])
        msg.position = np.array([0.25])
        msg.header.stamp.sec = 7
        pub.publish(msg)
        assert listener.spin_until(lambda: len(got) == 1, 10.0)
        assert isinstance(got[0].position, np.ndarray)
        assert got[0].position.tolist() == [0.25] and got[0].name == ["pitch"]
        assert got[0].header.stamp.sec == 7
    finally:
        talker.close()
        listener.close()


def test_endpoints_of_rclpy_message_classes_are_counted_and_reported(rclpy_env: None) -> None:
    """An rclpy message class and QoSProfile: rclpy's messages on both ends, the endpoints in
    the readiness report with their matched counts and QoS, a required input named, and
    rclpy's destroy_* taking them back out."""
    from std_msgs.msg import String

    from rig_runtime.qos_profiles import EVENTS_QOS, LATCHED_QOS

    talker = Node("talker", argv=[])
    listener = Node("listener", argv=[])
    got: list[Any] = []
    try:
        sub = listener.create_subscription(String, "/events", got.append, EVENTS_QOS, required=True)
        pub = talker.create_publisher(String, "/events", EVENTS_QOS)
        latched = talker.create_publisher(String, "/latched", LATCHED_QOS)
        assert talker.spin_until(lambda: pub.subscription_count() == 1, 10.0)
        pub.publish(String(data="plan_end"))
        assert listener.spin_until(lambda: len(got) == 1, 10.0)
        assert isinstance(got[0], String) and got[0].data == "plan_end"
        assert (pub.count, sub.count) == (1, 1)
        writers = {e.topic: e for e in talker.readiness_report().endpoints if e.kind == "writer"}
        assert writers["/events"].matched_count == 1 and writers["/events"].reliable
        assert writers["/latched"].transient_local and not writers["/events"].transient_local
        report = listener.readiness_report()
        assert report.required_inputs == ("/events",)
        (reader,) = [e for e in report.endpoints if e.topic == "/events"]
        assert reader.kind == "reader" and reader.matched_count == 1
        assert talker.destroy_publisher(latched)
        assert "/latched" not in {e.topic for e in talker.readiness_report().endpoints}
    finally:
        talker.close()
        listener.close()


def test_parameters_come_from_rcl_and_keep_the_runtime_s_checks(rclpy_env: None) -> None:
    node = Node(
        "gen",
        PARAMS,
        ["--ros-args", "-r", "__ns:=/rig", "-p", "fs:=100", "-p", "names:=[ab, cd]"],
    )
    try:
        assert node.fq_name == "/rig/gen"
        assert node.params["fs"] == 100.0 and isinstance(node.params["fs"], float)
        assert node.params["names"] == ["ab", "cd"]
        assert node.params.sources["fs"] == "--ros-args"
        rnode = node  # an rclpy node: rclpy's own parameter API
        descriptor = rnode.describe_parameter("fs")
        assert descriptor.read_only and descriptor.description == "sample rate [Hz]"
        assert descriptor.floating_point_range[0].from_value == 1.0
        assert descriptor.floating_point_range[0].to_value == 10000.0
        assert not rnode.describe_parameter("gain").read_only
        assert rnode.get_parameter("count").value == 3
        # A live change takes effect; a read-only or out-of-range one is refused with a reason.
        from rclpy.parameter import Parameter as RosParameter

        (ok,) = rnode.set_parameters([RosParameter("gain", RosParameter.Type.DOUBLE, 1.5)])
        assert ok.successful and node.params["gain"] == 1.5
        (refused,) = rnode.set_parameters([RosParameter("fs", RosParameter.Type.DOUBLE, 50.0)])
        assert not refused.successful and "read-only" in refused.reason
        (refused,) = rnode.set_parameters([RosParameter("gain", RosParameter.Type.DOUBLE, 3.0)])
        assert not refused.successful and node.params["gain"] == 1.5
        (refused,) = rnode.set_parameters([RosParameter("mode", RosParameter.Type.STRING, "c")])
        assert not refused.successful and "one of ['a', 'b']" in refused.reason
        assert node.params["mode"] == "a"
    finally:
        node.close()


@pytest.mark.parametrize(
    ("args", "error", "text"),
    [
        (["--ros-args", "-p", "fs:=0.5"], ParameterError, "parameter 'fs' = 0.5"),
        (["--ros-args", "-p", "zz:=1"], ParameterError, "unknown parameter 'zz'"),
        (["--ros-args", "-p", "mode:=c"], ParameterError, "one of ['a', 'b']"),
        (["--ros-args", "--bogus"], ArgumentError, "--bogus"),
    ],
)
def test_bad_arguments_give_one_clear_error(
    rclpy_env: None, args: list[str], error: type[Exception], text: str
) -> None:
    with pytest.raises(error) as info:
        Node("gen", PARAMS, args)
    assert text in str(info.value)


def test_bad_environment_is_refused_before_anything_starts(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("RIG_RCLPY_EXECUTOR", "multi")
    with pytest.raises(ArgumentError, match="expected 'events' or 'single'"):
        Node("gen", PARAMS, [])
    monkeypatch.delenv("RIG_RCLPY_EXECUTOR")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LAN")
    with pytest.raises(ArgumentError, match="ROS_AUTOMATIC_DISCOVERY_RANGE='LAN'"):
        Node("gen", PARAMS, [])
    monkeypatch.delenv("ROS_AUTOMATIC_DISCOVERY_RANGE")
    monkeypatch.setenv("ROS_DOMAIN_ID", "300")
    with pytest.raises(ArgumentError, match=r"ROS_DOMAIN_ID=300 is outside 0\.\.232"):
        Node("gen", PARAMS, [])


def test_logs_reach_rosout(rclpy_env: None) -> None:
    node = Node("speaker", argv=[])
    watcher = Node("rosout_watcher", argv=[])
    got: list[Any] = []
    try:
        # Transient local, as rcl's /rosout writers are (depth 1000, lifespan 10 s): the reader's
        # side of a match can complete before the writer's, and a volatile reader then misses
        # a record written in between (it failed that way once under load); a transient-local
        # one gets it from the writer's history when the writer side matches.
        watcher.create_subscription(
            "rcl_interfaces/msg/Log", "/rosout", got.append, qos_profile="latched", depth=100
        )
        # Matched with both nodes' /rosout writers (its own and the speaker's).
        assert watcher.spin_until(
            lambda: watcher.readiness_report().endpoints[-1].matched_count >= 2, 10.0
        )
        node.logger.warning("pitch %d deg", 7)

        def seen() -> bool:
            node.spin_once(0.01)
            return any(m.msg == "pitch 7 deg" for m in got)

        assert watcher.spin_until(seen, 10.0)
        (entry,) = [m for m in got if m.msg == "pitch 7 deg"]
        assert entry.name == "speaker" and entry.level == logging.WARNING
    finally:
        node.close()
        watcher.close()


def test_without_rclpy_a_graph_command_says_how_to_get_it(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """One line naming the PyPI wheels, a ROS 2 Jazzy install and RoboStack's conda packages,
    and exit code 2, before anything starts (rig-launch; the aero-rig verbs use the same
    check, aero_rig/test/test_without_rclpy.py runs them in a venv without rclpy)."""
    from rig_runtime import launcher, ros_environment

    monkeypatch.setattr(ros_environment, "rclpy_available", lambda: False)
    with pytest.raises(ArgumentError, match=r"pip install \"ros-jazzy-rclpy\[fastrtps\]\""):
        ros_environment.require_rclpy()
    assert launcher.main(["graph.yaml"]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "ROS 2 Jazzy" in line and "robostack" in line and "aero-rig fit" in line


def test_a_topic_known_only_from_its_readers_has_no_type_for_the_recorder_yet(
    rclpy_env: None,
) -> None:
    """The recorder subscribes with the QoS its writers offer. A topic with only a reader so
    far is not offered yet: a guessed reliable reader would never match a best-effort writer
    that comes later (the rig's lift and scanner publish best effort)."""
    from rig_runtime.qos import QosProfile

    reader = Node("identifier", argv=[])
    recorder = Node("recorder", argv=[])
    writer: Node | None = None
    try:
        reader.create_subscription(
            "std_msgs/msg/Float64", "/wing/lift_probe", lambda m: None, "default"
        )
        assert recorder.spin_until(
            lambda: "/wing/lift_probe" in dict(recorder.get_topic_names_and_types()),
            10.0,
        )
        assert "/wing/lift_probe" not in recorder.topic_types()
        writer = Node("lift", argv=[])
        writer.create_publisher(
            "std_msgs/msg/Float64", "/wing/lift_probe", QosProfile("best_effort", "volatile", 5)
        )
        assert recorder.spin_until(lambda: "/wing/lift_probe" in recorder.topic_types(), 10.0)
        type_name, offered = recorder.topic_types()["/wing/lift_probe"]
        assert type_name == "std_msgs/msg/Float64"
        assert offered is not None and offered.reliability == "best_effort"
    finally:
        for node in (reader, recorder, writer):
            if node is not None:
                node.close()
