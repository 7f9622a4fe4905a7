"""Bad input is refused before any node starts (rig_runtime.launcher.check_node): a plan file
that does not load and a `-p NODE.PARAM:=VALUE` outside its declaration stop `aero-rig
campaign`, `aero-rig run` and `rig-launch` with exit code 2 and the very line the node itself
prints when started with that input, and no node process is started."""

import subprocess
import sys
from pathlib import Path

import pytest

from rig_testing.processes import graph_env

CONFIG = Path(__file__).resolve().parents[1] / "src" / "aero_rig" / "config"


def _run(args: list[str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, *args], env=graph_env(), capture_output=True, text=True, timeout=120
    )


def _node_line(executable: str, *ros_args: str) -> str:
    """The line the node prints when started with this input (its last line on stderr)."""
    proc = subprocess.run(
        [str(Path(sys.executable).parent / executable), "--ros-args", *ros_args],
        env=graph_env(),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2, proc.stdout + proc.stderr
    line = proc.stderr.strip().splitlines()[-1]
    assert line.startswith("[FATAL] ["), line
    return line


@pytest.fixture(scope="module")
def bad_plan(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("plan") / "bad.json"
    path.write_text('{"fs": 200.0, "segments": [')
    return path


def test_a_campaign_with_a_bad_plan_file_starts_no_node(bad_plan: Path, tmp_path: Path) -> None:
    run = tmp_path / "run"
    proc = _run(["-m", "aero_rig.cli", "campaign", "--plan", str(bad_plan), "--out", str(run)])
    assert proc.returncode == 2, proc.stdout + proc.stderr
    expected = _node_line("generator", "-p", f"plan:={bad_plan}")
    assert "not valid JSON" in expected, expected
    assert proc.stderr.strip().splitlines()[-1] == f"aero-rig: {expected}", proc.stderr
    assert not (run / "logs").exists() and "running on" not in proc.stdout + proc.stderr


@pytest.mark.parametrize(
    ("command", "executable", "ros_args"),
    [
        (["-m", "aero_rig.cli", "campaign", "-p", "generator.seed:=-4"], "generator",
         ["-p", "seed:=-4"]),
        (["-m", "aero_rig.cli", "run", "sim", "-p", "sim_wing.preset:=glider"], "sim_wing",
         ["-p", "preset:=glider"]),
        (["-m", "rig_runtime.launcher", str(CONFIG / "sim.yaml"), "-p", "identifier.nx:=-1"],
         "identifier", ["-p", "nx:=-1"]),
        (["-m", "rig_runtime.launcher", str(CONFIG / "sim.yaml"), "-p", "lift.no_such:=1"],
         "lift", ["-p", "no_such:=1"]),
    ],
    ids=["campaign", "run", "rig-launch", "rig-launch-unknown"],
)  # fmt: skip
def test_a_parameter_outside_its_declaration_starts_no_node(
    command: list[str], executable: str, ros_args: list[str], tmp_path: Path
) -> None:
    if command[1] == "aero_rig.cli" and command[2] == "campaign":
        command = [*command, "--out", str(tmp_path / "run")]
    proc = _run(command)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    expected = _node_line(executable, *ros_args)
    assert proc.stderr.strip().splitlines()[-1].endswith(expected), (expected, proc.stderr)
    assert "running on" not in proc.stdout + proc.stderr
    assert not (tmp_path / "run" / "logs").exists()
