"""The campaign's liveness rule (aero_rig/cli/liveness.py), on a clock of its own."""

from aero_rig.cli.liveness import Liveness, stall_bound_s
from rig_runtime.ros_environment import PARTICIPANT_LEASE_S


def test_the_bound_is_the_fast_dds_lease_plus_two_status_periods() -> None:
    assert stall_bound_s() == PARTICIPANT_LEASE_S + 2.0 == 22.0


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


def test_a_stream_that_stands_still_before_the_plans_end_is_a_stall_naming_stopped_nodes() -> None:
    """Before the plan's end the generator must publish: waiting for a credit that a stopped
    stream node never returns ends the run at the bound, with the stopped processes named."""
    live = Liveness(12.0, total=100)
    live.stream(0.0, "barrier", 0)
    live.status(0.0, "collecting", (0, 0))
    assert live.check(30.0) is None  # no plan yet: the start barrier may still wait
    live.plan_seen(30.0)
    for t in range(31, 41):
        live.stream(float(t), "streaming", t)
        live.status(float(t), "collecting", (t, t))
    for t in range(41, 53):
        live.stream(float(t), "waiting for credit", 40)
        # the actuator's watchdog runs on: the identifier's samples advance, no progress
        live.status(float(t), "collecting", (t, 40))
    assert live.check(52.0) is None  # 12 s: within the bound
    live.stream(53.0, "waiting for credit", 40)
    reason = live.check(53.0, {"lift": 13.2})
    assert reason is not None and "stream stalled before the plan's end" in reason
    assert "no sample for 13 s, standing at 40 of 100 (waiting for credit)" in reason
    assert "/wing/coefficients" in reason and "identifier holds 52 pitch and 40 C_l" in reason
    assert "stopped (SIGSTOP, job control or a debugger): lift (13 s)" in reason
    plain = live.check(53.0)
    assert plain is not None and "SIGSTOP" not in plain  # processes named only when stopped


def test_a_silent_generator_before_the_plans_end_is_a_stall() -> None:
    live = Liveness(12.0, total=100)
    live.plan_seen(0.0)
    for t in range(0, 5):
        live.stream(float(t), "streaming", 10 * t)
    assert live.check(16.0) is None
    reason = live.check(16.5, {"generator": 12.0})
    assert (
        reason is not None
        and "generator is silent" in reason
        and "at 40 of 100 samples published" in reason
    )
    assert "generator (12 s)" in reason


def test_the_adaptive_hold_within_the_lease_is_no_stall() -> None:
    live = Liveness(12.0, total=100)
    live.plan_seen(0.0)
    live.stream(1.0, "streaming", 50)
    for t in range(2, 12):
        live.stream(float(t), "holding", 50)
    live.stream(12.0, "streaming", 60)
    for t in range(13, 24):
        live.stream(float(t), "streaming", 60 + t)
        assert live.check(float(t)) is None


def test_a_silent_identifier_before_the_plans_end_is_no_stream_stall() -> None:
    """The identifier itself paused: the generator streams on and the bag keeps the samples;
    only noted, and the plan's end decides (the campaign then recovers from the bag)."""
    live = Liveness(12.0, total=100)
    live.plan_seen(0.0)
    live.status(1.0, "collecting", (5, 5))
    for t in range(1, 41):
        live.stream(float(t), "streaming", t)
    assert live.check(40.0) is None
    note = live.silent_mid_run(40.0, {"identifier": 30.0})
    assert note is not None and "identifier (30 s)" in note
