"""The simulated actuator's silent-stream watchdog and command tracking, in-process."""

import math
from types import SimpleNamespace

from pitch_actuator.actuator_common import CommandTracking
from pitch_actuator.stream_watchdog import MAX_STEPS_PER_CALL, SilentStreamWatchdog
from rig_runtime.anomaly import Anomaly, AnomalyLog


def _watchdog() -> SilentStreamWatchdog:
    return SilentStreamWatchdog(fs=200.0, stream_timeout_s=30.0, lost_timeout_s=0.25)


def test_nothing_is_due_before_the_first_command() -> None:
    wd = _watchdog()
    assert wd.due(1000.0, publisher_present=False, stopped=True) == 0


def test_a_slow_graph_with_its_generator_present_waits_for_the_stream_timeout() -> None:
    wd = _watchdog()
    wd.command(0.0)
    assert wd.due(29.9, publisher_present=True, stopped=False) == 0  # pauses are harmless
    assert wd.due(30.0, publisher_present=True, stopped=False) == 1
    assert wd.due(30.1, publisher_present=True, stopped=False) == 21


def test_a_departed_generator_trips_after_the_governor_watchdog() -> None:
    wd = _watchdog()
    wd.command(0.0)
    assert wd.due(0.2, publisher_present=False, stopped=False) == 0
    assert wd.due(0.25, publisher_present=False, stopped=False) == 1


def test_a_stop_request_acts_within_two_samples() -> None:
    wd = _watchdog()
    wd.command(0.0)
    assert wd.due(0.01, publisher_present=True, stopped=True) == 1


def test_steps_are_counted_bounded_and_reset_by_a_command() -> None:
    wd = _watchdog()
    wd.command(0.0)
    due = wd.due(40.0, publisher_present=True, stopped=False)
    assert due == MAX_STEPS_PER_CALL  # a late timer catches up in bounded bursts
    wd.stepped(due)
    assert wd.running_on
    assert wd.due(30.2, publisher_present=True, stopped=False) == 0  # already stepped past
    assert wd.command(41.0) is True  # the command ends a free-run episode
    assert not wd.running_on and wd.command(41.1) is False


def _tracking(
    fs: float | None = 200.0, catch_up_deg: float = 0.0
) -> tuple[CommandTracking, list[Anomaly]]:
    sent: list[Anomaly] = []
    node = SimpleNamespace(anomalies=AnomalyLog("/sim_actuator", sent.append))
    return CommandTracking(node, fs, catch_up_deg), sent  # type: ignore[arg-type]


def test_followed_commands_report_nothing() -> None:
    tracking, sent = _tracking()
    for k in range(10):
        tracking.command(k * 5_000_000, 1.0 + k, 1.0 + k)
    assert sent == []


def test_commands_not_followed_form_one_episode() -> None:
    tracking, sent = _tracking()
    tracking.command(0, 10.0, 10.0)
    tracking.command(5_000_000, 40.0, 35.0)  # clamped to the limit
    tracking.command(10_000_000, 40.0, 35.0)
    tracking.command(15_000_000, math.nan, 35.0)  # refused
    assert [(a.kind, a.last_ns) for a in sent] == [("not_tracking", None)]
    tracking.command(20_000_000, 30.0, 30.0)
    assert (sent[-1].first_ns, sent[-1].last_ns) == (5_000_000, 15_000_000)


def test_stamp_jumps_are_time_discontinuities() -> None:
    tracking, sent = _tracking()
    tracking.command(0, 0.0, 0.0)
    tracking.command(5_000_000, 0.0, 0.0)
    tracking.command(20_000_000, 0.0, 0.0)  # two samples skipped
    tracking.command(10_000_000, 0.0, 0.0)  # backwards
    kinds = [(a.kind, a.first_ns, a.last_ns) for a in sent]
    assert kinds == [
        ("time_discontinuity", 5_000_000, 20_000_000),
        ("time_discontinuity", 10_000_000, 20_000_000),
    ]


def test_watchdog_episode_ends_with_the_next_followed_command() -> None:
    tracking, sent = _tracking(None)  # the rig: no fixed rate, no discontinuity check
    tracking.command(1_000, 5.0, 5.0)
    tracking.watchdog_tripped("no pitch command within the watchdog timeout")
    assert sent[-1].kind == "watchdog" and sent[-1].last_ns is None
    tracking.command(900_000_000, 6.0, 5.1)  # held: not followed yet
    tracking.command(905_000_000, 6.0, 6.0)
    watchdog = [a for a in sent if a.kind == "watchdog"]
    assert (watchdog[-1].first_ns, watchdog[-1].last_ns) == (1_000, 905_000_000)


def test_a_command_the_rate_limit_held_back_is_judged_at_the_next_tick() -> None:
    """The rig: commands delivered in a burst arrive microseconds apart, and the wall-clock
    rate budget holds them back until the next control tick, which may itself come right
    after them. Within one tick's budget (0.75° at 150°/s and 200 Hz) of the newest by then,
    or a later command followed at once: followed. Further behind (a stream faster than the
    rate limit, a hold after a trip): each is not_tracking at its own stamp."""
    tracking, sent = _tracking(None, catch_up_deg=0.75)
    tracking.command(0, 1.00, 0.99, catch_up=True)  # held back by microseconds of budget
    tracking.command(5_000_000, 1.05, 0.99, catch_up=True)  # the same burst
    assert sent == [] and len(tracking.pending) == 2
    tracking.settle(1.02)  # a tick right after them: on its way at the full rate
    assert sent == [] and tracking.pending == []
    tracking.command(10_000_000, 1.10, 1.06, catch_up=True)
    tracking.command(15_000_000, 1.15, 1.15, catch_up=True)  # followed at once: so was 1.10
    assert sent == []
    tracking.command(20_000_000, 3.00, 1.50, catch_up=True)
    tracking.settle(2.00)  # a whole degree behind at the next tick: the rate limit holds it
    assert [(a.kind, a.first_ns, a.last_ns) for a in sent] == [("not_tracking", 20_000_000, None)]
    tracking.command(25_000_000, 3.10, 3.10, catch_up=True)  # followed at once: episode ends
    assert (sent[-1].first_ns, sent[-1].last_ns) == (20_000_000, 20_000_000)
    tracking.command(30_000_000, 40.0, 35.0)  # clamped: judged at once, never held
    assert sent[-1].kind == "not_tracking" and sent[-1].first_ns == 30_000_000
