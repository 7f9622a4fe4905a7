"""`colcon build` and `colcon test` work on the workspace (colcon-common-extensions, no ROS).

Without a sourced ROS the ament_cmake interface package builds against the venv's ROS 2 wheels,
as src/aero_rig_interfaces/build_in_venv.sh does: the venv is the ament prefix, and the wheels'
include folders are pointed at this Python's (cmake/wheel_include_dirs.cmake).
"""

import glob
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
INTERFACES = ROOT / "src" / "aero_rig_interfaces"
PACKAGES = [
    "aero_rig_interfaces",
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
    if args[0] == "build" and not os.environ.get("ROS_DISTRO"):
        libs = glob.glob(f"{sys.prefix}/lib/python*/site-packages/ros_*.libs")
        env.update(
            AMENT_PREFIX_PATH=sys.prefix,
            CMAKE_PREFIX_PATH=sys.prefix,
            LD_LIBRARY_PATH=":".join([f"{sys.prefix}/lib", *libs, env.get("LD_LIBRARY_PATH", "")]),
            _ROS_WHEELS_BOOTSTRAP_COMPLETE="1",
        )
        args = (
            *args,
            "--cmake-args",
            f"-DPython3_EXECUTABLE={sys.executable}",
            f"-DCMAKE_PROJECT_INCLUDE={INTERFACES / 'cmake' / 'wheel_include_dirs.cmake'}",
            "-DBUILD_TESTING=OFF",
        )
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
    # The interface package: its definitions and its Python types, as a ROS install has them.
    iface = tmp_path / "install" / "aero_rig_interfaces"
    assert (iface / "share" / "aero_rig_interfaces" / "srv" / "ControlExperiment.srv").exists()
    assert list(iface.glob("lib/python3*/site-packages/aero_rig_interfaces/msg/_segment_event.py"))
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
