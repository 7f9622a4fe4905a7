"""ROS 2 launch descriptions built from a graph YAML (config/sim.yaml, config/rig.yaml).

The graph description that rig-launch and aero-rig run (rig_runtime.graph) is also what
``ros2 launch aero_rig sim.launch.py`` runs, so the list of nodes is written once:

- one ``launch_ros.actions.Node`` per graph node: package, executable, name, namespace,
  ``parameters=[file, ..., overrides]``, ``remappings=[(from, to), ...]``;
- ``on_exit``: a node with ``stops_graph`` shuts the launch down when it exits, any node that
  exits non-zero does too (rig-launch's rule);
- a run directory laid out as ``aero-rig run`` lays it out: the ``run_dir`` launch argument
  (default ``runs/<YYYYmmdd-HHMMSS>``); the recorder node (rig_runtime ``recorder``) writes
  ``<run_dir>/bag``, the identifier its models and report into ``<run_dir>``;
- ``record:=true`` adds ``ros2 bag record -s mcap`` of the recorder's topics (the docs/design.md §4
  topics) into ``<run_dir>/rosbag2``: rosbag2's own recording beside the project's;
- ``graph:=...`` picks another graph: a path, ``pkg://<package>/<path>`` or a file name in
  aero_rig's config directory (``graph:=rig`` = ``rig.yaml``);
- ``host:=rig`` (comma-separated names) launches only the nodes the graph places on those
  machines, as ``rig-launch --host``: one launch per machine of a lab (docs/ros_machine.md §6).

The .launch.py files only call :func:`generate_graph_launch_description`. The graph file is
read and checked by ``rig_runtime.graph`` (the one graph-description model, shared with
rig-launch and aero-rig); the topics come from the interface contract ``rig_runtime.interface``.
Both import only pyyaml and the standard library (``rig_runtime`` loads its middleware lazily):
the ``ros2 launch`` process imports rclpy, and must not pull in the venv's middleware or rerun.
launch, launch_ros and ament_index_python are imported inside the functions that need them
(they exist only on a ROS 2 machine).
"""

import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import yaml

from rig_runtime.graph import (
    GraphError,
    GraphSpec,
    NodeSpec,
    load_graph,
    package_share,
    resolve_path,
)
from rig_runtime.interface import RECORDED_TOPICS

PACKAGE = "aero_rig"
RECORDER = ("rig_runtime", "recorder")
IDENTIFIER = ("aero_identification", "identifier")
# (package, executable) that must not run under ROS launch, and why.
VENV_ONLY = {
    ("aero_rig", "view"): (
        "the Rerun view needs numpy >= 2, which a ROS 2 Jazzy install from Ubuntu's "
        "packages does not have (docs/design.md §3.9); start it from the project's virtual "
        "environment with `ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET aero-rig view live`"
    ),
}


def find_graph(text: str) -> Path:
    """The graph file named by the ``graph`` launch argument."""
    if text.startswith("pkg://"):
        candidates = [resolve_path(text, Path.cwd())]
    else:
        config = package_share(PACKAGE) / "config"
        candidates = [Path(text).expanduser(), config / text, config / f"{text}.yaml"]
    for path in candidates:
        if path.is_file():
            return path.resolve()
    raise GraphError(
        f"graph {text!r} not found (tried {', '.join(str(p) for p in candidates)}); give a "
        "path, pkg://<package>/<path> or a graph name in aero_rig/config (sim, rig)"
    )


def file_parameter(node: NodeSpec, name: str) -> Any:
    """The value of one parameter as the node's files and overrides set it (None: unset)."""
    value = None
    keys = {"/**", node.name, node.fq_name, node.fq_name.lstrip("/")}
    for path in node.parameters:
        document = yaml.safe_load(Path(path).read_text()) or {}
        for key, block in document.items():
            if str(key) in keys and isinstance(block, dict):
                params = block.get("ros__parameters") or {}
                if name in params:
                    value = params[name]
    return node.parameter_overrides.get(name, value)


def recorded_topics(nodes: Sequence[NodeSpec]) -> list[str]:
    """What ``record:=true`` records: the recorder node's ``topics`` (empty = every topic)."""
    recorders = [n for n in nodes if (n.package, n.executable) == RECORDER]
    if not recorders:
        return [t.name for t in RECORDED_TOPICS]
    return [str(t) for t in file_parameter(recorders[0], "topics") or []]


def default_run_dir(now: float | None = None) -> str:
    """``runs/<YYYYmmdd-HHMMSS>``, as aero-rig names its run directories."""
    return os.path.join("runs", time.strftime("%Y%m%d-%H%M%S", time.localtime(now)))


def stop_on_exit(node: NodeSpec) -> Callable[[Any, Any], list[Any] | None]:
    """``on_exit`` handler: shut the launch down as rig-launch stops a graph."""

    def on_exit(event: Any, _context: Any) -> list[Any] | None:
        from launch.actions import Shutdown

        code = event.returncode
        if code != 0:
            return [Shutdown(reason=f"node {node.name!r} exited with code {code}")]
        if node.stops_graph:
            return [Shutdown(reason=f"node {node.name!r} finished (stops_graph)")]
        return None

    return on_exit


def graph_actions(graph: GraphSpec, run_dir: str, hosts: Sequence[str] | None = None) -> list[Any]:
    """The launch actions of a graph: its Nodes and the conditional ros2 bag record.

    ``run_dir`` receives the recorder's bag (``bag``), the identifier's models and report, and
    the rosbag2 recording (``rosbag2``); it is not created here. ``hosts``: only the nodes
    placed on those machines (None: every node); the start barrier still waits for all.
    """
    from launch.actions import ExecuteProcess
    from launch.conditions import IfCondition
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node

    if hosts is not None:
        graph.check_hosts(hosts)
    nodes = [n for n in graph.nodes if n.on(hosts)]
    for node in nodes:
        reason = VENV_ONLY.get((node.package, node.executable))
        if reason:
            raise GraphError(f"node {node.name!r} cannot run under ros2 launch: {reason}")
    if sum((n.package, n.executable) == RECORDER for n in nodes) > 1:
        raise GraphError("more than one recorder node: they would share one bag")
    actions: list[Any] = []
    barrier = graph.barrier_overrides()  # the start barrier waits for every member
    for node in nodes:
        overrides = dict(node.parameter_overrides)
        for key, value in barrier.get(node.name, {}).items():
            overrides.setdefault(key, value)
        if (node.package, node.executable) == RECORDER:
            overrides["output"] = os.path.join(run_dir, "bag")
        elif (node.package, node.executable) == IDENTIFIER:
            overrides["output_dir"] = run_dir
        parameters: list[Any] = [str(path) for path in node.parameters]
        if overrides:
            parameters.append(overrides)
        actions.append(
            Node(
                package=node.package,
                executable=node.executable,
                name=node.name,
                namespace=None if node.namespace in ("", "/") else node.namespace,
                parameters=parameters,
                remappings=list(node.remappings.items()),
                output="screen",
                on_exit=stop_on_exit(node),
                **({"prefix": f"nice -n {node.nice}"} if node.nice else {}),
            )
        )
    topics = recorded_topics(graph.nodes)
    # Positional topics: accepted by every Jazzy ros2bag (later releases prefer --topics).
    actions.append(
        ExecuteProcess(
            cmd=["ros2", "bag", "record", "-s", "mcap", "-o", os.path.join(run_dir, "rosbag2")]
            + (topics or ["--all"]),
            name="ros2_bag_record",
            output="screen",
            condition=IfCondition(LaunchConfiguration("record")),
        )
    )
    return actions


def _launch_setup(context: Any, *_args: Any, **_kwargs: Any) -> list[Any]:
    from launch.substitutions import LaunchConfiguration

    path = find_graph(LaunchConfiguration("graph").perform(context))
    graph = load_graph(path)
    # Absolute, so the launch log names the place; nodes inherit the launch's cwd anyway.
    run_dir = os.path.abspath(LaunchConfiguration("run_dir").perform(context) or default_run_dir())
    hosts = [h.strip() for h in LaunchConfiguration("host").perform(context).split(",")]
    # checks before creating anything
    actions = graph_actions(graph, run_dir, [h for h in hosts if h] or None)
    if os.path.isdir(run_dir) and os.listdir(run_dir):
        raise GraphError(f"run directory {run_dir} exists and is not empty; use run_dir:=NEW")
    os.makedirs(run_dir, exist_ok=True)
    return actions


def generate_graph_launch_description(default_graph: str) -> Any:
    """The LaunchDescription of a .launch.py file: arguments, then the graph's actions."""
    # mypy resolves ``launch`` to this package's launch/ directory (the .launch.py files), a
    # namespace package without LaunchDescription; ROS's launch is untyped anyway.
    from launch import LaunchDescription  # type: ignore[attr-defined]  # see the comment above
    from launch.actions import DeclareLaunchArgument, OpaqueFunction

    default_path = str(package_share(PACKAGE) / "config" / default_graph)
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                "graph",
                default_value=default_path,
                description="graph YAML: a path, pkg://<package>/<path> or a name in "
                "aero_rig/config (sim, rig)",
            ),
            DeclareLaunchArgument(
                "record",
                default_value="false",
                description="true: also record the recorder's topics with "
                "`ros2 bag record -s mcap` into <run_dir>/rosbag2",
            ),
            DeclareLaunchArgument(
                "host",
                default_value="",
                description="launch only the nodes the graph places on these hosts "
                "(comma-separated, e.g. rig); empty: every node",
            ),
            DeclareLaunchArgument(
                "run_dir",
                default_value="",
                description="run directory (new or empty): bag/ of the recorder node, models "
                "and report of the identifier; empty: runs/<YYYYmmdd-HHMMSS>",
            ),
            OpaqueFunction(function=_launch_setup),
        ]
    )
