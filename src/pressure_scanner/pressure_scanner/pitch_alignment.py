"""Pitch by stamp for the taps samples of the lift node (docs/design.md §6), without ROS or DDS.

The coefficients of a taps sample need the angle of attack at the taps' stamp, and the pitch
arrives on its own topic, neither in step nor in a guaranteed order with the taps. This class
keeps a bounded, sorted history of pitch states and a queue of samples waiting for theirs:

- simulation: taps k carry the stamp of pitch state k, so an exact lookup (O(1)) finds it;
- rig: the two clocks differ, so the pitch is interpolated linearly between the neighbouring
  states, but only when they are at most ``max_gap_ns`` apart (a longer gap is a dropout, and
  a made-up pitch would give plausible but wrong coefficients: NaN instead).

A sample later than the newest pitch waits (its pitch may still come), and so does every sample
behind it, so they are released in arrival order. The queue is bounded: past ``max_pending`` the
oldest is forced out with whatever is known then (``final``). Stamps are integer nanoseconds;
payloads are opaque (the node passes the taps message). Released items are
``(stamp_ns, payload, alpha)`` with alpha NaN when no pitch near that stamp is known.
"""

import bisect
import math
from collections import deque
from typing import Any

Released = tuple[int, Any, float]


class PitchAlignment:
    """Pitch history + pending samples; every call returns the samples ready to process."""

    def __init__(self, max_gap_ns: int, max_pending: int, history: int = 4000) -> None:
        if max_gap_ns < 0 or max_pending < 0 or history < 1:
            raise ValueError(
                f"need max_gap_ns >= 0, max_pending >= 0, history >= 1, got {max_gap_ns}, "
                f"{max_pending}, {history}"
            )
        self.max_gap_ns = max_gap_ns
        self.max_pending = max_pending
        self.history = history
        self.stamps: deque[int] = deque(maxlen=history)
        self.values: deque[float] = deque(maxlen=history)
        # Exact stamps (simulation: taps k carry the stamp of state k) in O(1); bisect on the
        # deques (O(n) indexing) only for the rig's interpolation. Same keys as ``stamps``.
        self.by_stamp: dict[int, float] = {}
        self.pending: deque[tuple[int, Any]] = deque()

    @property
    def pending_count(self) -> int:
        """Samples waiting for their pitch."""
        return len(self.pending)

    def add_pitch(self, stamp_ns: int, value: float) -> list[Released]:
        """Record a pitch state; return the waiting samples whose pitch is now known, in order."""
        if self.stamps and stamp_ns <= self.stamps[-1]:
            return []  # out of order or repeated: the history stays sorted
        if len(self.stamps) == self.history:
            self.by_stamp.pop(self.stamps[0], None)
        self.stamps.append(stamp_ns)
        self.values.append(float(value))
        self.by_stamp[stamp_ns] = self.values[-1]
        released = []
        while self.pending and self.alpha(self.pending[0][0], final=False) is not None:
            released.append(self._release())
        return released

    def add_sample(self, stamp_ns: int, payload: Any) -> list[Released]:
        """Queue a sample, or return it at once when its pitch is known and none is waiting.

        Past ``max_pending`` waiting samples the oldest are returned (final: alpha may be NaN).
        """
        if self.pending or self.alpha(stamp_ns, final=False) is None:
            self.pending.append((stamp_ns, payload))
            released = []
            while len(self.pending) > self.max_pending:
                released.append(self._release())
            return released
        return [(stamp_ns, payload, self._final_alpha(stamp_ns))]

    def flush(self) -> list[Released]:
        """Return every waiting sample with what is known now (final), e.g. at shutdown."""
        released = []
        while self.pending:
            released.append(self._release())
        return released

    def alpha(self, stamp_ns: int, final: bool) -> float | None:
        """Pitch at ``stamp_ns``: None = not known yet (may come), NaN = cannot be known.

        ``final``: no later pitch will be waited for, so a stamp at most ``max_gap_ns`` after
        the newest state takes the newest value. A stamp before the history is decided at once
        (the oldest value within ``max_gap_ns``, else NaN). Without any pitch at all it stays
        None (the caller treats it as NaN).
        """
        exact = self.by_stamp.get(stamp_ns)
        if exact is not None:
            return exact
        stamps = self.stamps
        if not stamps or stamp_ns > stamps[-1]:
            if final and stamps and stamp_ns - stamps[-1] <= self.max_gap_ns:
                return self.values[-1]
            return None
        i = bisect.bisect_left(stamps, stamp_ns)
        if stamps[i] == stamp_ns:
            return self.values[i]
        if i == 0:
            # Before the oldest state: pitch stamps only grow, so waiting cannot help (a sample
            # left waiting here would hold up every sample behind it). Within the gap the
            # oldest state stands for it, as the newest does after the end.
            return self.values[0] if stamps[0] - stamp_ns <= self.max_gap_ns else math.nan
        s0, s1 = stamps[i - 1], stamps[i]
        if s1 - s0 > self.max_gap_ns:
            return math.nan
        w = (stamp_ns - s0) / (s1 - s0)
        return (1 - w) * self.values[i - 1] + w * self.values[i]

    def _final_alpha(self, stamp_ns: int) -> float:
        alpha = self.alpha(stamp_ns, final=True)
        return math.nan if alpha is None else alpha

    def _release(self) -> Released:
        stamp, payload = self.pending.popleft()
        return stamp, payload, self._final_alpha(stamp)
