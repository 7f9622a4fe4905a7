"""Each node's watch for pauses of its own process past the DDS participant lease
(docs/design.md §3.10): SIGSTOP, a debugger, a suspended laptop, a swap storm. Its peers have
then dropped it, and reliable writers with it what they had not delivered."""

import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from . import ros_environment

if TYPE_CHECKING:
    from .node import Node

__all__ = ["PAUSE_WATCH_S", "PauseWatch"]

PAUSE_WATCH_S = 1.0  # the period of every node's pause watch


class PauseWatch:
    """Noticed on the first timer tick after the process runs again: logged at once, kept in
    ``paused_s``, passed to the ``on_paused`` callbacks; the holes it leaves show as each
    node's own gap or time-discontinuity checks when the next sample arrives. run_node starts
    it for every graph node (``Node.pause_watch``)."""

    def __init__(self, node: "Node") -> None:
        self.node = node
        self.paused_s: list[float] = []  # how long this process did not run, each time
        self.callbacks: list[Callable[[float], None]] = []
        self._last = 0.0

    def start(self) -> None:
        if self._last:
            return
        self._last = time.monotonic()
        self.node.create_timer(PAUSE_WATCH_S, self.tick)

    def tick(self) -> None:
        now = time.monotonic()
        stopped = now - self._last - PAUSE_WATCH_S
        self._last = now
        lease_s = ros_environment.PARTICIPANT_LEASE_S
        if stopped <= lease_s:
            return
        self.paused_s.append(stopped)
        self.node.logger.warning(
            "this process did not run for %.1f s, past the DDS participant lease (%g s): its "
            "peers dropped it, and the samples they published meanwhile are lost for it unless "
            "the recorder's bag holds them",
            stopped,
            lease_s,
        )
        for callback in self.callbacks:
            callback(stopped)
