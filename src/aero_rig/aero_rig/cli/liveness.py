"""Progress liveness of a campaign: no silent wait for ever (docs/design.md §3.10).

The campaign's observer (`monitor.CampaignMonitor`) feeds `Liveness` with what the graph says
about itself: the end of the plan (the generator's ``plan_end`` on ``/experiment/segment``) and
the identifier's status heartbeat (``/identification/status``, once a second, with its state and
the plan samples it holds on each channel). After the plan has ended, the identifier must move
on: hold more samples, start or finish its final identification, or keep its heartbeat while
it refits. A bound without news ends the wait, naming what stalled and on what.

The bound comes from the graph's own clocks, not a guess: the DDS participant lease (a writer
drops a reader silent for that long, with what it did not deliver: ros_environment
.PARTICIPANT_LEASE_S) plus two status periods. Before the plan's end a silent identifier is
only reported (once): the generator streams on, and the recorder keeps what the identifier
misses; the campaign then recovers the identification from the bag (campaign.py).
"""

from dataclasses import dataclass, field

from rig_runtime.ros_environment import PARTICIPANT_LEASE_S

STATUS_PERIOD_S = 1.0  # the identifier's status timer (identifier_node.py)


def stall_bound_s(backend: str) -> float:
    """Seconds without progress after the plan's end that count as a stall."""
    return PARTICIPANT_LEASE_S.get(backend, max(PARTICIPANT_LEASE_S.values())) + 2 * STATUS_PERIOD_S


@dataclass
class Liveness:
    """What the campaign knows of the identifier's progress; `check` says when it stalled."""

    bound_s: float
    total: int = 0  # plan samples
    plan_end_at: float | None = None  # when the generator said the plan ended
    status_at: float | None = None  # the identifier's last heartbeat
    state: str = ""
    samples: tuple[int, int] = (0, 0)  # plan samples it holds: pitch, C_l
    progress_at: float | None = None  # when its state or sample counts last changed
    warned: set[str] = field(default_factory=set)

    def plan_ended(self, now: float) -> None:
        if self.plan_end_at is None:
            self.plan_end_at = now

    def status(self, now: float, state: str, samples: tuple[int, int]) -> None:
        if state != self.state or samples != self.samples or self.progress_at is None:
            self.progress_at = now
        self.status_at, self.state, self.samples = now, state, samples

    def silent_mid_run(self, now: float) -> str | None:
        """A one-time note while the plan streams and the identifier is silent past the bound."""
        if self.plan_end_at is not None or self.status_at is None or "silent" in self.warned:
            return None
        if now - self.status_at <= self.bound_s:
            return None
        self.warned.add("silent")
        return (
            f"identifier silent for {now - self.status_at:.0f} s (paused, starved or hung); "
            "the plan streams on and the bag keeps what it misses"
        )

    def check(self, now: float) -> str | None:
        """None while the run may go on; after the plan's end, what stalled and on what."""
        if self.plan_end_at is None or self.state == "done":
            return None
        since_end = now - self.plan_end_at
        if since_end <= self.bound_s:
            return None
        if self.status_at is None or now - self.status_at > self.bound_s:
            heard = "never" if self.status_at is None else f"{now - self.status_at:.0f} s ago"
            return (
                f"identifier stalled: its last status came {heard}, {since_end:.0f} s after the "
                f"plan ended (bound {self.bound_s:g} s: DDS lease + 2 status periods); it is "
                "paused, hung or gone"
            )
        assert self.progress_at is not None
        if self.state == "collecting" and now - max(self.progress_at, self.plan_end_at) > (
            self.bound_s
        ):
            pitch, cl = self.samples
            if self.total and min(pitch, cl) >= self.total:
                return (
                    f"identifier stalled: it holds every plan sample but has not finished its "
                    f"final identification {since_end:.0f} s after the plan ended (its refit "
                    "failed, or the plan's end on /experiment/segment was lost)"
                )
            return (
                f"identifier stalled: still collecting {since_end:.0f} s after the plan ended, "
                f"holding {pitch} pitch and {cl} C_l samples of {self.total} per channel; it "
                "waits on /pitch/state and /wing/coefficients for the rest, or on "
                "/experiment/segment for the plan's end (lost past the DDS lease)"
            )
        return None
