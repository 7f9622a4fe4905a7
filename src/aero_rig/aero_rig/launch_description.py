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
- ``record:=true`` adds ``ros2 bag record -s mcap`` of the recorder's topics (the DESIGN.md §4
  topics) into ``<run_dir>/rosbag2``: rosbag2's own recording beside the project's;
- ``graph:=...`` picks another graph: a path, ``pkg://<package>/<path>`` or a file name in
  aero_rig's config directory (``graph:=rig`` = ``rig.yaml``).

The .launch.py files only call :func:`generate_graph_launch_description`. This module reads
YAML with pyyaml and imports launch, launch_ros and ament_index_python inside the functions
that need them (they exist only on a ROS 2 machine). It never imports rig_runtime: the
``ros2 launch`` process imports rclpy, and must not pull in the venv's middleware or rerun.
"""

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

PACKAGE = "aero_rig"
RECORDER = ("rig_runtime", "recorder")
IDENTIFIER = ("aero_identification", "identifier")
# (package, executable) that must not run under ROS launch, and why.
VENV_ONLY = {
    ("aero_rig", "view"): (
        "the Rerun view needs numpy >= 2 and must never run in an rclpy process "
        "(DESIGN.md §3); start it from the project's virtual environment with "
        "`RIG_DDS_NETWORK=lan aero-rig view live`"
    ),
}
# DESIGN.md §4; recorded by `record:=true` when the graph has no recorder node to ask.
DESIGN_TOPICS = (
    "/pitch/command",
    "/pitch/state",
    "/pressure/taps",
    "/wing/coefficients",
    "/experiment/plan",
    "/experiment/segment",
    "/experiment/anomaly",  # addition: stretches to exclude (rig_runtime/anomaly.py)
    "/identification/status",
    "/identification/model",
)
_NODE_KEYS = {
    "name",
    "package",
    "executable",
    "namespace",
    "parameters",
    "parameter_overrides",
    "remappings",
    "stops_graph",
    "nice",
    "barrier",
}
BARRIER_ROLES = ("lead", "member", "none")  # rig_runtime.graph's start-barrier roles


class GraphFileError(ValueError):
    """A graph description the launch files cannot run."""


@dataclass(frozen=True)
class LaunchNode:
    """One graph node, resolved: parameter files are absolute paths that exist."""

    name: str
    package: str
    executable: str
    namespace: str = "/"
    parameter_files: tuple[str, ...] = ()
    overrides: dict[str, Any] = field(default_factory=dict)
    remappings: tuple[tuple[str, str], ...] = ()
    stops_graph: bool = False
    nice: int = 0
    barrier: str = "member"

    @property
    def fq_name(self) -> str:
        prefix = "" if self.namespace in ("", "/") else "/" + self.namespace.strip("/")
        return f"{prefix}/{self.name}"


def share_directory(package: str) -> str:
    """The package's installed share directory (ament index)."""
    from ament_index_python.packages import get_package_share_directory

    return str(get_package_share_directory(package))


def resolve_file(text: str, base_dir: Path) -> Path:
    """``pkg://<package>/<path>`` (share directory), absolute, or relative to ``base_dir``."""
    if text.startswith("pkg://"):
        package, _, rest = text[len("pkg://") :].partition("/")
        return Path(share_directory(package)) / rest
    path = Path(text).expanduser()
    return path if path.is_absolute() else base_dir / path


def find_graph(text: str) -> Path:
    """The graph file named by the ``graph`` launch argument."""
    if text.startswith("pkg://"):
        candidates = [resolve_file(text, Path.cwd())]
    else:
        config = Path(share_directory(PACKAGE)) / "config"
        candidates = [Path(text).expanduser(), config / text, config / f"{text}.yaml"]
    for path in candidates:
        if path.is_file():
            return path.resolve()
    raise GraphFileError(
        f"graph {text!r} not found (tried {', '.join(str(p) for p in candidates)}); give a "
        "path, pkg://<package>/<path> or a graph name in aero_rig/config (sim, rig)"
    )


def read_graph(path: Path) -> dict[str, Any]:
    try:
        document = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise GraphFileError(f"cannot read graph {path}: {exc}") from exc
    if not isinstance(document, dict) or not isinstance(document.get("nodes"), list):
        raise GraphFileError(f"{path}: expected a mapping with a 'nodes' list")
    return document


def graph_nodes(document: dict[str, Any], base_dir: Path) -> list[LaunchNode]:
    """The nodes of a parsed graph YAML, checked as rig_runtime.graph.parse_graph checks them."""
    nodes: list[LaunchNode] = []
    for i, item in enumerate(document.get("nodes") or []):
        where = f"nodes[{i}]"
        if not isinstance(item, dict):
            raise GraphFileError(f"{where}: expected a mapping")
        unknown = set(item) - _NODE_KEYS
        if unknown:
            raise GraphFileError(f"{where}: unknown keys {sorted(unknown)}")
        for key in ("name", "package", "executable"):
            if not isinstance(item.get(key), str) or not item[key]:
                raise GraphFileError(f"{where}: '{key}' (a non-empty string) is required")
        if any(n.name == item["name"] for n in nodes):
            raise GraphFileError(f"{where}: duplicate node name {item['name']!r}")
        nice = item.get("nice", 0)
        if isinstance(nice, bool) or not isinstance(nice, int) or not 0 <= nice <= 19:
            raise GraphFileError(f"{where} ({item['name']}): 'nice' must be an integer 0..19")
        barrier = item.get("barrier", "member")
        if barrier not in BARRIER_ROLES:
            raise GraphFileError(
                f"{where} ({item['name']}): 'barrier' must be one of {', '.join(BARRIER_ROLES)}"
            )
        files = []
        for text in item.get("parameters") or []:
            path = resolve_file(str(text), base_dir)
            if not path.is_file():
                raise GraphFileError(f"{where} ({item['name']}): no parameter file {path}")
            files.append(str(path))
        nodes.append(
            LaunchNode(
                name=item["name"],
                package=item["package"],
                executable=item["executable"],
                namespace=item.get("namespace") or "/",
                parameter_files=tuple(files),
                overrides=dict(item.get("parameter_overrides") or {}),
                remappings=tuple(
                    (str(k), str(v)) for k, v in (item.get("remappings") or {}).items()
                ),
                stops_graph=bool(item.get("stops_graph", False)),
                nice=nice,
                barrier=barrier,
            )
        )
    if sum(n.barrier == "lead" for n in nodes) > 1:
        raise GraphFileError("more than one node with 'barrier: lead'")
    return nodes


def file_parameter(node: LaunchNode, name: str) -> Any:
    """The value of one parameter as the node's files and overrides set it (None: unset)."""
    value = None
    keys = {"/**", node.name, node.fq_name, node.fq_name.lstrip("/")}
    for path in node.parameter_files:
        document = yaml.safe_load(Path(path).read_text()) or {}
        for key, block in document.items():
            if str(key) in keys and isinstance(block, dict):
                params = block.get("ros__parameters") or {}
                if name in params:
                    value = params[name]
    return node.overrides.get(name, value)


def recorded_topics(nodes: Sequence[LaunchNode]) -> list[str]:
    """What ``record:=true`` records: the recorder node's ``topics`` (empty = every topic)."""
    recorders = [n for n in nodes if (n.package, n.executable) == RECORDER]
    if not recorders:
        return list(DESIGN_TOPICS)
    return [str(t) for t in file_parameter(recorders[0], "topics") or []]


def default_run_dir(now: float | None = None) -> str:
    """``runs/<YYYYmmdd-HHMMSS>``, as aero-rig names its run directories."""
    return os.path.join("runs", time.strftime("%Y%m%d-%H%M%S", time.localtime(now)))


def stop_on_exit(node: LaunchNode) -> Callable[[Any, Any], list[Any] | None]:
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


def graph_actions(document: dict[str, Any], base_dir: Path, run_dir: str) -> list[Any]:
    """The launch actions of a parsed graph: its Nodes and the conditional ros2 bag record.

    ``run_dir`` receives the recorder's bag (``bag``), the identifier's models and report, and
    the rosbag2 recording (``rosbag2``); it is not created here.
    """
    from launch.actions import ExecuteProcess
    from launch.conditions import IfCondition
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node

    nodes = graph_nodes(document, base_dir)
    for node in nodes:
        reason = VENV_ONLY.get((node.package, node.executable))
        if reason:
            raise GraphFileError(f"node {node.name!r} cannot run under ros2 launch: {reason}")
    if sum((n.package, n.executable) == RECORDER for n in nodes) > 1:
        raise GraphFileError("more than one recorder node: they would share one bag")
    actions: list[Any] = []
    members = [n.fq_name for n in nodes if n.barrier == "member"]
    for node in nodes:
        overrides = dict(node.overrides)
        if node.barrier == "lead":  # the start barrier waits for every member (as rig-launch)
            overrides.setdefault("barrier_nodes", members)
        if (node.package, node.executable) == RECORDER:
            overrides["output"] = os.path.join(run_dir, "bag")
        elif (node.package, node.executable) == IDENTIFIER:
            overrides["output_dir"] = run_dir
        parameters: list[Any] = list(node.parameter_files)
        if overrides:
            parameters.append(overrides)
        actions.append(
            Node(
                package=node.package,
                executable=node.executable,
                name=node.name,
                namespace=None if node.namespace in ("", "/") else node.namespace,
                parameters=parameters,
                remappings=list(node.remappings),
                output="screen",
                on_exit=stop_on_exit(node),
                **({"prefix": f"nice -n {node.nice}"} if node.nice else {}),
            )
        )
    topics = recorded_topics(nodes)
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
    document = read_graph(path)
    # Absolute, so the launch log names the place; nodes inherit the launch's cwd anyway.
    run_dir = os.path.abspath(LaunchConfiguration("run_dir").perform(context) or default_run_dir())
    actions = graph_actions(document, path.parent, run_dir)  # checks before creating anything
    if os.path.isdir(run_dir) and os.listdir(run_dir):
        raise GraphFileError(f"run directory {run_dir} exists and is not empty; use run_dir:=NEW")
    os.makedirs(run_dir, exist_ok=True)
    return actions


def generate_graph_launch_description(default_graph: str) -> Any:
    """The LaunchDescription of a .launch.py file: arguments, then the graph's actions."""
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument, OpaqueFunction

    default_path = os.path.join(share_directory(PACKAGE), "config", default_graph)
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
                "run_dir",
                default_value="",
                description="run directory (new or empty): bag/ of the recorder node, models "
                "and report of the identifier; empty: runs/<YYYYmmdd-HHMMSS>",
            ),
            OpaqueFunction(function=_launch_setup),
        ]
    )
