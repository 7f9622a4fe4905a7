"""The tests of this directory run the node graph (rclpy node processes over Fast DDS),
whole campaigns, the identification pipeline on a simulated campaign, or a colcon build: all
are marked ``slow``. ``make test-fast`` (``pytest -m "not slow"``) leaves them out; ``make
test`` runs them.
"""

from pathlib import Path

import pytest
from graph_support import small_plan_design

from multisine_gen.plan_format import plan_to_json

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
