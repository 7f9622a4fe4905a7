"""Graph descriptions: the single source of truth for which nodes run, and how.

The one model of a graph YAML: the launcher (rig-launch, aero-rig) and the ROS launch files
(aero_rig.launch_description) both read graphs through :func:`load_graph`. It imports only
pyyaml and the standard library, so a ``ros2 launch`` process can use it::

    name: sim
    nodes:
      - name: generator               # node name (-r __node:=...)
        package: multisine_gen        # ament package
        executable: generator         # console_scripts entry point of that package
        namespace: /                  # optional
        parameters: [generator.yaml]  # files: absolute, relative to the graph file,
                                      #   or package-relative "pkg://aero_rig/config/x.yaml"
        parameter_overrides: {real_time_factor: 0.0}
        remappings: {/pitch/command: /pitch/command}
        stops_graph: false            # true: when it exits (even with 0), the graph stops
        nice: 0                       # lower the CPU priority by 0..19, as `nice -n`
        barrier: member               # start barrier (barrier.py): lead | member | none
        host: rig                     # optional: the machine it runs on (see below)

The start barrier: the ``lead`` node (the generator) starts the experiment only when every
``member`` node (the default) has reported ready and matched on /graph/ready; the lead gets
their names as its ``barrier_nodes`` parameter. ``none``: a process that does not report
(not written on rig_runtime) and is not waited for.

A node that exits non-zero always stops the graph.

Hosts: a lab runs one graph on several machines (the hardware nodes on the rig PC, the
identification on a workstation). ``host`` names the machine a node runs on; ``rig-launch
--host NAME`` and ``aero-rig campaign --host NAME`` start only that machine's nodes, and the
start barrier still waits for every member, wherever it runs. A graph launched for named
hosts must place every node on one.
"""

import re
from collections.abc import Collection
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any

import yaml

BARRIER_ROLES = ("lead", "member", "none")
_HOST_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")


class GraphError(ValueError):
    """An invalid graph description."""


@dataclass(frozen=True)
class NodeSpec:
    name: str
    package: str
    executable: str
    namespace: str = "/"
    parameters: tuple[Path, ...] = ()
    parameter_overrides: dict[str, Any] = field(default_factory=dict)
    remappings: dict[str, str] = field(default_factory=dict)
    stops_graph: bool = False
    nice: int = 0
    barrier: str = "member"
    host: str = ""  # the machine it runs on ("": not placed; only a whole-graph launch runs it)

    def on(self, hosts: Collection[str] | None) -> bool:
        """Whether a launcher started for ``hosts`` (None: every host) starts this node."""
        return hosts is None or self.host in hosts

    @property
    def fq_name(self) -> str:
        prefix = "" if self.namespace in ("", "/") else "/" + self.namespace.strip("/")
        return f"{prefix}/{self.name}"

    def ros_arguments(self, extra_overrides: dict[str, Any] | None = None) -> list[str]:
        """The ``--ros-args`` section ``ros2 run`` would pass for this node."""
        args = ["--ros-args", "-r", f"__node:={self.name}"]
        if self.namespace not in ("", "/"):
            args += ["-r", f"__ns:={self.namespace}"]
        for src, dst in self.remappings.items():
            args += ["-r", f"{src}:={dst}"]
        for path in self.parameters:
            args += ["--params-file", str(path)]
        overrides = {**self.parameter_overrides, **(extra_overrides or {})}
        for key, value in overrides.items():
            args += ["-p", f"{key}:={yaml_scalar(value)}"]
        return args


def yaml_scalar(value: Any) -> str:
    """A value as ``-p NAME:=VALUE`` gives it: one line of YAML."""
    text = yaml.safe_dump(value, default_flow_style=True).strip()
    return text.removesuffix("\n...").removesuffix("...").strip()


@dataclass(frozen=True)
class GraphSpec:
    name: str
    nodes: tuple[NodeSpec, ...]
    source: Path | None = None

    def barrier_overrides(self) -> dict[str, dict[str, Any]]:
        """``{lead: {"barrier_nodes": [member FQNs]}}``: what the start barrier waits for."""
        members = [n.fq_name for n in self.nodes if n.barrier == "member"]
        return {n.name: {"barrier_nodes": members} for n in self.nodes if n.barrier == "lead"}

    @property
    def hosts(self) -> tuple[str, ...]:
        """The named hosts, in the order their first node is listed."""
        return tuple(dict.fromkeys(n.host for n in self.nodes if n.host))

    def check_hosts(self, hosts: Collection[str]) -> None:
        """GraphError unless every name in ``hosts`` is a host of this graph and every node is
        placed on a host (a node on no host would run on none, or on each)."""
        unknown = sorted(set(hosts) - set(self.hosts))
        if unknown:
            known = ", ".join(self.hosts) or "none"
            raise GraphError(f"graph {self.name!r} has no host {unknown[0]!r} (its hosts: {known})")
        unplaced = [n.name for n in self.nodes if not n.host]
        if unplaced:
            raise GraphError(
                f"graph {self.name!r} places no host for {', '.join(unplaced)}: give each node "
                "a 'host' to launch it by hosts"
            )

    def node(self, name: str) -> NodeSpec:
        for n in self.nodes:
            if n.name == name:
                return n
        raise KeyError(f"graph {self.name!r} has no node {name!r}")


def package_share(package: str) -> Path:
    """The package's share directory (config/, launch/): ament index, install or source tree."""
    try:
        from ament_index_python.packages import get_package_share_directory

        return Path(get_package_share_directory(package))
    except Exception:
        pass
    try:
        module = __import__(package)
    except ImportError as exc:
        raise GraphError(f"package {package!r} is not installed") from exc
    source = Path(module.__file__ or "").resolve().parent.parent
    if (source / "package.xml").exists():  # editable install: src/<pkg>/
        return source
    import sys

    installed = Path(sys.prefix) / "share" / package
    if installed.exists():
        return installed
    raise GraphError(f"cannot find the share directory of package {package!r}")


def resolve_path(text: str, base: Path | None) -> Path:
    if text.startswith("pkg://"):
        package, _, rest = text[len("pkg://") :].partition("/")
        return package_share(package) / rest
    path = Path(text).expanduser()
    if not path.is_absolute() and base is not None:
        path = base / path
    return path


def entry_point(package: str, executable: str) -> str:
    """``module:function`` of a package's console_scripts entry point."""
    try:
        dist = metadata.distribution(package)
    except metadata.PackageNotFoundError:
        raise GraphError(f"package {package!r} is not installed") from None
    names = []
    for ep in dist.entry_points:
        if ep.group == "console_scripts":
            names.append(ep.name)
            if ep.name == executable:
                return ep.value
    raise GraphError(
        f"package {package!r} has no executable {executable!r}; it has: {sorted(names)}"
    )


def load_graph(path: str | Path) -> GraphSpec:
    path = Path(path)
    try:
        document = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise GraphError(f"cannot read graph {path}: {exc}") from exc
    return parse_graph(document, path.parent, source=path)


def parse_graph(document: Any, base: Path | None = None, source: Path | None = None) -> GraphSpec:
    if not isinstance(document, dict) or not isinstance(document.get("nodes"), list):
        raise GraphError(f"{source or 'graph'}: expected a mapping with a 'nodes' list")
    nodes = []
    seen = set()
    for i, item in enumerate(document["nodes"]):
        where = f"{source or 'graph'}: nodes[{i}]"
        if not isinstance(item, dict):
            raise GraphError(f"{where}: expected a mapping")
        unknown = set(item) - {
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
            "host",
        }
        if unknown:
            raise GraphError(f"{where}: unknown keys {sorted(unknown)}")
        for key in ("name", "package", "executable"):
            if not isinstance(item.get(key), str) or not item[key]:
                raise GraphError(f"{where}: '{key}' (a non-empty string) is required")
        if item["name"] in seen:
            raise GraphError(f"{where}: duplicate node name {item['name']!r}")
        seen.add(item["name"])
        nice = item.get("nice", 0)
        if isinstance(nice, bool) or not isinstance(nice, int) or not 0 <= nice <= 19:
            raise GraphError(f"{where} ({item['name']}): 'nice' must be an integer 0..19")
        barrier = item.get("barrier", "member")
        if barrier not in BARRIER_ROLES:
            raise GraphError(
                f"{where} ({item['name']}): 'barrier' must be one of {', '.join(BARRIER_ROLES)}"
            )
        host = item.get("host", "")
        if not isinstance(host, str) or (host and not _HOST_NAME.fullmatch(host)):
            raise GraphError(
                f"{where} ({item['name']}): 'host' must be a name of letters, digits, '_' or '-'"
            )
        params = tuple(resolve_path(str(p), base) for p in item.get("parameters") or [])
        for p in params:
            if not p.exists():
                raise GraphError(f"{where} ({item['name']}): parameter file {p} does not exist")
        nodes.append(
            NodeSpec(
                name=item["name"],
                package=item["package"],
                executable=item["executable"],
                namespace=item.get("namespace") or "/",
                parameters=params,
                parameter_overrides=dict(item.get("parameter_overrides") or {}),
                remappings={str(k): str(v) for k, v in (item.get("remappings") or {}).items()},
                stops_graph=bool(item.get("stops_graph", False)),
                nice=nice,
                barrier=barrier,
                host=host,
            )
        )
    leads = [n.name for n in nodes if n.barrier == "lead"]
    if len(leads) > 1:
        raise GraphError(f"{source or 'graph'}: more than one barrier lead: {leads}")
    return GraphSpec(name=str(document.get("name", "graph")), nodes=tuple(nodes), source=source)
