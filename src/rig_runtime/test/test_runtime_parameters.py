"""Invalid parameters stop a node before it creates anything, naming the parameter."""

import subprocess
import sys
from pathlib import Path

import pytest

from rig_runtime.params import Parameter, ParameterError, resolve_parameters
from rig_testing.processes import graph_env

PARAMS = [
    Parameter("rate_hz", 200.0, "sample rate", min=1.0, max=1000.0),
    Parameter("count", 10, "messages", min=1),
    Parameter("mode", "sim", "mode", choices=("sim", "rig")),
    Parameter("gains", [1.0, 2.0], "gains", min=0.0),
]


def test_defaults_files_and_overrides_in_ros_order(tmp_path: Path) -> None:
    f = tmp_path / "p.yaml"
    f.write_text(
        "/**:\n  ros__parameters:\n    count: 5\nnode:\n  ros__parameters:\n    rate_hz: 100\n"
    )
    ps = resolve_parameters(PARAMS, "/node", [f], [("count", "7")])
    assert ps["rate_hz"] == 100.0 and isinstance(ps["rate_hz"], float)
    assert ps["count"] == 7
    assert ps["gains"] == [1.0, 2.0]


def test_exponents_without_a_dot_are_floats_as_rcl_reads_them(tmp_path: Path) -> None:
    """rcl reads ``1e2`` as a double, in a file and after ``-p``: so do the checks before a
    graph starts (PyYAML's YAML 1.1 alone would make it a string and refuse it)."""
    f = tmp_path / "p.yaml"
    f.write_text("node:\n  ros__parameters:\n    rate_hz: 1e2\n")
    for files, overrides in (([f], []), ([], [("rate_hz", "2.5E+2")])):
        for as_ros_args in (False, True):
            ps = resolve_parameters(PARAMS, "/node", files, overrides, as_ros_args=as_ros_args)
            assert ps["rate_hz"] in (100.0, 250.0) and isinstance(ps["rate_hz"], float)
    assert resolve_parameters(PARAMS, "/node", [], [("count", "5")])["count"] == 5


@pytest.mark.parametrize(
    ("override", "fragment"),
    [
        (("rate_hz", "5000"), "'rate_hz' = 5000"),
        (("rate_hz", "fast"), "'rate_hz' = 'fast'"),
        (("count", "1.5"), "'count' = 1.5"),
        (("mode", "hardware"), "one of ['sim', 'rig']"),
        (("gains", "[1.0, -1.0]"), "'gains'"),
        (("nonexistent", "1"), "unknown parameter 'nonexistent'"),
    ],
)
def test_invalid_values_are_named(override: tuple[str, str], fragment: str) -> None:
    with pytest.raises(ParameterError, match=None) as info:
        resolve_parameters(PARAMS, "/node", [], [override])
    assert fragment in str(info.value)


def test_unknown_name_in_yaml(tmp_path: Path) -> None:
    f = tmp_path / "p.yaml"
    f.write_text("node:\n  ros__parameters:\n    rate_hz: 10.0\n    typo_name: 3\n")
    with pytest.raises(ParameterError, match="unknown parameter 'typo_name'"):
        resolve_parameters(PARAMS, "/node", [f])


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["-p", "count:=-3"], "'count' = -3"),
        (["-p", "rate_hz:=abc"], "'rate_hz' = 'abc'"),
        (["-p", "bogus:=1"], "unknown parameter 'bogus'"),
    ],
)
def test_node_process_exits_nonzero_naming_parameter(args: list[str], fragment: str) -> None:
    code = "import sys; from rig_testing.talker import main; sys.exit(main())"
    proc = subprocess.run(
        [sys.executable, "-c", code, "--ros-args", *args],
        env=graph_env(),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert fragment in proc.stderr


def test_help_lists_parameters() -> None:
    code = "import sys; from rig_testing.talker import main; sys.exit(main())"
    proc = subprocess.run(
        [sys.executable, "-c", code, "--help"], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 0
    assert "rate_hz" in proc.stdout and "range [0, inf]" in proc.stdout


def test_launch_ros_parameter_files_with_tuples_are_read(tmp_path: Path) -> None:
    """launch_ros dumps a launch file's parameter dict with yaml.dump after turning lists into
    tuples; rclpy nodes read ``!!python/tuple`` as a list, and so must resolve_parameters."""
    import yaml

    path = tmp_path / "launch_params_x"
    path.write_text(yaml.dump({"/**": {"ros__parameters": {"names": ("/a", "/b")}}}))
    assert "!!python/tuple" in path.read_text()
    declared = [Parameter("names", [], "nodes", element_type=str)]
    assert resolve_parameters(declared, "/gen", [path]).values["names"] == ["/a", "/b"]
    path.write_text("/**:\n  ros__parameters:\n    names: !!python/object/apply:os.system [x]\n")
    with pytest.raises(ParameterError, match="not valid YAML"):
        resolve_parameters(declared, "/gen", [path])
