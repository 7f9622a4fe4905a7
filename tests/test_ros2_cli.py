"""The simulated graph seen with the real ``ros2`` command (ros2cli, Jazzy).

The tools come from ``../shared/ros2-python`` (``make test`` installs them into the venv);
without them these tests skip with one line. The graph is `aero-rig run sim`'s, in real time
(``real_time_factor`` 1), on this machine only (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, as
every test).
"""

import re
import select
import signal
import subprocess
import time
from collections.abc import Iterator

import pytest
from graph_support import NEEDS_ROS2_TOOLS, ROS2, Ros2Graph, sim_graph_for_ros2
from graph_support import SIM_NODES as NODES

from rig_runtime.interface import PITCH_COMMAND
from rig_runtime.qos import resolve_qos
from rig_testing.processes import graph_env

pytestmark = NEEDS_ROS2_TOOLS


@pytest.fixture(scope="module")
def graph(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Ros2Graph]:
    """The sim graph, as rclpy node processes: the default plan in real time."""
    generator = {"plan": "default", "real_time_factor": 1.0, "start_timeout_s": 120.0}
    with sim_graph_for_ros2(graph_env(), tmp_path_factory.mktemp("ros2cli"), generator) as g:
        yield g


def test_node_list_shows_the_six_nodes_every_time(graph: Ros2Graph) -> None:
    """As a user types it (the daemon, its default spin time), ten times in a row."""
    for _ in range(10):
        assert sorted(graph.ros2("node", "list").split()) == NODES


def test_node_info_shows_the_generator_s_endpoints(graph: Ros2Graph) -> None:
    info = graph.ros2("node", "info", "/generator")
    publishers = info.split("Publishers:")[1].split("Service Servers:")[0]
    subscribers = info.split("Subscribers:")[1].split("Publishers:")[0]
    for topic in ("/pitch/command", "/experiment/plan", "/experiment/segment", "/graph/ready"):
        assert f"{topic}:" in publishers, info
    # its credit (flow control): the lift's progress, not every coefficients sample
    assert "/wing/coefficients/progress:" in subscribers and "/graph/ready:" in subscribers, info
    assert "/wing/coefficients:" not in subscribers, info


def test_topic_list_with_types(graph: Ros2Graph) -> None:
    listed = graph.ros2("topic", "list", "-t")
    assert "/pitch/command [sensor_msgs/msg/JointState]" in listed
    assert "/pressure/taps [sensor_msgs/msg/PointCloud2]" in listed
    assert "/wing/coefficients [geometry_msgs/msg/Vector3Stamped]" in listed


def test_topic_info_qos_is_the_interface_s(graph: Ros2Graph) -> None:
    info = graph.ros2("topic", "info", "-v", PITCH_COMMAND.name)
    blocks = info.split("Node name: ")[1:]
    by_node = {b.split("\n", 1)[0].strip(): b for b in blocks}
    assert "PUBLISHER" in by_node["generator"] and "SUBSCRIPTION" in by_node["sim_actuator"]
    qos = resolve_qos(PITCH_COMMAND.qos)
    reliability = "RELIABLE" if qos.reliability == "reliable" else "BEST_EFFORT"
    durability = "TRANSIENT_LOCAL" if qos.durability == "transient_local" else "VOLATILE"
    for block in by_node.values():
        assert f"Reliability: {reliability}" in block, block
        assert f"Durability: {durability}" in block, block


def test_topic_hz_of_the_taps_is_200_hz(graph: Ros2Graph) -> None:
    proc = subprocess.Popen(
        [str(ROS2), "topic", "hz", "/pressure/taps", "--window", "400"],
        env=graph.env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    lines: list[str] = []
    rates: list[float] = []
    deadline = time.monotonic() + 60.0
    try:
        assert proc.stdout is not None
        # ros2 topic hz reports once a second; the sixth report averages over 5 s or more.
        while len(rates) < 6 and time.monotonic() < deadline:
            ready, _, _ = select.select([proc.stdout], [], [], 1.0)
            if not ready:
                continue
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line)
            rates += [float(r) for r in re.findall(r"average rate: ([0-9.]+)", line)]
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=20)
    assert len(rates) >= 6, "".join(lines)
    assert 190.0 <= rates[-1] <= 210.0, "".join(lines)


def test_topic_echo_once(graph: Ros2Graph) -> None:
    out = graph.ros2("topic", "echo", "--once", "/wing/coefficients")
    assert "header:" in out and re.search(r"x: -?[0-9.e-]+", out), out


def test_param_list_get_describe_set(graph: Ros2Graph) -> None:
    listed = graph.ros2("param", "list", "/generator")
    for name in ("plan", "real_time_factor", "max_deg", "barrier_nodes"):
        assert f"  {name}\n" in listed, listed
    assert "Double value is: 1.0" in graph.ros2("param", "get", "/generator", "real_time_factor")
    described = graph.ros2("param", "describe", "/generator", "real_time_factor")
    assert "Read only: true" in described.replace("Read only: True", "Read only: true")
    assert "Min value: 0.0" in described and "Max value: 1000.0" in described, described
    dumped = graph.ros2("param", "dump", "/lift")
    assert "ros__parameters:" in dumped
    refused = graph.ros2("param", "set", "/generator", "seed", "3")
    assert "Setting parameter failed" in refused and "read-only" in refused, refused
    out_of_range = graph.ros2("param", "set", "/identifier", "max_early_samples", "-5")
    assert "Setting parameter failed" in out_of_range, out_of_range
    done = graph.ros2("param", "set", "/identifier", "max_early_samples", "30000")
    assert "Set parameter successful" in done, done
    assert "Integer value is: 30000" in graph.ros2(
        "param", "get", "/identifier", "max_early_samples"
    )
