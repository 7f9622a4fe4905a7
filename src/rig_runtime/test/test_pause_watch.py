"""Every node notices at once that its own process did not run past the DDS lease."""

from collections.abc import Iterator

import pytest

from rig_runtime.node import PAUSE_WATCH_S, Node
from rig_runtime.ros_environment import PARTICIPANT_LEASE_S
from rig_testing.processes import graph_env


@pytest.fixture
def node(monkeypatch: pytest.MonkeyPatch) -> Iterator[Node]:
    for key, value in graph_env().items():
        monkeypatch.setenv(key, value)
    made = Node("pause_watch_test", argv=[])
    yield made
    made.close()


def test_a_pause_past_the_lease_is_logged_kept_and_passed_on_at_the_next_tick(
    node: Node, monkeypatch: pytest.MonkeyPatch
) -> None:
    import rig_runtime.pause_watch as pause_watch_module

    clock = [1000.0]
    monkeypatch.setattr(pause_watch_module.time, "monotonic", lambda: clock[0])
    seen: list[float] = []
    node.on_paused(seen.append)
    node.start_pause_watch()
    lease = PARTICIPANT_LEASE_S
    clock[0] += PAUSE_WATCH_S + lease  # late by exactly the lease: not past it
    node.pause_watch.tick()
    assert node.paused_s == [] and seen == []
    clock[0] += PAUSE_WATCH_S + lease + 3.0  # stopped for the lease + 3 s
    node.pause_watch.tick()
    assert node.paused_s == pytest.approx([lease + 3.0]) and seen == node.paused_s
    clock[0] += PAUSE_WATCH_S  # on time again
    node.pause_watch.tick()
    assert len(node.paused_s) == 1
