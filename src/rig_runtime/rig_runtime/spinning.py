"""How a node runs and stops (docs/design.md §3): rclpy's executor loop in turns, shutdown
requests (from a callback, a signal handler or a launcher that is gone), draining after a
shutdown request, and the orderly close: the shutdown callbacks, the reliable writers' linger,
the node destroyed and its context shut down."""

import os
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import rclpy
from rclpy.signals import SignalHandlerOptions

if TYPE_CHECKING:
    from .node import Node

__all__ = ["SPIN_TURN_S", "WRITER_LINGER_S", "Spinner", "events_executor", "new_context"]

# spin()'s turn check: how soon a flag set by a signal handler (or a gone launcher) is read.
SPIN_TURN_S = 0.05
# When a node closes, its reliable writers wait this long for their readers to acknowledge what
# they hold: Fast DDS deletes a writer at once, and a reader that lost the end of a burst (a
# full receive queue, a paused process) gets its repair from that writer only.
WRITER_LINGER_S = 1.0


def events_executor(context: Any) -> Any:
    """rclpy.experimental.EventsExecutor without its ``faulthandler.enable()``, which fails
    where stderr has no file descriptor (pytest's capture) and is the process's business. The
    public wrapper has no option to skip it, so the executor comes from rclpy's implementation
    module, which that wrapper itself constructs it from."""
    from rclpy.impl.implementation_singleton import rclpy_implementation

    executor = rclpy_implementation.EventsExecutor(context)
    context.on_shutdown(executor.wake)  # as the wrapper does: a shutdown ends a blocked spin
    return executor


def new_context(domain: int) -> Any:
    """A context per node: its own participant in ``domain``, the domain of this moment (tests
    move between domains), shut down with the node. run_node handles SIGINT/SIGTERM itself (an
    orderly stop that lets the recorder drain), so rclpy installs no handler."""
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    return context


class Spinner:
    """The running and stopping of one node (``Node.spinner``) on its own executor and context.

    ``launcher_pid``: the launcher this node is a direct child of (rig_runtime.launcher), whose
    disappearance stops it; None: not watched."""

    def __init__(self, node: "Node", executor: Any, context: Any, launcher_pid: int | None) -> None:
        from rclpy.task import Future

        self._future = Future
        self.node = node
        self.executor = executor
        self.context = context
        self.launcher_pid = launcher_pid
        self.delivered = 0  # samples delivered by the node's subscriptions (spin_once counts)
        self.shutdown_requested = False
        self.closed = False
        self.callbacks: list[Callable[[], None]] = []  # on_shutdown, run in reverse at close
        self._turn: Any = None  # the Future of spin()'s turn under way

    def request_shutdown(self, exit_code: int | None = None) -> None:
        """Stop spinning: ``spin``'s turn ends after the event whose callback asks (a
        subscription's event delivers every sample it announced). Not from a signal handler:
        see ``signal_shutdown``."""
        self.signal_shutdown(exit_code)
        self._end_turn()

    def signal_shutdown(self, exit_code: int | None = None) -> None:
        """``request_shutdown`` for a signal handler: only the flag, which ``spin``'s turn
        check reads within SPIN_TURN_S. Completing the turn's future there could deadlock:
        the handler may interrupt this thread inside that future's own lock."""
        if exit_code is not None:
            self.node.exit_code = exit_code
        self.shutdown_requested = True

    def _end_turn(self) -> None:
        turn = self._turn
        if turn is not None and not turn.done():
            turn.set_result(None)  # the executor's loop returns once this callback does

    def spin_once(self, timeout_s: float = 0.05) -> int:
        before = self.delivered
        self.executor.spin_once(timeout_sec=max(timeout_s, 0.0))
        return self.delivered - before

    def spin(self) -> None:
        next_check = time.monotonic() + 0.5

        def check_turn() -> None:
            # A timer: while samples keep coming, the executor's loop may not return at its
            # timeout, so the flag a signal handler set and the launcher are checked here.
            nonlocal next_check
            if self.launcher_pid is not None and time.monotonic() >= next_check:
                next_check = time.monotonic() + 0.5
                if os.getppid() != self.launcher_pid:
                    self.node.logger.error(
                        "the launcher (pid %d) is gone: shutting down", self.launcher_pid
                    )
                    self.signal_shutdown(1)
            if self.shutdown_requested:
                self._end_turn()

        # The executor's own loop, in turns: a turn handles every event that comes without
        # returning to Python between them (a Python loop around spin_once costs the stream
        # nodes about a tenth of their CPU). rclpy 7.1's EventsExecutor.spin takes no
        # timeout; spin_until_future_complete does, and the turn ends when its future is
        # completed (request_shutdown, check_turn). A new future per turn: each call adds a
        # done callback to it.
        timer = self.node.create_timer(SPIN_TURN_S, check_turn)
        try:
            while not self.shutdown_requested and self.context.ok():
                self._turn = self._future()
                self.executor.spin_until_future_complete(self._turn, timeout_sec=SPIN_TURN_S)
                check_turn()
        finally:
            self._turn = None
            self.node.destroy_timer(timer)

    def spin_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while not predicate():
            remaining = deadline - time.monotonic()
            if remaining <= 0 or self.shutdown_requested:
                return predicate()
            self.spin_once(min(0.05, remaining))
        return True

    def drain(self, until: Callable[[], bool], timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while True:
            remaining = deadline - time.monotonic()
            done = until()
            if remaining <= 0:
                return done
            delivered = self.spin_once(0.0 if done else min(0.05, remaining))
            if done and not delivered:
                return True

    def _linger(self) -> list[str]:
        """Wait (WRITER_LINGER_S in all) until every reliable writer's samples are
        acknowledged; the topics of those whose samples were not."""
        from rclpy.duration import Duration

        deadline = time.monotonic() + WRITER_LINGER_S
        late = []
        for pub in self.node.rig_publishers:
            # the flow report is a heartbeat: a cut-off peer need not get the last one
            if pub.profile.reliability != "reliable" or pub is self.node.flow_report.publisher:
                continue
            remaining = max(deadline - time.monotonic(), 0.0)
            try:
                acked = pub.handle.wait_for_all_acked(Duration(nanoseconds=int(remaining * 1e9)))
            except Exception:  # rclpy's RCLError: the writer cannot say
                acked = False
            if not acked:
                late.append(pub.topic)
        return late

    def close(self) -> None:
        """Run the shutdown callbacks, let the reliable writers linger, then destroy the node
        and shut its context down (once; the context is shut down whatever failed before)."""
        if self.closed:
            return
        self.closed = True
        try:
            self._close_endpoints()
        finally:
            self.context.try_shutdown()

    def _close_endpoints(self) -> None:
        node = self.node
        for callback in reversed(self.callbacks):
            try:
                callback()
            except Exception:
                node.logger.exception("shutdown callback failed")
        self.callbacks.clear()
        node.close_anomalies()  # an episode still open ends at its last stamp
        late = self._linger()
        if late:
            node.logger.warning(
                "closing with samples not acknowledged after %g s on %s: a reader is paused, "
                "starved or gone",
                WRITER_LINGER_S,
                ", ".join(sorted(set(late))),
            )
        try:
            self.executor.remove_node(node)
            self.executor.shutdown()
        finally:
            node.destroy_node()
