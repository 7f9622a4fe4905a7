"""Every test of the workspace: ROS 2 discovery on this machine only (loopback), whatever the
environment of the shell that runs pytest (tests never reach another host); in CI, a skipped
``ci_required`` test fails."""

import os
from collections.abc import Generator
from typing import Any

import pytest

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_STATIC_PEERS", None)
os.environ.pop("RIG_DDS_NETWORK", None)

pytest_plugins = ["pytester"]  # tests/test_ci_skips.py runs pytest on a suite of its own


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(
    item: pytest.Item, call: pytest.CallInfo[None]
) -> Generator[None, Any, None]:
    """In CI (``CI=true``), a skipped test marked ``ci_required`` fails with its skip reason:
    the F-16 data, the ros2 tools and the launch stack are there in CI, and a green run must not
    hide that they went untested."""
    outcome = yield
    report = outcome.get_result()
    if (
        report.skipped
        and not hasattr(report, "wasxfail")  # an expected failure is not a skip
        and os.environ.get("CI", "").lower() == "true"
        and item.get_closest_marker("ci_required") is not None
    ):
        reason = report.longrepr[-1] if isinstance(report.longrepr, tuple) else report.longrepr
        report.outcome = "failed"
        report.longrepr = f"skipped in CI, where it must run: {reason}"
