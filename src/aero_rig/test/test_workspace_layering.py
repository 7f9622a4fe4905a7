"""The workspace's layering, read from the source (docs/design.md §2).

- A package imports another workspace package only if its package.xml declares it
  (``exec_depend``), so colcon's build order and the import graph are the same graph, and no
  package imports upward.
- Algorithm modules (identification, excitation, plant) never import a middleware: rclpy,
  or the parts of rig_runtime that load it. Only node shells (``*_node.py``) and
  the runtime itself may.
- The interface contract and the graph model load no middleware, so the ROS launch files can
  use them (checked in a fresh interpreter).
"""

import ast
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from xml.etree import ElementTree

import pytest

SRC = Path(__file__).resolve().parents[2]
PACKAGES = sorted(p.parent.name for p in SRC.glob("*/package.xml"))
# Modules that bring up a middleware when imported (directly or through what they import).
MIDDLEWARE = (
    "rclpy",
    "rig_runtime.node",
    "rig_runtime.node_main",
    "rig_runtime.qos_profiles",
    "std_msgs",
    "diagnostic_msgs",
    "sensor_msgs",
    "geometry_msgs",
    "aero_rig_interfaces",
)
# ROS packages a module may import only if its package.xml declares them.
ROS_PACKAGES = (
    "rclpy",
    "std_msgs",
    "diagnostic_msgs",
    "sensor_msgs",
    "geometry_msgs",
    "aero_rig_interfaces",
)
ALGORITHM_PACKAGES = ("multisine_gen", "wing_sim", "aero_identification")


def _imports(path: Path) -> set[str]:
    """Absolute module names a file imports (``import a.b`` and ``from a.b import c``)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def _modules(package: str) -> list[Path]:
    return sorted((SRC / package / package).rglob("*.py"))


def _declared(package: str) -> set[str]:
    root = ElementTree.parse(SRC / package / "package.xml").getroot()
    return {e.text or "" for e in root.iter() if e.tag in ("depend", "exec_depend")}


def test_the_workspace_has_its_nine_packages() -> None:
    assert PACKAGES == sorted(
        [
            "aero_identification",
            "aero_rig",
            "aero_rig_interfaces",  # ament_cmake: the rig's messages and service
            "multisine_gen",
            "pitch_actuator",
            "pressure_scanner",
            "rig_runtime",
            "rig_testing",
            "wing_sim",
        ]
    )


def _undeclared(package: str, among: Sequence[str]) -> set[str]:
    """The imports by ``package``'s modules of packages in ``among`` that its package.xml does
    not declare (itself excepted), as ``path: module``."""
    allowed = _declared(package) | {package}
    return {
        f"{path.relative_to(SRC)}: {name}"
        for path in _modules(package)
        for name in _imports(path)
        if name.split(".")[0] in among and name.split(".")[0] not in allowed
    }


@pytest.mark.parametrize("package", PACKAGES)
def test_a_package_imports_only_what_its_package_xml_declares(package: str) -> None:
    wrong = _undeclared(package, PACKAGES)
    assert not wrong, f"undeclared (or upward) imports: {sorted(wrong)}"


@pytest.mark.parametrize("package", PACKAGES)
def test_a_package_declares_the_ros_packages_it_imports(package: str) -> None:
    wrong = _undeclared(package, ROS_PACKAGES)
    assert not wrong, f"ROS packages imported but not declared in package.xml: {sorted(wrong)}"


@pytest.mark.parametrize("package", ALGORITHM_PACKAGES)
def test_algorithm_modules_import_no_middleware(package: str) -> None:
    shells = {"refit_worker.py"}  # runs in the identifier node's worker process, imports none
    wrong = {
        f"{path.relative_to(SRC)}: {name}"
        for path in _modules(package)
        if not path.name.endswith("_node.py") or path.name in shells
        for name in _imports(path)
        if name.startswith(MIDDLEWARE)
    }
    assert not wrong, f"algorithm code importing a middleware: {sorted(wrong)}"


def test_the_contract_and_the_graph_model_load_no_middleware() -> None:
    code = (
        "import sys, rig_runtime.interface, rig_runtime.graph\n"
        "heavy = ('rclpy', 'rosbags', 'numpy', 'rerun')\n"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in heavy)\n"
        "print(bad); sys.exit(1 if bad else 0)\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr
