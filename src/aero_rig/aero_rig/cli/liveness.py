"""Progress liveness of a campaign: no silent wait for ever (docs/design.md §3.10).

The campaign's observer (`monitor.CampaignMonitor`) feeds `Liveness` with what the graph says
about itself: the generator's stream heartbeat (``/diagnostics``, once a second: its state and
the samples it has published), the end of the plan (its ``plan_end`` on
``/experiment/segment``), the identifier's status heartbeat (``/identification/status``, once a
second, with its state and the plan samples it holds on each channel), and the launcher's view
of the node processes (which are stopped: SIGSTOP, job control, a debugger).

- **While the plan streams,** the generator must publish: a stream that stands still for the
  bound (the generator paused or hung, or waiting for a credit that a paused stream node never
  returns) is a stall. Its own heartbeat counts, not the identifier's samples: once the
  commands stop, the actuator's watchdog runs on in real time, and its states would look like
  progress. Past the lease the run cannot be whole any more: the writers have dropped the
  silent reader with what they had not delivered. A silent identifier is only reported
  (once): the generator streams on, and the recorder keeps what the identifier misses.
- **After the plan's end,** the identifier must move on: hold more samples, start or finish
  its final identification, or keep its heartbeat while it refits.

At the bound the wait ends, naming what stalled and on what (and any node process that is
stopped). The bound comes from the graph's own clocks, not a guess: the DDS participant lease
(ros_environment.PARTICIPANT_LEASE_S) plus two status periods. It also covers the generator's
longest legitimate stand-still, the adaptive hold at a period's end, which the lease bounds
(generator_node.py). The campaign then recovers the identification from the bag (recovery.py).
"""

from dataclasses import dataclass, field

from rig_runtime.ros_environment import PARTICIPANT_LEASE_S

STATUS_PERIOD_S = 1.0  # the identifier's status timer (identifier_node.py)


def stall_bound_s() -> float:
    """Seconds without progress that count as a stall."""
    return PARTICIPANT_LEASE_S + 2 * STATUS_PERIOD_S


def stopped_note(stopped: dict[str, float]) -> str:
    """'; stopped: lift (14 s), …' for the node processes that are stopped now, else ''."""
    if not stopped:
        return ""
    names = ", ".join(f"{name} ({seconds:.0f} s)" for name, seconds in sorted(stopped.items()))
    return f"; node process(es) stopped (SIGSTOP, job control or a debugger): {names}"


@dataclass
class Liveness:
    """What the campaign knows of the identifier's progress; `check` says when it stalled."""

    bound_s: float
    total: int = 0  # plan samples
    plan_at: float | None = None  # when the plan was first seen (t0: the barrier is passed)
    plan_end_at: float | None = None  # when the generator said the plan ended
    status_at: float | None = None  # the identifier's last heartbeat
    state: str = ""
    samples: tuple[int, int] = (0, 0)  # plan samples it holds: pitch, C_l
    progress_at: float | None = None  # when its state or sample counts last changed
    stream_at: float | None = None  # the generator's last heartbeat
    stream_state: str = ""
    published: int = 0  # samples the generator has published
    published_at: float | None = None  # when that count last changed
    warned: set[str] = field(default_factory=set)
    # The generator's host is cut off (rig_runtime.flow's partition), e.g. "host 'rig' for 21 s":
    # a silent generator is then named as unreachable, not as paused, hung or gone.
    cut_off: str = ""

    def plan_seen(self, now: float) -> None:
        if self.plan_at is None:
            self.plan_at = now

    def plan_ended(self, now: float) -> None:
        if self.plan_end_at is None:
            self.plan_end_at = now

    def status(self, now: float, state: str, samples: tuple[int, int]) -> None:
        if state != self.state or samples != self.samples or self.progress_at is None:
            self.progress_at = now
        self.status_at, self.state, self.samples = now, state, samples

    def stream(self, now: float, state: str, published: int) -> None:
        """The generator's heartbeat: its state and the samples it has published."""
        if published != self.published or self.published_at is None:
            self.published_at = now
        self.stream_at, self.stream_state, self.published = now, state, published

    def silent_mid_run(self, now: float, stopped: dict[str, float] | None = None) -> str | None:
        """A one-time note while the plan streams and the identifier is silent past the bound."""
        if self.plan_end_at is not None or self.status_at is None or "silent" in self.warned:
            return None
        if now - self.status_at <= self.bound_s:
            return None
        self.warned.add("silent")
        return (
            f"identifier silent for {now - self.status_at:.0f} s (paused, starved or hung); "
            "the plan streams on and the bag keeps what it misses" + stopped_note(stopped or {})
        )

    def check(self, now: float, stopped: dict[str, float] | None = None) -> str | None:
        """None while the run may go on; else what stalled and on what."""
        reason = self._stalled(now)
        return None if reason is None else reason + stopped_note(stopped or {})

    def _stalled(self, now: float) -> str | None:
        if self.state == "done":
            return None
        if self.plan_end_at is None:
            return self._stream_stalled(now)
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

    def _stream_stalled(self, now: float) -> str | None:
        """Before the plan's end: the generator's stream stands still (or it fell silent)."""
        if self.plan_at is None or self.published_at is None or self.stream_at is None:
            return None  # no stream yet (the start barrier), or no heartbeat to judge by
        still = now - max(self.published_at, self.plan_at)
        if still <= self.bound_s:
            return None
        if now - self.stream_at > self.bound_s:
            why = (
                f"cut off by a partition: {self.cut_off}"
                if self.cut_off
                else "paused, hung or gone"
            )
            what = (
                f"the generator is silent: its last heartbeat came {now - self.stream_at:.0f} s "
                f"ago, at {self.published} of {self.total} samples published ({why})"
            )
        else:
            what = (
                f"the generator has published no sample for {still:.0f} s, standing at "
                f"{self.published} of {self.total} ({self.stream_state})"
            )
            if self.stream_state == "waiting for credit":
                what += (
                    "; it waits for the lift's /wing/coefficients/progress, which comes as the "
                    "actuator, the wing and the lift return coefficients"
                )
        pitch, cl = self.samples
        return (
            f"stream stalled before the plan's end: {what} (bound {self.bound_s:g} s: DDS lease "
            f"+ 2 status periods); the identifier holds {pitch} pitch and {cl} C_l samples"
        )
