"""What `make` says when the interface package cannot be built (build_in_venv.sh): one line
naming everything that is missing, exit code 2, before anything is installed or written."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "src" / "aero_rig_interfaces" / "build_in_venv.sh"
# What the script runs before it checks the prerequisites.
TOOLS = ("bash", "dirname", "basename", "sed", "sort", "head", "printf")


def _bin(tmp_path: Path, *, cmake: str | None, compiler: bool) -> Path:
    """A PATH folder with the shell tools, and a cmake and a compiler only where asked."""
    folder = tmp_path / "bin"
    folder.mkdir()
    for tool in TOOLS:
        found = shutil.which(tool)
        if found is not None:
            (folder / tool).symlink_to(found)
    if compiler:
        for tool in ("cc", "c++"):
            (folder / tool).symlink_to(shutil.which(tool) or "/bin/true")
    if cmake is not None:
        fake = folder / "cmake"
        fake.write_text(f"#!/bin/sh\necho 'cmake version {cmake}'\n")
        fake.chmod(0o755)
    return folder


def _venv(tmp_path: Path) -> Path:
    """A folder that looks like a venv to the script: its python is this interpreter."""
    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    (venv / "bin" / "python").symlink_to(sys.executable)
    return venv


def _run(tmp_path: Path, folder: Path) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("ROS_DISTRO",)}
    env["PATH"] = str(folder)
    return subprocess.run(
        [str(folder / "bash"), str(SCRIPT), str(_venv(tmp_path))],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )


@pytest.mark.parametrize(
    ("cmake", "compiler", "named"),
    [
        (None, True, "without cmake (Debian"),
        ("3.18.4", True, "without cmake >= 3.21 (this one: cmake version 3.18.4)"),
        ("3.25.1", False, "without a C/C++ compiler (Debian"),
        (None, False, "without cmake, a C/C++ compiler (Debian"),
    ],
)
def test_missing_prerequisites_are_named_in_one_line(
    tmp_path: Path, cmake: str | None, compiler: bool, named: str
) -> None:
    proc = _run(tmp_path, _bin(tmp_path, cmake=cmake, compiler=compiler))
    assert proc.returncode == 2, proc.stdout + proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("aero_rig_interfaces: cannot build the rig's messages"), lines
    assert named in lines[0] and "sudo apt install cmake g++ python3-dev" in lines[0], lines
    assert not (tmp_path / "venv" / "build").exists()  # nothing written before the check
