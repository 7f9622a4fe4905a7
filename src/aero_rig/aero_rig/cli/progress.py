"""The campaign's progress on stderr: tqdm's bar on a terminal, plain lines in a log.

tqdm redraws its bar with carriage returns; written to a file (``make campaign > run.log
2>&1``, ``nohup``, a job scheduler, CI) every redraw stays in it, all on one line: the
monitor redraws five times a second, so a 40-minute rig run would leave about 12,000
redraws (over a megabyte) on a single line. Where stderr is not a terminal the campaign
therefore writes one line when the state changes (starting, collecting, refitting, done)
and at most one every ``interval_s`` seconds otherwise.
"""

import sys
import time
from collections.abc import Callable
from typing import Any, TextIO

# Seconds between two plain progress lines while the state stays the same.
LINE_INTERVAL_S = 30.0


class Progress:
    """``update(k, total, state)`` once per monitor spin; ``write`` a message; ``close``."""

    def __init__(
        self,
        *,
        quiet: bool,
        stream: TextIO | None = None,
        interval_s: float = LINE_INTERVAL_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.quiet = quiet
        self.interval_s = interval_s
        self.clock = clock
        self.started = clock()
        self.bar: Any = None
        if not quiet and _is_terminal(self.stream):
            from tqdm import tqdm

            self.bar = tqdm(
                total=1, unit="sample", unit_scale=True, desc="experiment", file=self.stream
            )
        self._last: tuple[str, float] | None = None  # (state, time) of the last plain line

    def update(self, k: int, total: int, state: str) -> None:
        state = state or "starting"
        if self.quiet:
            return
        if self.bar is not None:
            if total and self.bar.total != total:
                self.bar.total = total
            self.bar.n = k
            self.bar.set_postfix_str(state)
            self.bar.refresh()
            return
        now = self.clock()
        if self._last and self._last[0] == state and now - self._last[1] < self.interval_s:
            return
        self._last = (state, now)
        print(line(k, total, state, now - self.started), file=self.stream, flush=True)

    def write(self, text: str) -> None:
        """A message that must not be lost under the bar (shown also when quiet)."""
        if self.bar is not None:
            self.bar.write(text, file=self.stream)
        else:
            print(text, file=self.stream, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def line(k: int, total: int, state: str, elapsed_s: float) -> str:
    """One plain progress line, e.g. 'experiment: 46 % (6,340 of 13,764 samples), collecting,
    15 s'."""
    if total:
        done = f"{100 * k / total:.0f} % ({k:,} of {total:,} samples)"
    else:
        done = f"{k:,} samples, plan not yet received"
    return f"experiment: {done}, {state}, {elapsed_s:.0f} s"


def _is_terminal(stream: TextIO) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):  # a closed or foreign stream
        return False
