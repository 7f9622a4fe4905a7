"""rmw_fastrtps publishes asynchronously only where no Cyclone DDS reader can lose the start of
a stream: every node of the graph on rclpy, and never against the user's own choice."""

from pathlib import Path

import yaml

from rig_runtime.graph import load_graph
from rig_runtime.launcher import Launcher
from rig_runtime.ros_environment import PUBLICATION_MODE_ENV, asynchronous_publication


def test_asynchronous_only_for_an_all_rclpy_graph_and_no_user_choice() -> None:
    assert asynchronous_publication(["rclpy", "rclpy"], {}) == {
        PUBLICATION_MODE_ENV: "ASYNCHRONOUS"
    }
    assert asynchronous_publication(["rclpy", "dds"], {}) == {}  # a mixed graph
    assert asynchronous_publication(["dds"], {}) == {}
    assert asynchronous_publication([], {}) == {}
    user = {PUBLICATION_MODE_ENV: "SYNCHRONOUS"}
    assert asynchronous_publication(["rclpy"], user) == {}


def test_the_launcher_names_each_nodes_backend(tmp_path: Path) -> None:
    graph = {
        "name": "g",
        "nodes": [
            {"name": "a", "package": "rig_runtime", "executable": "talker"},
            {"name": "b", "package": "rig_runtime", "executable": "listener", "backend": "rclpy"},
            {"name": "c", "package": "rig_runtime", "executable": "listener"},
        ],
    }
    path = tmp_path / "graph.yaml"
    path.write_text(yaml.safe_dump(graph))
    env = {"RIG_RUNTIME_BACKEND": "dds"}
    launcher = Launcher(load_graph(path), env=env, backends={"c": "rclpy"})
    assert launcher.node_backends() == {"a": "dds", "b": "rclpy", "c": "rclpy"}
    assert asynchronous_publication(launcher.node_backends().values(), {}) == {}
    every = Launcher(load_graph(path), env=env, backends={"a": "rclpy", "c": "rclpy"})
    assert set(every.node_backends().values()) == {"rclpy"}
