"""The graph descriptions and parameter files in aero_rig/config.

Every parameter file must be accepted by the node it configures: each key a declared parameter
of that node, each value in range (rig_runtime.params.resolve_parameters with the node's
PARAMETERS), each section actually applied (resolve_parameters silently skips a section whose
node name does not match, so that is checked here too), and writable by ROS 2's own parser.
Every graph must load with rig_runtime.graph.load_graph and name executables that exist.
"""

import contextlib
import importlib
import io
import re
from pathlib import Path
from typing import Any

import pytest
import yaml

from rig_runtime.graph import NodeSpec, entry_point, load_graph
from rig_runtime.interface import RECORDED_TOPICS, ActuatorLimits
from rig_runtime.params import Parameter, ParameterError, resolve_parameters

CONFIG = Path(__file__).resolve().parents[1] / "config"
GRAPHS = ("sim.yaml", "rig.yaml", "live_view.yaml")
# Values deliberately different from the node's default in the shared files (file, key).
NOT_DEFAULT = {
    ("recorder.yaml", "topics"),  # the docs/design.md §4 topics instead of everything
    ("view.yaml", "mode"),  # a live view opens a viewer (the node's default only saves)
}


def _yaml(path: Path) -> Any:
    return yaml.safe_load(path.read_text())


def _graph_nodes() -> list[tuple[str, NodeSpec]]:
    return [(g, n) for g in GRAPHS for n in load_graph(CONFIG / g).nodes]


def _node_id(item: tuple[str, NodeSpec]) -> str:
    return f"{item[0]}:{item[1].name}"


def _declared(spec: NodeSpec) -> list[Parameter]:
    """The PARAMETERS of the module behind the node's console_scripts entry point."""
    module, _, _ = entry_point(spec.package, spec.executable).partition(":")
    return importlib.import_module(module).PARAMETERS


def _overrides(spec: NodeSpec) -> list[tuple[str, str]]:
    # As `-p name:=value`, the way rig-launch passes graph overrides.
    return [
        (k, yaml.safe_dump(v, default_flow_style=True).strip().removesuffix("\n..."))
        for k, v in spec.parameter_overrides.items()
    ]


def _resolve(spec: NodeSpec, files: tuple[Path, ...] | None = None) -> Any:
    fq_name = f"{'' if spec.namespace == '/' else spec.namespace}/{spec.name}"
    return resolve_parameters(
        _declared(spec), fq_name, spec.parameters if files is None else files, _overrides(spec)
    )


def _sections(path: Path) -> dict[str, dict[str, Any]]:
    return {str(k): (v or {}).get("ros__parameters") or {} for k, v in _yaml(path).items()}


def _parameter_files() -> list[Path]:
    return sorted(p for p in CONFIG.glob("*.yaml") if p.name not in GRAPHS)


def test_config_holds_only_graphs_and_ros2_parameter_files() -> None:
    graphs = {p.name for p in CONFIG.glob("*.yaml") if "nodes" in (_yaml(p) or {})}
    assert graphs == set(GRAPHS)
    for path in _parameter_files():
        document = _yaml(path)
        assert isinstance(document, dict) and document, path.name
        for key, block in document.items():
            assert isinstance(block, dict) and set(block) == {"ros__parameters"}, (
                f"{path.name}: section {key!r} is not `node_name: ros__parameters: {{...}}`"
            )
            assert isinstance(block["ros__parameters"], dict) and block["ros__parameters"], (
                f"{path.name}: section {key!r} is empty"
            )


def test_every_parameter_file_is_used_by_a_graph_and_every_section_applies() -> None:
    users: dict[Path, set[str]] = {}
    for _graph, spec in _graph_nodes():
        for path in spec.parameters:
            users.setdefault(path.resolve(), set()).add(spec.name)
    for path in _parameter_files():
        assert path.resolve() in users, f"{path.name} is used by no graph"
        for section in _sections(path):
            # A section named after no node of a graph that lists the file is silently ignored.
            assert section in users[path.resolve()] | {"/**"}, (
                f"{path.name}: section {section!r} matches none of {sorted(users[path.resolve()])}"
            )


@pytest.mark.parametrize("graph", GRAPHS)
def test_graph_loads_and_its_parameter_files_exist(graph: str) -> None:
    spec = load_graph(CONFIG / graph)
    assert spec.name == Path(graph).stem
    assert spec.nodes
    for node in spec.nodes:
        for path in node.parameters:
            assert path.is_file() and path.parent.resolve() == CONFIG.resolve(), path


@pytest.mark.parametrize("item", _graph_nodes(), ids=_node_id)
def test_graph_node_executable_exists(item: tuple[str, NodeSpec]) -> None:
    _graph, spec = item
    target = entry_point(spec.package, spec.executable)  # GraphError if the package lacks it
    module, _, func = target.partition(":")
    main = getattr(importlib.import_module(module), func)
    # The node's own --help: what `ros2 run PACKAGE EXECUTABLE --help` prints, with the
    # parameters this graph's files set.
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["--help"])
    assert code == 0, out.getvalue()
    assert all(p.name in out.getvalue() for p in _declared(spec)), out.getvalue()


@pytest.mark.parametrize("item", _graph_nodes(), ids=_node_id)
def test_parameter_files_are_accepted_and_applied_by_their_node(
    item: tuple[str, NodeSpec],
) -> None:
    _graph, spec = item
    params = _resolve(spec)  # raises ParameterError on an unknown key or a bad value
    for path in spec.parameters:
        sections = _sections(path)
        assert spec.name in sections or "/**" in sections, (
            f"{path.name} has no section for node {spec.name!r}: it would be ignored"
        )
        for key, value in {**sections.get("/**", {}), **sections.get(spec.name, {})}.items():
            if key == "use_sim_time":  # every ROS 2 node accepts it; rig_runtime ignores it
                continue
            later = spec.parameters[spec.parameters.index(path) + 1 :]
            if params.sources[key] == str(path):
                assert params[key] == value
            else:  # overridden by a later file of the same node
                assert params.sources[key] in {str(p) for p in later}, (key, params.sources[key])


def test_a_misspelt_key_fails(tmp_path: Path) -> None:
    spec = load_graph(CONFIG / "sim.yaml").node("generator")
    text = (CONFIG / "generator.yaml").read_text().replace("max_lead_samples:", "max_lead_sample:")
    (tmp_path / "generator.yaml").write_text(text)
    with pytest.raises(ParameterError, match="unknown parameter 'max_lead_sample'"):
        _resolve(spec, (tmp_path / "generator.yaml",))


def test_an_out_of_range_value_fails(tmp_path: Path) -> None:
    spec = load_graph(CONFIG / "sim.yaml").node("sim_actuator")
    text = (
        (CONFIG / "sim_actuator.yaml").read_text().replace("damping_ratio: 0.7", "damping_ratio: 0")
    )
    (tmp_path / "sim_actuator.yaml").write_text(text)
    with pytest.raises(ParameterError, match="damping_ratio"):
        _resolve(spec, (tmp_path / "sim_actuator.yaml",))


@pytest.mark.parametrize("item", _graph_nodes(), ids=_node_id)
def test_shared_files_hold_the_node_defaults(item: tuple[str, NodeSpec]) -> None:
    """A node default changed in code must not be silently pinned to its old value here."""
    _graph, spec = item
    declared = {p.name: p for p in _declared(spec)}
    shared = [p for p in spec.parameters if not p.stem.endswith("_rig")]  # _rig: per-graph
    assert shared, f"{spec.name} has no shared parameter file"
    keys = [k for path in shared for k in _sections(path).get(spec.name, {})]
    assert keys, f"no shared file has a section for {spec.name}: nothing here is checked"
    for path in shared:
        for key, value in _sections(path).get(spec.name, {}).items():
            if key == "use_sim_time" or (path.name, key) in NOT_DEFAULT:
                continue
            default = declared[key].validate(declared[key].default, "default")
            assert declared[key].validate(value, path.name) == default, (
                f"{path.name}: {key} = {value!r}, the node's default is {default!r}; "
                "update the file or list the deliberate difference in NOT_DEFAULT"
            )


@pytest.mark.parametrize("item", _graph_nodes(), ids=_node_id)
def test_values_are_typed_for_the_ros2_parameter_parser(item: tuple[str, NodeSpec]) -> None:
    """rcl's YAML parser types values from their spelling and cannot type an empty list."""
    _graph, spec = item
    declared = {p.name: p for p in _declared(spec)}
    values = [v for path in spec.parameters for v in _sections(path).get(spec.name, {})]
    assert values, f"no parameter file of {spec.name} sets a value: nothing here is checked"
    for path in spec.parameters:
        for key, value in _sections(path).get(spec.name, {}).items():
            where = f"{path.name}: {key}"
            assert value is not None, f"{where} has no value"
            if isinstance(value, list):
                assert value, f"{where} is an empty list"
                assert len({type(v) for v in value}) == 1, f"{where} mixes element types"
            if key in declared and declared[key].value_type is float:
                values = value if isinstance(value, list) else [value]
                assert all(isinstance(v, float) for v in values), f"{where}: write a float (1.0)"


def test_every_key_is_commented() -> None:
    key_line = re.compile(r"^ {4}(\w+):")
    for path in _parameter_files():
        lines = path.read_text().splitlines()
        for i, line in enumerate(lines):
            match = key_line.match(line)
            if not match:
                continue
            above = lines[i - 1].strip()
            assert "#" in line or above.startswith("#"), (
                f"{path.name}:{i + 1}: {match.group(1)} has no comment (meaning and unit)"
            )


def test_every_copy_of_the_actuator_limits_holds_the_contracts_defaults() -> None:
    """The limits are declared once (rig_runtime.interface.ActuatorLimits); the parameter files
    of the generator and of both actuators repeat them, and must repeat them unchanged."""
    defaults = ActuatorLimits().as_dict()
    copies = [
        (path.name, section, key, value)
        for path in _parameter_files()
        for section, values in _sections(path).items()
        for key, value in values.items()
        if key in defaults
    ]
    holders = {(name, section) for name, section, _, _ in copies}
    assert {
        ("generator.yaml", "generator"),
        ("sim_actuator.yaml", "sim_actuator"),
        ("hw_actuator.yaml", "hw_actuator"),
    } <= holders, holders
    for name, section, key, value in copies:
        assert isinstance(value, float) and value == defaults[key], (
            f"{name}: {section}.{key} = {value!r}, rig_runtime.interface.ActuatorLimits has "
            f"{defaults[key]!r}; change the limits there (one declaration), not in one file"
        )
    for name, section in holders:  # all three keys, never one alone
        keys = {key for n, s, key, _ in copies if (n, s) == (name, section)}
        assert keys == set(defaults), f"{name}: {section} sets only {sorted(keys)}"


@pytest.mark.parametrize("graph", ["sim.yaml", "rig.yaml"])
def test_generator_checks_the_plan_against_the_actuator_limits(graph: str) -> None:
    spec = load_graph(CONFIG / graph)
    actuator = next(n for n in spec.nodes if n.package == "pitch_actuator")
    generator = _resolve(spec.node("generator"))
    limits = _resolve(actuator)
    for key in ("min_deg", "max_deg", "max_rate_deg_s"):
        assert generator[key] == limits[key], key


def test_rig_generator_runs_in_real_time_without_flow_control() -> None:
    rig = _resolve(load_graph(CONFIG / "rig.yaml").node("generator"))
    assert rig["real_time_factor"] == 1.0
    assert rig["flow_control"] is False
    assert rig["plan"] == "default"
    sim = _resolve(load_graph(CONFIG / "sim.yaml").node("generator"))
    assert sim["flow_control"] is True


@pytest.mark.parametrize(
    ("graph", "publishers"),
    [
        ("sim.yaml", {"sim_actuator": "state_qos", "sim_wing": "taps_qos"}),
        ("rig.yaml", {"hw_actuator": "state_qos", "scanner": "taps_qos"}),
    ],
)
def test_lift_qos_matches_its_publishers(graph: str, publishers: dict[str, str]) -> None:
    """A reliable reader never matches a best-effort writer (the rig's sensor QoS)."""
    spec = load_graph(CONFIG / graph)
    lift_qos = _resolve(spec.node("lift"))["qos"]
    for node, key in publishers.items():
        assert _resolve(spec.node(node))[key] == lift_qos, node


@pytest.mark.parametrize("graph", ["sim.yaml", "rig.yaml"])
def test_recorder_records_the_contracts_topics(graph: str) -> None:
    recorder = _resolve(load_graph(CONFIG / graph).node("recorder"))
    assert recorder["topics"] == [t.name for t in RECORDED_TOPICS]
    assert recorder["output"] == "", "the bag directory is chosen per run"


def test_the_rerun_view_is_not_in_the_ros_graphs() -> None:
    for graph in ("sim.yaml", "rig.yaml"):
        assert all(n.executable != "view" for n in load_graph(CONFIG / graph).nodes)
    (view,) = load_graph(CONFIG / "live_view.yaml").nodes
    assert (view.package, view.executable) == ("aero_rig", "view")
