"""launch/sim.launch.py and launch/rig.launch.py, without ROS.

launch, launch_ros and ament_index_python cannot be installed here, so minimal stand-ins are
put into sys.modules: each records how it was constructed. The launch files are imported from
their paths as `ros2 launch` does, generate_launch_description() is called, the graph-reading
OpaqueFunction is run with the launch arguments, and the recorded actions are compared with
the graph YAML as rig_runtime.graph.load_graph reads it.
"""

import contextlib
import importlib
import importlib.util
import io
import re
import subprocess
import sys
import types
from pathlib import Path
from typing import Any

import pytest
import yaml

from rig_runtime.graph import GraphError, entry_point, load_graph
from rig_runtime.interface import IDENTIFICATION_MODEL, PITCH_COMMAND, WING_COEFFICIENTS

PACKAGE_DIR = Path(__file__).resolve().parents[1]
LAUNCH = PACKAGE_DIR / "launch"
CONFIG = PACKAGE_DIR / "config"
LAUNCH_FILES = {"sim.launch.py": "sim.yaml", "rig.launch.py": "rig.yaml"}


class Recorded:
    """Base of the stand-ins: keeps the constructor's arguments."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.args = args
        self.kwargs = kwargs


class LaunchDescription(Recorded):
    @property
    def entities(self) -> list[Any]:
        return list(self.args[0])


class DeclareLaunchArgument(Recorded):
    @property
    def name(self) -> str:
        return self.args[0]


class OpaqueFunction(Recorded):
    pass


class ExecuteProcess(Recorded):
    pass


class Shutdown(Recorded):
    pass


class IfCondition(Recorded):
    pass


class LaunchConfiguration(Recorded):
    def perform(self, context: Any) -> str:
        return context.launch_configurations[self.args[0]]


class Node(Recorded):
    pass


class Context:
    def __init__(self, configurations: dict[str, str]) -> None:
        self.launch_configurations = configurations


class Exited:
    def __init__(self, returncode: int) -> None:
        self.returncode = returncode


def get_package_share_directory(package: str) -> str:
    """Editable installs: the source package directory (what colcon installs as share/)."""
    try:
        module = importlib.import_module(package)
    except ImportError:
        raise LookupError(f"package {package!r} not found") from None
    assert module.__file__ is not None, package  # a regular package, not a namespace
    source = Path(module.__file__).resolve().parent.parent
    assert (source / "package.xml").is_file(), source
    return str(source)


@pytest.fixture
def ros_stubs(monkeypatch: pytest.MonkeyPatch) -> None:
    modules: dict[str, dict[str, Any]] = {
        "launch": {"LaunchDescription": LaunchDescription},
        "launch.actions": {
            "DeclareLaunchArgument": DeclareLaunchArgument,
            "OpaqueFunction": OpaqueFunction,
            "ExecuteProcess": ExecuteProcess,
            "Shutdown": Shutdown,
        },
        "launch.conditions": {"IfCondition": IfCondition},
        "launch.substitutions": {"LaunchConfiguration": LaunchConfiguration},
        "launch_ros": {},
        "launch_ros.actions": {"Node": Node},
        "ament_index_python": {},
        "ament_index_python.packages": {"get_package_share_directory": get_package_share_directory},
    }
    for name, attributes in modules.items():
        module = types.ModuleType(name)
        module.__dict__.update(attributes)
        monkeypatch.setitem(sys.modules, name, module)


def _description(launch_file: str) -> LaunchDescription:
    path = LAUNCH / launch_file
    spec = importlib.util.spec_from_file_location(f"launch_file_{path.stem}", path)
    assert spec is not None and spec.loader is not None, path
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.generate_launch_description()


def _launch(launch_file: str, **arguments: str) -> list[Any]:
    """The actions `ros2 launch aero_rig <launch_file> name:=value ...` would run.

    Pass run_dir (a tmp_path): the launch setup creates it.
    """
    description = _description(launch_file)
    declared = [e for e in description.entities if isinstance(e, DeclareLaunchArgument)]
    configurations = {a.name: a.kwargs["default_value"] for a in declared}
    unknown = set(arguments) - set(configurations)
    assert not unknown, f"undeclared launch arguments {unknown}"
    configurations.update(arguments)
    (opaque,) = [e for e in description.entities if isinstance(e, OpaqueFunction)]
    return list(opaque.kwargs["function"](Context(configurations)))


def _nodes(actions: list[Any]) -> dict[str, Node]:
    nodes = [a for a in actions if isinstance(a, Node)]
    by_name = {n.kwargs["name"]: n for n in nodes}
    assert len(by_name) == len(nodes), "duplicate node names"
    return by_name


def _bag_record(actions: list[Any]) -> ExecuteProcess:
    (record,) = [a for a in actions if isinstance(a, ExecuteProcess) and not isinstance(a, Node)]
    return record


@pytest.mark.usefixtures("ros_stubs")
@pytest.mark.parametrize(("launch_file", "graph"), LAUNCH_FILES.items())
def test_launch_arguments(launch_file: str, graph: str) -> None:
    declared = {
        e.name: e.kwargs
        for e in _description(launch_file).entities
        if isinstance(e, DeclareLaunchArgument)
    }
    assert set(declared) == {"graph", "host", "record", "run_dir"}
    assert declared["host"]["default_value"] == ""
    assert Path(declared["graph"]["default_value"]) == CONFIG / graph
    assert declared["record"]["default_value"] == "false"
    assert all(kwargs["description"] for kwargs in declared.values())


@pytest.mark.usefixtures("ros_stubs")
@pytest.mark.parametrize(("launch_file", "graph"), LAUNCH_FILES.items())
def test_one_node_per_graph_node(launch_file: str, graph: str, tmp_path: Path) -> None:
    spec = load_graph(CONFIG / graph)
    run = tmp_path / "run7"
    nodes = _nodes(_launch(launch_file, run_dir=str(run)))
    assert run.is_dir()
    assert list(nodes) == [n.name for n in spec.nodes]
    for expected in spec.nodes:
        node = nodes[expected.name].kwargs
        assert (node["package"], node["executable"]) == (expected.package, expected.executable)
        assert node["namespace"] is None  # the root namespace
        files = [p for p in node["parameters"] if not isinstance(p, dict)]
        assert [Path(f) for f in files] == list(expected.parameters)
        assert files and all(Path(f).is_file() for f in files)
        overrides = [p for p in node["parameters"] if isinstance(p, dict)]
        if expected.executable == "recorder":
            assert overrides == [{**expected.parameter_overrides, "output": str(run / "bag")}]
        elif expected.executable == "identifier":
            assert overrides == [{**expected.parameter_overrides, "output_dir": str(run)}]
        else:
            # The start barrier's lead waits for every member, as rig-launch tells it.
            wanted = {
                **expected.parameter_overrides,
                **spec.barrier_overrides().get(expected.name, {}),
            }
            assert overrides == ([wanted] if wanted else [])
            if expected.barrier == "lead":
                assert wanted["barrier_nodes"] == [
                    n.fq_name for n in spec.nodes if n.barrier == "member"
                ]
        assert node["remappings"] == list(expected.remappings.items())


@pytest.mark.usefixtures("ros_stubs")
@pytest.mark.parametrize(("launch_file", "graph"), LAUNCH_FILES.items())
def test_host_launches_only_that_machines_nodes(
    launch_file: str, graph: str, tmp_path: Path
) -> None:
    spec = load_graph(CONFIG / graph)
    rig = _nodes(_launch(launch_file, run_dir=str(tmp_path / "rig"), host="rig"))
    assert list(rig) == [n.name for n in spec.nodes if n.host == "rig"]
    assert "identifier" not in rig and "generator" in rig
    # the lead's barrier still names the workstation's members
    (lead,) = [n for n in spec.nodes if n.barrier == "lead"]
    (overrides,) = [p for p in rig[lead.name].kwargs["parameters"] if isinstance(p, dict)]
    assert "/identifier" in overrides["barrier_nodes"]
    both = _nodes(_launch(launch_file, run_dir=str(tmp_path / "both"), host="rig, workstation"))
    assert list(both) == [n.name for n in spec.nodes]
    with pytest.raises(GraphError, match="no host 'tunnel'"):
        _launch(launch_file, run_dir=str(tmp_path / "bad"), host="tunnel")


@pytest.mark.parametrize(
    ("package", "executable"),
    sorted(
        {
            (n.package, n.executable)
            for g in LAUNCH_FILES.values()
            for n in load_graph(CONFIG / g).nodes
        }
    ),
)
def test_launched_executables_are_console_scripts(package: str, executable: str) -> None:
    # colcon installs console_scripts to lib/<package>/<name>: what launch_ros Node runs.
    target = entry_point(package, executable)  # GraphError if the package lacks it
    module, _, func = target.partition(":")
    main = getattr(importlib.import_module(module), func)
    # It is a node's main: its --help names it and takes the ROS arguments launch_ros passes.
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["--help"])
    assert code == 0, out.getvalue()
    assert out.getvalue().startswith(f"usage: {executable} [--ros-args"), out.getvalue()


@pytest.mark.usefixtures("ros_stubs")
@pytest.mark.parametrize(("launch_file", "graph"), LAUNCH_FILES.items())
def test_stops_graph_and_failures_shut_the_launch_down(
    launch_file: str, graph: str, tmp_path: Path
) -> None:
    spec = load_graph(CONFIG / graph)
    nodes = _nodes(_launch(launch_file, run_dir=str(tmp_path / "run")))
    assert any(n.stops_graph for n in spec.nodes)
    for expected in spec.nodes:
        on_exit = nodes[expected.name].kwargs["on_exit"]
        (failed,) = on_exit(Exited(1), None)
        assert isinstance(failed, Shutdown) and expected.name in failed.kwargs["reason"]
        finished = on_exit(Exited(0), None)
        if expected.stops_graph:
            assert len(finished) == 1 and isinstance(finished[0], Shutdown)
        else:
            assert not finished


@pytest.mark.usefixtures("ros_stubs")
@pytest.mark.parametrize(("launch_file", "graph"), LAUNCH_FILES.items())
def test_record_adds_a_conditional_ros2_bag_record(
    launch_file: str, graph: str, tmp_path: Path
) -> None:
    record = _bag_record(_launch(launch_file, run_dir=str(tmp_path / "run3")))
    condition = record.kwargs["condition"]
    assert isinstance(condition, IfCondition)
    (predicate,) = condition.args
    assert isinstance(predicate, LaunchConfiguration) and predicate.args == ("record",)
    cmd = record.kwargs["cmd"]
    assert cmd[:3] == ["ros2", "bag", "record"]
    assert cmd[cmd.index("-s") + 1] == "mcap"
    assert cmd[cmd.index("-o") + 1] == str(tmp_path / "run3" / "rosbag2")
    recorder_file = yaml.safe_load((CONFIG / "recorder.yaml").read_text())
    topics = recorder_file["recorder"]["ros__parameters"]["topics"]
    assert cmd[cmd.index("-o") + 2 :] == topics
    assert WING_COEFFICIENTS.name in topics and IDENTIFICATION_MODEL.name in topics


@pytest.mark.usefixtures("ros_stubs")
def test_default_run_dir_is_new_per_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    actions = _launch("rig.launch.py")
    output = Path(_nodes(actions)["recorder"].kwargs["parameters"][-1]["output"])
    (run,) = (tmp_path / "runs").iterdir()
    assert output == run / "bag"
    assert re.fullmatch(r"\d{8}-\d{6}", run.name)
    assert _bag_record(actions).kwargs["cmd"][6] == str(run / "rosbag2")


@pytest.mark.usefixtures("ros_stubs")
def test_a_used_run_dir_is_refused(tmp_path: Path) -> None:

    (tmp_path / "models.json").write_text("{}")
    with pytest.raises(GraphError, match="not empty"):
        _launch("sim.launch.py", run_dir=str(tmp_path))


@pytest.mark.usefixtures("ros_stubs")
def test_graph_argument_picks_another_graph_by_name(tmp_path: Path) -> None:
    nodes = _nodes(_launch("sim.launch.py", graph="rig", run_dir=str(tmp_path / "run")))
    assert list(nodes) == [n.name for n in load_graph(CONFIG / "rig.yaml").nodes]


@pytest.mark.usefixtures("ros_stubs")
def test_graph_argument_runs_any_graph_file(tmp_path: Path) -> None:
    """The launch files hold no node list: whatever the YAML says is launched."""
    (tmp_path / "talker.yaml").write_text("talker:\n  ros__parameters:\n    use_sim_time: false\n")
    graph = {
        "name": "demo",
        "nodes": [
            {
                "name": "talker",
                "package": "rig_testing",
                "executable": "talker",
                "namespace": "/bench",
                "parameters": ["talker.yaml", "pkg://aero_rig/config/lift.yaml"],
                "parameter_overrides": {"rate_hz": 5.0},
                "remappings": {"/chatter": "/bench/chatter"},
                "stops_graph": True,
            }
        ],
    }
    (tmp_path / "demo.yaml").write_text(yaml.safe_dump(graph))
    actions = _launch(
        "rig.launch.py", graph=str(tmp_path / "demo.yaml"), run_dir=str(tmp_path / "r")
    )
    node = _nodes(actions)["talker"].kwargs
    assert node["namespace"] == "/bench"
    assert node["parameters"] == [
        str(tmp_path / "talker.yaml"),
        str(CONFIG / "lift.yaml"),
        {"rate_hz": 5.0},
    ]
    assert node["remappings"] == [("/chatter", "/bench/chatter")]
    assert isinstance(node["on_exit"](Exited(0), None)[0], Shutdown)
    # No recorder in this graph: record:=true falls back to the docs/design.md §4 topics.
    assert PITCH_COMMAND.name in _bag_record(actions).kwargs["cmd"]


@pytest.mark.usefixtures("ros_stubs")
def test_bad_graphs_are_refused_with_a_reason(tmp_path: Path) -> None:

    run = str(tmp_path / "run")
    with pytest.raises(GraphError, match="cannot run under ros2 launch: the Rerun view"):
        _launch("sim.launch.py", graph="live_view", run_dir=run)
    with pytest.raises(GraphError, match="not found"):
        _launch("sim.launch.py", graph="no_such_graph", run_dir=run)
    (tmp_path / "typo.yaml").write_text(
        "nodes:\n  - {name: lift, package: pressure_scanner, executable: lift,"
        " parameters: [lfit.yaml]}\n"
    )
    with pytest.raises(GraphError, match=r"parameter file .* does not exist"):
        _launch("sim.launch.py", graph=str(tmp_path / "typo.yaml"), run_dir=run)
    assert not (tmp_path / "run").exists(), "a refused graph must not leave a run directory"


def test_launch_module_imports_no_middleware_and_no_rerun() -> None:
    """The `ros2 launch` process imports rclpy: it must not load the venv's DDS or rerun.

    Of rig_runtime it may load only the light modules: the package (lazy), the graph model
    and the interface contract, which import the standard library and pyyaml.
    """
    light = ("rig_runtime", "rig_runtime.graph", "rig_runtime.interface")
    code = (
        "import sys, aero_rig.launch_description\n"
        f"light = {light!r}\n"
        "bad = sorted(m for m in sys.modules if m not in light and m.split('.')[0] in"
        " ('rig_runtime', 'rosbags', 'rerun', 'numpy', 'rclpy'))\n"
        "print(bad); sys.exit(1 if bad else 0)\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0, result.stdout + result.stderr


@pytest.mark.usefixtures("ros_stubs")
@pytest.mark.parametrize(("launch_file", "graph"), LAUNCH_FILES.items())
def test_nice_becomes_a_nice_prefix(launch_file: str, graph: str, tmp_path: Path) -> None:
    nodes = _nodes(_launch(launch_file, run_dir=str(tmp_path / "run")))
    spec = load_graph(CONFIG / graph)
    assert any(n.nice for n in spec.nodes)  # both shipped graphs set priorities
    for expected in spec.nodes:
        prefix = nodes[expected.name].kwargs.get("prefix")
        assert prefix == (f"nice -n {expected.nice}" if expected.nice else None)
