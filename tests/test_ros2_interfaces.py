"""The rig's own messages and service (aero_rig_interfaces) seen with the real ``ros2`` tools.

Every type is shown by ``ros2 interface show``; every typed topic of a running simulated graph
is echoed once with named fields; the control service answers ``ros2 service call`` and refuses
outside an adaptive run, saying why. The tools come from ``../shared/ros2-python`` (``make
test`` installs them); the graph is `aero-rig run sim`'s with the short plan in real time (its
225 s outlast the tests: the first model comes after about 50 s, and the anomaly test needs
commands still streaming), on this machine only (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST).
"""

import re
import select
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from graph_support import NEEDS_ROS2_TOOLS, ROS2, Ros2Graph, sim_graph_for_ros2

from rig_runtime.interface import (
    EXPERIMENT_ANOMALY,
    EXPERIMENT_CONTROL,
    EXPERIMENT_PLAN,
    EXPERIMENT_SEGMENT,
    GRAPH_READY,
    IDENTIFICATION_MODEL,
    PITCH_STOP,
)
from rig_testing.processes import graph_env

INTERFACES = Path(__file__).resolve().parents[1] / "src" / "aero_rig_interfaces"
TYPES = sorted(
    f"aero_rig_interfaces/{p.parent.name}/{p.stem}"
    for p in (*INTERFACES.glob("msg/*.msg"), *INTERFACES.glob("srv/*.srv"))
)
pytestmark = NEEDS_ROS2_TOOLS


def _env() -> dict[str, str]:
    """A test graph's environment with the venv in the ament index (what sourcing a ROS
    install does; docs/usage.md): ``ros2 interface`` finds the types there."""
    return graph_env(AMENT_PREFIX_PATH=sys.prefix)


def _ros2(env: dict[str, str], *args: str, timeout: float = 60.0) -> str:
    proc = subprocess.run(
        [str(ROS2), *args], env=env, capture_output=True, text=True, timeout=timeout
    )
    assert proc.returncode == 0, (args, proc.returncode, proc.stdout, proc.stderr[-2000:])
    return proc.stdout + proc.stderr


def _field_names(definition: str) -> list[str]:
    """The field names of a .msg or .srv text (comments and constants left out)."""
    names = []
    for line in definition.splitlines():
        words = line.split("#", 1)[0].split()
        if len(words) >= 2 and "=" not in words[1]:
            names.append(words[1])
    return names


@pytest.mark.parametrize("type_name", TYPES)
def test_interface_show_names_every_field(type_name: str) -> None:
    """``ros2 interface show`` finds each type in the venv's ament index, fields and comments."""
    kind, name = type_name.split("/")[1:]
    source = (INTERFACES / kind / f"{name}.{kind}").read_text()
    shown = _ros2(_env(), "interface", "show", type_name)
    for field in _field_names(source):
        assert re.search(rf"^\s*\S+\s+{field}\b", shown, re.MULTILINE), (field, shown)
    if kind == "srv":
        assert "---" in shown, shown


def test_the_package_lists_its_types() -> None:
    listed = _ros2(_env(), "interface", "package", "aero_rig_interfaces").split()
    assert sorted(listed) == TYPES


def _echo_once(graph: Ros2Graph, topic: str, timeout: float = 120.0) -> str:
    return graph.ros2("topic", "echo", "--once", topic, timeout=timeout)


@pytest.fixture(scope="module")
def graph(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Ros2Graph]:
    """The sim graph as rclpy node processes: the short plan in real time."""
    generator = {"plan": "short", "real_time_factor": 1.0, "start_timeout_s": 120.0}
    with sim_graph_for_ros2(_env(), tmp_path_factory.mktemp("ros2interfaces"), generator) as g:
        yield g


def test_topic_list_shows_the_rig_s_types(graph: Ros2Graph) -> None:
    listed = graph.ros2("topic", "list", "-t")
    for topic in (
        EXPERIMENT_PLAN,
        EXPERIMENT_SEGMENT,
        EXPERIMENT_ANOMALY,
        IDENTIFICATION_MODEL,
        GRAPH_READY,
    ):
        assert f"{topic.name} [{topic.type}]" in listed, listed
    assert "std_msgs/msg/String" not in listed, listed


def test_echo_of_the_plan(graph: Ros2Graph) -> None:
    out = _echo_once(graph, EXPERIMENT_PLAN.name)
    assert re.search(r"^plan_id: short$", out, re.MULTILINE), out
    assert re.search(r"^revision: 0$", out, re.MULTILINE), out
    assert re.search(r"^fs: 200\.0$", out, re.MULTILINE), out
    assert re.search(r"^adaptive: false$", out, re.MULTILINE), out
    assert "plan_json: '{" in out, out


def test_echo_of_a_readiness_report(graph: Ros2Graph) -> None:
    out = _echo_once(graph, GRAPH_READY.name)
    assert re.search(r"^node: /\w+$", out, re.MULTILINE), out
    assert re.search(r"^ready: (true|false)$", out, re.MULTILINE), out
    assert re.search(r"^- topic: /", out, re.MULTILINE), out
    assert re.search(r"^  matched_count: \d+$", out, re.MULTILINE), out


def test_echo_of_a_segment_event(graph: Ros2Graph) -> None:
    out = _echo_once(graph, EXPERIMENT_SEGMENT.name)
    assert re.search(r"^event: (start|end)$", out, re.MULTILINE), out
    assert re.search(r"^kind: (ramp|settle|multisine|sine)$", out, re.MULTILINE), out
    assert re.search(r"^start_k: \d+$", out, re.MULTILINE), out
    assert re.search(r"^offset_deg: ", out, re.MULTILINE), out


def test_echo_of_the_model(graph: Ros2Graph) -> None:
    """Latched: the first refit's model (after the first realization) once it is there."""
    out = _echo_once(graph, IDENTIFICATION_MODEL.name, timeout=240.0)
    assert re.search(r"^refit: [1-9]\d*$", out, re.MULTILINE), out
    assert re.search(r"^- name: ", out, re.MULTILINE), out
    assert re.search(r"^  offset_deg: -?\d", out, re.MULTILINE), out
    assert re.search(r"^  clusters: \d+$", out, re.MULTILINE), out
    assert "model_json: '{" in out, out


def test_control_service_refuses_outside_an_adaptive_run(graph: Ros2Graph) -> None:
    listed = graph.ros2("service", "list", "-t")
    assert f"{EXPERIMENT_CONTROL.name} [{EXPERIMENT_CONTROL.type}]" in listed, listed
    out = graph.ros2(
        "service",
        "call",
        EXPERIMENT_CONTROL.name,
        EXPERIMENT_CONTROL.type,
        "{action: finish_level, level: 0, after_k: 0, reason: 'from ros2 service call'}",
    )
    assert "accepted=False" in out, out
    assert re.search(r"message='[^']*not an adaptive run", out), out


def test_echo_of_an_anomaly(graph: Ros2Graph) -> None:
    """A stop on /pitch/stop: the actuator holds, the commands it no longer follows are an
    anomaly (not_tracking). Last in this module: the run is not nominal after it."""
    echo = subprocess.Popen(
        [str(ROS2), "topic", "echo", "--once", EXPERIMENT_ANOMALY.name],
        env=graph.env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        # The echo's reader is matched when the topic counts one more subscription than the
        # graph's own two (identifier, recorder): then the stop is sent.
        deadline = time.monotonic() + 60.0
        count = 0
        while time.monotonic() < deadline and count < 3:
            info = graph.ros2("topic", "info", EXPERIMENT_ANOMALY.name)
            count = int(re.search(r"Subscription count: (\d+)", info).group(1))  # type: ignore[union-attr]
        assert count >= 3, info
        graph.ros2("topic", "pub", "--once", PITCH_STOP.name, "std_msgs/msg/Bool", "{data: true}")
        assert echo.stdout is not None
        ready, _, _ = select.select([echo.stdout], [], [], 60.0)
        assert ready, "no anomaly within 60 s of the stop"
        out, _ = echo.communicate(timeout=30)
    finally:
        if echo.poll() is None:
            echo.kill()
            echo.communicate()
    assert re.search(r"^kind: not_tracking$", out, re.MULTILINE), out
    assert re.search(r"^node: sim_actuator$", out, re.MULTILINE), out
    assert re.search(r"^first_ns: \d+$", out, re.MULTILINE), out
    assert re.search(r"^open: (true|false)$", out, re.MULTILINE), out
