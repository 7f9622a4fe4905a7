"""The campaign's liveness rule (aero_rig/cli/liveness.py), on a clock of its own."""

from aero_rig.cli.liveness import Liveness, stall_bound_s
from rig_runtime.ros_environment import PARTICIPANT_LEASE_S


def test_the_bound_is_the_backend_lease_plus_two_status_periods() -> None:
    assert stall_bound_s("dds") == PARTICIPANT_LEASE_S["dds"] + 2.0 == 12.0
    assert stall_bound_s("rclpy") == PARTICIPANT_LEASE_S["rclpy"] + 2.0 == 22.0


def _heartbeats(live: Liveness, start: float, stop: float, state: str, samples: int) -> None:
    t = start
    while t <= stop:
        live.status(t, state, (samples, samples))
        t += 1.0


def test_a_refit_with_heartbeats_is_progress_however_long() -> None:
    live = Liveness(12.0, total=100)
    _heartbeats(live, 0.0, 10.0, "collecting", 100)
    live.plan_ended(10.0)
    _heartbeats(live, 11.0, 200.0, "refitting", 100)
    assert live.check(200.5) is None
    live.status(201.0, "done", (100, 100))
    assert live.check(500.0) is None  # done: the identifier exits and ends the graph


def test_an_identifier_that_missed_the_plan_end_is_named_after_the_bound() -> None:
    live = Liveness(12.0, total=100)
    _heartbeats(live, 0.0, 10.0, "collecting", 60)
    live.plan_ended(10.0)
    _heartbeats(live, 11.0, 22.0, "collecting", 60)
    assert live.check(22.0) is None  # within the bound of the plan's end
    _heartbeats(live, 23.0, 23.0, "collecting", 60)
    reason = live.check(23.0)
    assert reason is not None and "still collecting" in reason
    assert "60 pitch and 60 C_l samples of 100" in reason and "/experiment/segment" in reason


def test_samples_still_arriving_after_the_end_are_progress() -> None:
    live = Liveness(12.0, total=100)
    live.plan_ended(0.0)
    for t in range(30):
        live.status(float(t), "collecting", (70 + t, 70 + t))
    assert live.check(29.0) is None


def test_a_silent_identifier_is_reported_mid_run_and_stalls_after_the_end() -> None:
    live = Liveness(12.0, total=100)
    live.status(0.0, "collecting", (10, 10))
    assert live.silent_mid_run(12.0) is None
    note = live.silent_mid_run(13.0)
    assert note is not None and "silent for 13 s" in note
    assert live.silent_mid_run(14.0) is None  # once
    live.plan_ended(14.0)
    assert live.check(26.0) is None
    reason = live.check(26.5)
    assert reason is not None and "last status came 26 s ago" in reason
    never = Liveness(12.0, total=100)
    never.plan_ended(0.0)
    assert "never" in (never.check(13.0) or "")


def test_an_identifier_holding_every_sample_but_not_done_is_named_so() -> None:
    live = Liveness(12.0, total=100)
    live.plan_ended(0.0)
    for t in range(14):
        live.status(float(t), "collecting", (100, 100))
    reason = live.check(13.0)
    assert reason is not None and "holds every plan sample" in reason
