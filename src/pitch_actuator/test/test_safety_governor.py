"""SafetyGovernor: the setpoint never leaves the limits, never moves faster than the rate limit,
refuses non-finite commands, and goes hold → ramp → safe angle when commands stop."""

import math

import numpy as np
import pytest

from pitch_actuator.safety import (
    DiagnosticLevel,
    GovernorMode,
    LimitsError,
    SafetyGovernor,
    SafetyLimits,
)
from rig_runtime.interface import ActuatorLimits

LIMITS = SafetyLimits(
    min_deg=-5.0,
    max_deg=30.0,
    max_rate_deg_s=100.0,
    safe_angle_deg=2.0,
    watchdog_timeout_s=0.1,
    hold_s=0.5,
    ramp_rate_deg_s=5.0,
    limit_approach_s=0.0,  # plain clamping here; the approach has its own test below
)
FS = 200.0


def test_random_command_sweep_never_leaves_limits_or_rate() -> None:
    rng = np.random.default_rng(12)
    gov = SafetyGovernor(LIMITS, initial_deg=0.0, t_s=0.0)
    t, previous = 0.0, gov.setpoint_deg
    n_out_of_range = n_non_finite = 0
    for _ in range(20_000):
        dt = float(rng.uniform(0.0005, 0.02))
        t += dt
        action = rng.uniform()
        if action < 0.1:  # a timer tick without command
            setpoint = gov.update(t)
        else:
            if action < 0.12:
                value = float(rng.choice([math.nan, math.inf, -math.inf]))
                n_non_finite += 1
            else:
                value = float(rng.normal(12.0, 40.0))
                n_out_of_range += not LIMITS.min_deg <= value <= LIMITS.max_deg
            setpoint = gov.command(t, value)
        assert LIMITS.min_deg <= setpoint <= LIMITS.max_deg
        assert abs(setpoint - previous) <= LIMITS.max_rate_deg_s * dt + 1e-9
        previous = setpoint
    assert gov.counters.clamped == n_out_of_range > 1000
    assert gov.counters.refused == n_non_finite > 100


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_command_is_refused_and_setpoint_kept(bad: float) -> None:
    gov = SafetyGovernor(LIMITS, initial_deg=0.0)
    for k in range(1, 11):
        gov.command(k / FS, 1.0)
    assert gov.setpoint_deg == 1.0
    assert gov.command(11 / FS, bad) == 1.0
    assert gov.counters.refused == 1
    events = [e for e in gov.drain_events() if e.kind == "refused"]
    assert len(events) == 1 and events[0].level is DiagnosticLevel.ERROR
    assert "non-finite" in events[0].message and "1.000" in events[0].message
    assert gov.status().level is DiagnosticLevel.WARN  # reported once on /diagnostics


def test_out_of_range_command_is_clamped_and_reported() -> None:
    gov = SafetyGovernor(LIMITS, initial_deg=29.0)
    assert gov.command(0.005, 45.0) == 29.5  # rate: 100 °/s · 5 ms
    assert gov.command(0.010, 45.0) == 30.0
    assert gov.command(0.015, 45.0) == 30.0
    (event, *_) = gov.drain_events()
    assert event.kind == "clamped" and event.requested_deg == 45.0 and event.applied_deg == 30.0
    assert "45.000" in event.message and "30.000" in event.message
    assert gov.counters.clamped == 3


def test_rate_limit_on_a_step_command() -> None:
    gov = SafetyGovernor(LIMITS, initial_deg=0.0)
    setpoints = [gov.command(k / FS, 20.0) for k in range(1, 61)]
    steps = np.diff([0.0, *setpoints])
    # 100 °/s at 200 Hz: 0.5° per sample until the target is reached after 40 samples.
    np.testing.assert_allclose(steps[:40], 0.5, rtol=1e-12)
    np.testing.assert_allclose(setpoints[39:], 20.0, rtol=1e-12)
    assert gov.counters.rate_limited in (39, 40)  # the 40th may miss 20.0 by rounding of k/fs


def test_commands_within_rate_are_followed_exactly() -> None:
    gov = SafetyGovernor(LIMITS, initial_deg=10.0)
    k = np.arange(1, 401)
    commands = 10.0 + 3.0 * np.sin(2 * np.pi * 1.0 * k / FS)  # peak rate 18.8 °/s
    setpoints = [gov.command(kk / FS, float(c)) for kk, c in zip(k, commands, strict=True)]
    np.testing.assert_array_equal(setpoints, commands)


def _ticks(gov: SafetyGovernor, t_start: float, t_stop: float, dt: float) -> np.ndarray:
    times = np.arange(t_start, t_stop, dt)
    return np.array([[t, gov.update(float(t))] for t in times])


def test_watchdog_holds_then_ramps_to_safe_angle() -> None:
    gov = SafetyGovernor(LIMITS, initial_deg=0.0)
    for k in range(1, 201):
        gov.command(k / FS, 12.0)
    t_last = 200 / FS
    trace = _ticks(gov, t_last + 0.001, t_last + 4.0, 0.001)
    t, sp = trace[:, 0], trace[:, 1]
    t_trip = t_last + LIMITS.watchdog_timeout_s
    t_ramp = t_trip + LIMITS.hold_s
    t_safe = t_ramp + (12.0 - LIMITS.safe_angle_deg) / LIMITS.ramp_rate_deg_s
    assert np.all(sp[t <= t_ramp] == 12.0)  # no move until the hold is over
    ramping = (t > t_ramp + 0.01) & (t < t_safe - 0.01)
    expected = 12.0 - LIMITS.ramp_rate_deg_s * (t[ramping] - t_ramp)
    np.testing.assert_allclose(sp[ramping], expected, atol=1e-9)
    assert np.all(sp[t >= t_safe] == LIMITS.safe_angle_deg)
    assert gov.mode is GovernorMode.SAFE
    assert gov.counters.watchdog_trips == 1
    kinds = [e.kind for e in gov.drain_events()]
    assert kinds == ["watchdog", "safe"]
    assert gov.status().level is DiagnosticLevel.ERROR


def test_the_plans_end_disarms_the_watchdog_hold_and_ramp_without_error() -> None:
    """After `end_stream` (the plan has ended) the silence that follows is expected: the same
    hold → ramp → safe as a trip, but no watchdog trip, no ERROR event and an OK status. The
    plan's last commands may still arrive after the plan's end; they are tracked as before."""
    gov = SafetyGovernor(LIMITS, initial_deg=0.0)
    for k in range(1, 191):
        gov.command(k / FS, 12.0)
    gov.end_stream(190 / FS, "the plan has ended")
    for k in range(191, 201):  # the last commands, delivered after the plan's end
        gov.command(k / FS, 12.0)
    assert gov.mode is GovernorMode.TRACKING
    t_last = 200 / FS
    trace = _ticks(gov, t_last + 0.001, t_last + 4.0, 0.001)
    t, sp = trace[:, 0], trace[:, 1]
    t_ramp = t_last + LIMITS.watchdog_timeout_s + LIMITS.hold_s
    t_safe = t_ramp + (12.0 - LIMITS.safe_angle_deg) / LIMITS.ramp_rate_deg_s
    assert np.all(sp[t <= t_ramp] == 12.0)
    ramping = (t > t_ramp + 0.01) & (t < t_safe - 0.01)
    np.testing.assert_allclose(
        sp[ramping], 12.0 - LIMITS.ramp_rate_deg_s * (t[ramping] - t_ramp), atol=1e-9
    )
    assert np.all(sp[t >= t_safe] == LIMITS.safe_angle_deg)
    assert gov.mode is GovernorMode.SAFE
    assert gov.counters.watchdog_trips == 0
    events = gov.drain_events()
    assert [e.kind for e in events] == ["stream_end", "safe"], events
    assert all(e.level < DiagnosticLevel.ERROR for e in events), events
    assert "the plan has ended" in events[0].message and "holding 12.000°" in events[0].message
    assert gov.status().level is DiagnosticLevel.OK


def test_a_command_stream_resumed_after_the_plans_end_is_watched_again() -> None:
    """A new stream after the plan's end (the next run) re-arms the watchdog: its loss trips."""
    gov = SafetyGovernor(LIMITS, initial_deg=0.0)
    gov.command(0.005, 5.0)
    gov.end_stream(0.005, "the plan has ended")
    gov.update(0.4)  # silent: holding, no trip
    assert gov.mode is GovernorMode.HOLDING and gov.counters.watchdog_trips == 0
    for k in range(1, 30):
        gov.command(0.4 + k / FS, 8.0)
    assert gov.mode is GovernorMode.TRACKING
    gov.update(1.0)
    assert gov.counters.watchdog_trips == 1
    assert [e.kind for e in gov.drain_events()] == ["stream_end", "resumed", "watchdog"]


def test_the_plans_end_does_not_outlive_a_trip_a_stop_or_its_silence() -> None:
    """A plan's end is one silence: after a trip, a stop or the planned hold itself, the next
    lost stream trips the watchdog again."""
    for before in ("trip", "stop", "planned"):
        gov = SafetyGovernor(LIMITS, initial_deg=0.0)
        gov.command(0.005, 5.0)
        if before == "trip":
            gov.update(0.4)  # tripped while the plan still ran
            gov.end_stream(0.4, "the plan has ended")  # arrives during the hold: nothing to end
        elif before == "stop":
            gov.end_stream(0.01, "the plan has ended")
            gov.stop(0.02)
            gov.resume(0.03)
        else:
            gov.end_stream(0.01, "the plan has ended")
            gov.update(0.4)
        assert not gov.end_expected, before
        for k in range(1, 30):  # a new stream
            gov.command(0.5 + k / FS, 8.0)
        trips = gov.counters.watchdog_trips
        gov.update(1.5)  # and its loss
        assert gov.counters.watchdog_trips == trips + 1, before


def test_command_stream_resuming_after_watchdog_is_tracked_rate_limited() -> None:
    gov = SafetyGovernor(LIMITS, initial_deg=5.0)
    gov.command(0.005, 5.0)
    gov.update(0.4)  # tripped at 0.105 s, holding until 0.605 s
    assert gov.mode is GovernorMode.HOLDING
    setpoints = [gov.command(0.4 + k / FS, 15.0) for k in range(1, 30)]
    assert gov.mode is GovernorMode.TRACKING
    assert max(np.diff([5.0, *setpoints])) <= LIMITS.max_rate_deg_s / FS + 1e-12
    assert setpoints[-1] == 15.0
    assert "resumed" in [e.kind for e in gov.drain_events()]


def test_stop_request_holds_ramps_and_ignores_commands_until_resume() -> None:
    gov = SafetyGovernor(LIMITS, initial_deg=0.0)
    for k in range(1, 201):
        gov.command(k / FS, 8.0)
    t_stop = 1.0 + 0.5 / FS
    gov.stop(t_stop)
    # Commands keep arriving but are ignored; they must not re-arm tracking.
    times = np.arange(1, 800) / FS + t_stop
    setpoints = np.array([gov.command(float(t), 25.0) for t in times])
    assert np.all(setpoints[times <= t_stop + LIMITS.hold_s] == 8.0)
    ramping = (times > t_stop + LIMITS.hold_s + 0.01) & (times < t_stop + LIMITS.hold_s + 1.1)
    np.testing.assert_allclose(
        setpoints[ramping],
        8.0 - LIMITS.ramp_rate_deg_s * (times[ramping] - t_stop - LIMITS.hold_s),
        atol=1e-9,
    )
    assert setpoints[-1] == LIMITS.safe_angle_deg and gov.mode is GovernorMode.SAFE
    assert gov.counters.ignored_after_stop == len(times)
    gov.resume(times[-1] + 0.005)
    assert gov.command(times[-1] + 0.01, 2.4) == pytest.approx(2.4)


def test_long_gap_before_first_command_does_not_jump() -> None:
    gov = SafetyGovernor(LIMITS, initial_deg=0.0, t_s=0.0, max_step_interval_s=0.01)
    assert gov.command(10.0, 25.0) == pytest.approx(1.0)  # 100 °/s · 10 ms, not 25°


def test_radian_interface() -> None:
    gov = SafetyGovernor(LIMITS, initial_deg=0.0)
    out = gov.command_rad(0.005, math.radians(0.3))
    assert out == pytest.approx(math.radians(0.3))
    assert gov.setpoint_rad == pytest.approx(math.radians(0.3))


def test_invalid_limits_are_refused_with_a_clear_message() -> None:
    with pytest.raises(LimitsError, match=r"min_deg .* must be below max_deg"):
        SafetyLimits(min_deg=10.0, max_deg=5.0)
    with pytest.raises(LimitsError, match="safe_angle_deg"):
        SafetyLimits(safe_angle_deg=50.0)
    with pytest.raises(LimitsError, match=r"ramp_rate_deg_s .* must not exceed"):
        SafetyLimits(max_rate_deg_s=2.0, ramp_rate_deg_s=5.0)
    with pytest.raises(LimitsError, match="finite"):
        SafetyLimits(max_deg=math.nan)
    with pytest.raises(LimitsError, match="finite"):
        SafetyLimits(hold_s=math.inf)  # the governor's own fields are checked too
    with pytest.raises(LimitsError, match="must be a number"):
        SafetyLimits(max_rate_deg_s=True)
    with pytest.raises(LimitsError, match="unknown actuator limit parameter"):
        SafetyLimits.from_mapping({"max_deg": 30.0, "max_speed": 3.0})
    assert SafetyLimits.from_mapping(LIMITS.as_dict()) == LIMITS


def test_the_governor_takes_the_actuator_limits_and_their_defaults_from_the_contract() -> None:
    """One declaration: SafetyLimits extends rig_runtime.interface.ActuatorLimits."""
    assert issubclass(SafetyLimits, ActuatorLimits)
    contract = ActuatorLimits()
    governor = SafetyLimits()
    assert {k: governor.as_dict()[k] for k in contract.as_dict()} == contract.as_dict()


def test_limit_approach_keeps_the_loop_inside_the_limits() -> None:
    """A full-rate ramp into a limit must not make the ζ = 0.7 position loop overshoot it."""
    from pitch_actuator.dynamics import ActuatorModel, ActuatorParams

    for approach, overshoots in ((0.0, True), (0.02, False)):
        limits = SafetyLimits(
            max_deg=35.0, min_deg=-10.0, max_rate_deg_s=150.0, limit_approach_s=approach
        )
        gov = SafetyGovernor(limits, initial_deg=30.0)
        model = ActuatorModel(
            ActuatorParams(
                initial_deg=30.0, noise_std_deg=0.0, encoder_step_deg=0.0, gust_std_deg=0.0
            ),
            fs=FS,
        )
        peak = max(
            math.degrees(model.step(math.radians(gov.command(k / FS, 60.0))).true_position_rad)
            for k in range(1, 200)
        )
        assert (peak > 35.01) is overshoots, (approach, peak)
        assert peak > 34.99  # the limit is still reached
