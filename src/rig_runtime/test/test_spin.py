"""Node.spin: the executor's own loop, stopped by the callback that asks."""

from collections.abc import Callable, Iterator

import pytest

from rig_runtime.node import EXECUTOR_ENV, Node
from rig_testing.processes import graph_env


@pytest.fixture(params=["events", "single"])
def node(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> Iterator[Node]:
    for key, value in graph_env().items():
        monkeypatch.setenv(key, value)
    monkeypatch.setenv(EXECUTOR_ENV, request.param)
    made = Node("spin_test", argv=[])
    yield made
    made.close()


def _ticks_until_stopped(node: Node, stop: Callable[[int], None]) -> int:
    """Spin a timer due every millisecond that calls ``stop(exit_code 3)`` at its fifth call;
    how many calls ran before spin returned."""
    calls: list[int] = []

    def tick() -> None:
        calls.append(len(calls))
        if len(calls) == 5:
            stop(3)

    node.create_timer(0.001, tick)
    node.spin()
    assert node.exit_code == 3
    return len(calls)


def test_spin_returns_after_the_callback_that_requests_shutdown(node: Node) -> None:
    # A turn that went on after the request (SPIN_TURN_S, 50 ms) would call the timer dozens
    # of times more.
    assert _ticks_until_stopped(node, node.request_shutdown) == 5


def test_a_flag_set_by_a_signal_handler_ends_spin(node: Node) -> None:
    # What run_node's SIGINT/SIGTERM handler calls: only the flag, read between turns.
    assert _ticks_until_stopped(node, node.spinner.signal_shutdown) >= 5


def test_a_signal_ends_spin_while_samples_keep_coming(node: Node) -> None:
    # Each sample taken publishes two more, so the executor always has an event ready and
    # its loop never reaches its timeout; the turn check (a timer) still reads the flag.
    import threading

    from rig_runtime.interface import PITCH_COMMAND

    taken = [0]
    pub = node.create_publisher(PITCH_COMMAND.type, "/spin_test/echo", "events")

    def publish() -> None:
        pub.publish(node.new_message(PITCH_COMMAND.type))

    def on_sample(_msg: object) -> None:
        taken[0] += 1
        if taken[0] == 5:
            node.spinner.signal_shutdown(3)
        publish()
        publish()

    node.create_subscription(PITCH_COMMAND.type, "/spin_test/echo", on_sample, "events")
    assert node.spin_until(lambda: pub.handle.get_subscription_count() > 0, 10.0)
    # A bound on the wait, not part of what is tested: a spin that never reads the flag
    # would be stopped here, 30 s on, and fail below.
    rescued = threading.Event()

    def rescue() -> None:
        if not rescued.wait(30.0):
            rescued.set()
            node.spinner._end_turn()

    guard = threading.Thread(target=rescue, daemon=True)
    guard.start()
    publish()
    node.spin()
    stopped_by_guard = rescued.is_set()
    rescued.set()
    guard.join()
    assert not stopped_by_guard
    assert node.exit_code == 3 and taken[0] >= 5
