"""Where rclpy does not import, the offline verbs work and every graph verb says, in one line,
how to get rclpy (docs/design.md §3.1).

A virtual environment is made from this one with everything but rclpy: each entry of this
venv's site-packages is linked into it except ``rclpy`` itself, so ``import rclpy`` fails there
as on a machine without the wheels (aarch64, CPython 3.14) and no sourced ROS 2. The verbs run
in it as a user runs them: ``aero-rig fit`` on records, ``aero-rig view BAG``, ``aero-rig bag
recover`` and, refused, ``aero-rig campaign``, ``aero-rig run`` and ``aero-rig view live``
(``rig-launch``'s refusal: test_rclpy_endpoints.py).
"""

import importlib.util
import os
import subprocess
import sys
import sysconfig
from pathlib import Path
from types import ModuleType

import pytest
from rosbags.rosbag2 import StoragePlugin


def _sibling(name: str) -> ModuleType:
    """A test module of this directory (its helpers), as pytest's importlib mode loads it."""
    spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name(f"{name}.py"))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


pytestmark = pytest.mark.slow  # a venv and four CLI processes, one a fit


def _env() -> dict[str, str]:
    """This environment without what a sourced ROS 2 puts on the import path."""
    return {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "AMENT_PREFIX_PATH")}


@pytest.fixture(scope="module")
def python_without_rclpy(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("no_rclpy")
    venv = root / "venv"
    base = getattr(sys, "_base_executable", sys.executable)
    subprocess.run([base, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    ours = Path(sysconfig.get_paths()["purelib"])
    python = venv / "bin" / "python"
    theirs = Path(
        subprocess.run(
            [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
            check=True,
            capture_output=True,
            text=True,
            timeout=60,
        ).stdout.strip()
    )
    for entry in ours.iterdir():
        if entry.name == "rclpy" or entry.name.startswith(("rclpy-", "ros_jazzy_rclpy")):
            continue
        (theirs / entry.name).symlink_to(entry)
    probe = subprocess.run(
        [str(python), "-c", "import rclpy"], capture_output=True, timeout=60, env=_env()
    )
    assert probe.returncode != 0, "rclpy still imports in the venv made without it"
    return python


def _aero_rig(python: Path, *args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    code = "import sys; from aero_rig.cli import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.run(
        [str(python), "-c", code, *args],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=cwd,
        env=_env(),
    )


def test_offline_verbs_work_without_rclpy(python_without_rclpy: Path, tmp_path: Path) -> None:
    bag = tmp_path / "run"
    _sibling("test_view").write_bag(bag, StoragePlugin.MCAP)
    viewed = _aero_rig(python_without_rclpy, "view", str(bag), "--save", "v.rrd", cwd=tmp_path)
    assert viewed.returncode == 0, viewed.stderr[-3000:]
    assert (tmp_path / "v.rrd").stat().st_size > 0
    recovered = _aero_rig(python_without_rclpy, "bag", "recover", str(bag), cwd=tmp_path)
    assert recovered.returncode == 0, recovered.stderr[-3000:]
    records = tmp_path / "levels"
    records.mkdir()
    for k, amplitude in ((1, 0.5), (2, 1.0)):
        _sibling("test_fit_records")._write_level(records / f"sys_Level{k}.csv", 0.2, amplitude, k)
    fitted = _aero_rig(
        python_without_rclpy,
        *("fit", str(records), "--format", "csv", "--input", "u", "--output", "y"),
        *("--period", "256", "--realizations", "2", "--degrees", "3", "--max-iter", "3"),
        *("--out", str(tmp_path / "fit")),
        cwd=tmp_path,
    )
    assert fitted.returncode == 0, fitted.stderr[-3000:]
    assert (tmp_path / "fit" / "models.json").stat().st_size > 0


@pytest.mark.parametrize(
    "args",
    [["campaign", "--plan", "short"], ["run", "sim"], ["view", "live"]],
    ids=["campaign", "run", "view_live"],
)
def test_graph_verbs_say_in_one_line_how_to_get_rclpy(
    python_without_rclpy: Path, tmp_path: Path, args: list[str]
) -> None:
    proc = _aero_rig(python_without_rclpy, *args, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    (line,) = proc.stderr.strip().splitlines()
    assert "rclpy does not import here" in line and "ROS 2 Jazzy" in line
    assert "robostack" in line and "aero-rig fit" in line
    assert not (tmp_path / "runs").exists()  # refused before anything was made
