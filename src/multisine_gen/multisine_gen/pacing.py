"""How far the generator may stream: wall-clock pacing and the simulation's credit window.

Two limits, either or both (docs/design.md §5):

- **Wall clock**: at ``real_time_factor`` r > 0, sample k is due once ``k / (r·fs)`` wall seconds
  have passed since t0 (the rig runs at r = 1).
- **Credit** (simulation, ``flow_control``): never more than ``max_lead`` samples ahead of the
  last sample whose ``/wing/coefficients`` the lift has published (it reports their stamps on
  ``/wing/coefficients/progress`` every few milliseconds). The simulated stream is as fast as
  the graph takes, and what is in flight is bounded: a slow or paused node stalls the
  generator instead of piling samples up in front of it, and nothing is lost.

Plain logic with explicit times, tested in-process; the node only feeds it.
"""

from dataclasses import dataclass


@dataclass
class StreamPacer:
    total: int  # samples in the plan
    fs: float  # sample rate [Hz]
    real_time_factor: float = 1.0  # 0: no wall-clock pacing
    flow_control: bool = False
    max_lead: int = 1000
    k_seen: int = -1  # plan index of the last coefficients sample that came back
    wall0: float | None = None  # wall time of t0 [s]

    def start(self, wall_s: float) -> None:
        self.wall0 = wall_s

    def credit(self, k: int) -> None:
        """The coefficients of plan sample k were published (out-of-order reports are
        harmless)."""
        self.k_seen = max(self.k_seen, k)

    @property
    def credit_until(self) -> int:
        """Exclusive end index the credit allows (flow control)."""
        return self.k_seen + 1 + self.max_lead

    def target(self, wall_s: float) -> int:
        """Samples that may have been published by ``wall_s`` (exclusive end index)."""
        if self.wall0 is None:
            return 0
        target = self.total
        if self.real_time_factor > 0:
            elapsed = wall_s - self.wall0
            target = min(target, int(elapsed * self.real_time_factor * self.fs) + 1)
        if self.flow_control:
            target = min(target, self.credit_until)
        return max(target, 0)
