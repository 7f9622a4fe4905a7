"""Node.spin: the executor's own loop, stopped by the callback that asks."""

from collections.abc import Iterator

import pytest

from rig_runtime.node import EXECUTOR_ENV, Node
from rig_runtime.testing import graph_env


@pytest.fixture(params=["events", "single"])
def node(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> Iterator[Node]:
    for key, value in graph_env().items():
        monkeypatch.setenv(key, value)
    monkeypatch.setenv(EXECUTOR_ENV, request.param)
    made = Node("spin_test", argv=[])
    yield made
    made.close()


def test_spin_returns_after_the_callback_that_requests_shutdown(node: Node) -> None:
    # A timer due every millisecond: a turn that went on after the request (SPIN_TURN_S,
    # 50 ms) would call it dozens of times more.
    calls: list[int] = []

    def tick() -> None:
        calls.append(len(calls))
        if len(calls) == 5:
            node.request_shutdown(3)

    node.create_timer(0.001, tick)
    node.spin()
    assert len(calls) == 5
    assert node.exit_code == 3


def test_a_flag_set_by_a_signal_handler_ends_spin(node: Node) -> None:
    # What run_node's SIGINT/SIGTERM handler calls: only the flag, read between turns.
    calls: list[int] = []

    def tick() -> None:
        calls.append(len(calls))
        if len(calls) == 5:
            node._signal_shutdown(4)

    node.create_timer(0.001, tick)
    node.spin()
    assert len(calls) >= 5
    assert node.exit_code == 4
