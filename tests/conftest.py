"""The tests of this directory run the node graph (rclpy node processes over Fast DDS),
whole campaigns, the identification pipeline on a simulated campaign, or a colcon build: all
are marked ``slow``. ``make test-fast`` (``pytest -m "not slow"``) leaves them out; ``make
test`` runs them.
"""

import subprocess
import sys
from pathlib import Path

import pytest
from graph_support import WING, small_plan_design

from multisine_gen.plan_format import plan_to_json
from rig_testing.processes import graph_env

HERE = Path(__file__).resolve().parent


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if item.path.resolve().is_relative_to(HERE):
            item.add_marker(pytest.mark.slow)


@pytest.fixture(scope="session")
def small_plan(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """small_plan_design() as a plan file, what the generator's ``plan`` parameter takes."""
    path = tmp_path_factory.mktemp("plan") / "small.json"
    path.write_text(plan_to_json(small_plan_design()))
    return path


@pytest.fixture(scope="session")
def small_campaign(
    small_plan: Path, tmp_path_factory: pytest.TempPathFactory
) -> tuple[Path, subprocess.CompletedProcess[str]]:
    """The small plan (one level, 69 s of experiment) on the release-0.1 wing
    (graph_support.WING), one machine, idle: the reference of the runs that must lose nothing
    and give the same tables under load, after a fault or on two hosts."""
    run = tmp_path_factory.mktemp("small") / "run"
    cli = [sys.executable, "-m", "aero_rig.cli", "campaign", "--plan", str(small_plan)]
    cli += [*WING, "--out", str(run), "--quiet"]
    proc = subprocess.run(
        [*cli, "--timeout", "600"],
        env=graph_env(),
        capture_output=True,
        text=True,
        timeout=700,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return run, proc
