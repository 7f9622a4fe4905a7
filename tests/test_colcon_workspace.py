"""`colcon build` and `colcon test` work on the workspace (colcon-common-extensions, no ROS)."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = [
    "rig_runtime",
    "rig_testing",
    "multisine_gen",
    "pitch_actuator",
    "pressure_scanner",
    "wing_sim",
    "aero_identification",
    "aero_rig",
]


def _colcon(tmp: Path, *args: str) -> subprocess.CompletedProcess[str]:
    colcon = shutil.which("colcon", path=str(Path(sys.executable).parent))
    if colcon is None:
        pytest.fail("colcon is not installed in the virtual environment (make test installs it)")
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}:{os.environ['PATH']}")
    common = [
        "--base-paths",
        str(ROOT / "src"),
        "--build-base",
        str(tmp / "build"),
        "--install-base",
        str(tmp / "install"),
    ]
    return subprocess.run(
        [colcon, "--log-base", str(tmp / "log"), *args[:1], *common, *args[1:]],
        cwd=tmp,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )


def test_colcon_build_and_test(tmp_path: Path) -> None:
    build = _colcon(tmp_path, "build")
    assert build.returncode == 0, build.stdout + build.stderr
    for pkg in PACKAGES:
        share = tmp_path / "install" / pkg / "share" / pkg
        assert (share / "package.xml").exists()
        assert (
            tmp_path
            / "install"
            / pkg
            / "share"
            / "ament_index"
            / "resource_index"
            / "packages"
            / pkg
        ).exists()
    assert (tmp_path / "install" / "rig_runtime" / "lib" / "rig_runtime" / "recorder").exists()
    # The unit tests that need no processes, run the way a ROS developer runs them.
    test = _colcon(
        tmp_path,
        "test",
        "--packages-select",
        "rig_runtime",
        "--pytest-args",
        "-k",
        "wire_format or parameters and not process",
    )
    assert test.returncode == 0, test.stdout + test.stderr
    result = subprocess.run(
        [
            str(Path(sys.executable).parent / "colcon"),
            "--log-base",
            str(tmp_path / "log"),
            "test-result",
            "--test-result-base",
            str(tmp_path / "build"),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 0, result.stdout
    assert "0 errors, 0 failures" in result.stdout
    assert "Summary: 0 tests" not in result.stdout
