"""Signals that ask a process to stop, turned into a flag that its own loop reads.

A handler that only records the signal keeps the stop where the loop can do it in order (stop
the graph's nodes, close the bag): an exception raised from a handler could surface anywhere.
Light: standard library only.
"""

import signal
from collections.abc import Callable
from types import FrameType, TracebackType
from typing import Any

__all__ = ["StopSignals"]


class StopSignals:
    """While the context is entered, each of ``signums`` is recorded (``received``: the names,
    first first) and ``on_signal(name)`` is called; the object is true once one came. On exit
    the previous handlers come back, or with ``ignore_after`` and a signal received, the
    signals are ignored from then on (the process is on its way out: a second Ctrl-C, e.g. a
    terminal's and then ros2 launch's, must not kill it mid-shutdown)."""

    def __init__(
        self,
        *signums: signal.Signals,
        on_signal: Callable[[str], None] | None = None,
        ignore_after: bool = False,
    ) -> None:
        self.signums = signums
        self.on_signal = on_signal
        self.ignore_after = ignore_after
        self.received: list[str] = []
        self._previous: dict[signal.Signals, Any] = {}

    def __bool__(self) -> bool:
        return bool(self.received)

    def _handle(self, signum: int, _frame: FrameType | None) -> None:
        name = signal.Signals(signum).name
        self.received.append(name)
        if self.on_signal is not None:
            self.on_signal(name)

    def install(self) -> "StopSignals":
        """Record the signals from now on (for the process's life, or until the context's exit)."""
        self._previous = {s: signal.signal(s, self._handle) for s in self.signums}
        return self

    def __enter__(self) -> "StopSignals":
        return self.install()

    def ignore(self) -> None:
        """Ignore the signals from now on (e.g. while a bounded stop runs)."""
        for s in self.signums:
            signal.signal(s, signal.SIG_IGN)

    def restore(self) -> None:
        """The previous handlers back (ignored instead, with ``ignore_after`` and a signal
        received)."""
        for s, handler in self._previous.items():
            signal.signal(s, signal.SIG_IGN if self.ignore_after and self.received else handler)

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.restore()
