"""Safety layer shared by the simulated and the hardware actuator nodes.

The `SafetyGovernor` turns a stream of pitch commands into a setpoint that the actuator may
follow. It holds no clock: every call carries its time `t_s` (seconds, any monotonic clock the
node chooses, one clock per governor), so the same code runs at experiment time in simulation,
at wall-clock time on the rig and at made-up times in tests.

Units: the governor works in **degrees** (like the parameter files and `SafetyLimits`);
`command_rad` / `setpoint_rad` are the radian doors for nodes that speak SI on the wire.

Guarantees (docs/design.md §8):

- the setpoint never leaves [min_deg, max_deg];
- between two calls at t₁ < t₂ the setpoint changes by at most
  max_rate_deg_s · min(t₂ − t₁, max_step_interval_s);
- NaN/inf commands are refused (the previous setpoint is kept), out-of-range commands are
  clamped, both reported;
- no accepted command for watchdog_timeout_s → hold for hold_s, then ramp to safe_angle_deg at
  ramp_rate_deg_s; an explicit stop request does the same and latches until `resume()`.
"""

import enum
import math
from collections import deque
from dataclasses import dataclass, field, fields

from rig_runtime.interface import ActuatorLimits, LimitsError

__all__ = [
    "DiagnosticLevel",
    "GovernorCounters",
    "GovernorEvent",
    "GovernorMode",
    "GovernorStatus",
    "LimitsError",
    "SafetyGovernor",
    "SafetyLimits",
]


@dataclass(frozen=True)
class SafetyLimits(ActuatorLimits):
    """The actuator limits (min_deg, max_deg, max_rate_deg_s and their defaults from
    rig_runtime.interface.ActuatorLimits) and what the governor does at them and when commands
    stop, in degrees and seconds as in the parameter files.

    Attributes:
        min_deg, max_deg: allowed pitch range of the setpoint.
        max_rate_deg_s: largest setpoint rate while tracking commands.
        safe_angle_deg: where the wing goes when commands stop or a stop is requested.
        watchdog_timeout_s: silence after the last accepted command that trips the watchdog.
        hold_s: how long the setpoint is held still after a trip or stop before ramping.
        ramp_rate_deg_s: rate of the ramp to the safe angle (≤ max_rate_deg_s).
        limit_approach_s: time constant of the approach to a limit (0 = off).
    """

    safe_angle_deg: float = 0.0
    watchdog_timeout_s: float = 0.25
    hold_s: float = 1.0
    ramp_rate_deg_s: float = 5.0
    limit_approach_s: float = 0.02

    def __post_init__(self) -> None:
        super().__post_init__()  # every field a finite number, min < max, max rate > 0
        if not self.min_deg <= self.safe_angle_deg <= self.max_deg:
            raise LimitsError(
                f"SafetyLimits: safe_angle_deg ({self.safe_angle_deg}) must lie in "
                f"[min_deg, max_deg] = [{self.min_deg}, {self.max_deg}]"
            )
        for name in ("ramp_rate_deg_s", "watchdog_timeout_s"):
            if getattr(self, name) <= 0.0:
                raise LimitsError(f"SafetyLimits.{name} must be > 0, got {getattr(self, name)}")
        if self.hold_s < 0.0:
            raise LimitsError(f"SafetyLimits.hold_s must be >= 0, got {self.hold_s}")
        if self.limit_approach_s < 0.0:
            raise LimitsError(
                f"SafetyLimits.limit_approach_s must be >= 0, got {self.limit_approach_s}"
            )
        if self.ramp_rate_deg_s > self.max_rate_deg_s:
            raise LimitsError(
                f"SafetyLimits: ramp_rate_deg_s ({self.ramp_rate_deg_s}) must not exceed "
                f"max_rate_deg_s ({self.max_rate_deg_s})"
            )


class DiagnosticLevel(enum.IntEnum):
    """Levels of diagnostic_msgs/DiagnosticStatus (byte OK=0, WARN=1, ERROR=2)."""

    OK = 0
    WARN = 1
    ERROR = 2


class GovernorMode(enum.Enum):
    IDLE = "idle"  # no command yet (or resumed after a stop): holds the setpoint
    TRACKING = "tracking"  # follows the commands, rate limited
    HOLDING = "holding"  # after a watchdog trip or stop: still for hold_s
    RAMPING = "ramping"  # moving to the safe angle at ramp_rate_deg_s
    SAFE = "safe"  # at the safe angle


@dataclass(frozen=True)
class GovernorEvent:
    """One thing the node should report (log line, /diagnostics)."""

    t_s: float
    level: DiagnosticLevel
    kind: str  # refused | clamped | watchdog | stop | resumed | safe | time_reversed
    message: str
    requested_deg: float | None = None
    applied_deg: float | None = None


@dataclass
class GovernorCounters:
    """Totals since construction (for /diagnostics values)."""

    accepted: int = 0
    refused: int = 0
    clamped: int = 0
    rate_limited: int = 0
    watchdog_trips: int = 0
    stops: int = 0
    ignored_after_stop: int = 0
    time_reversals: int = 0
    events_dropped: int = 0


@dataclass(frozen=True)
class GovernorStatus:
    """What a node puts in one diagnostic_msgs/DiagnosticStatus."""

    level: DiagnosticLevel
    message: str
    mode: GovernorMode
    setpoint_deg: float
    values: dict[str, str] = field(default_factory=dict)


def _move_toward(x: float, target: float, max_step: float) -> float:
    if target > x + max_step:
        return x + max_step
    if target < x - max_step:
        return x - max_step
    return target


class SafetyGovernor:
    """Rate-limited, clamped, watchdog-guarded pitch setpoint (degrees; explicit time).

    Args:
        limits: the actuator limits and the watchdog, hold and ramp settings.
        initial_deg: where the actuator is now (clamped into the limits and reported if outside).
        t_s: time of construction on the governor's clock.
        max_step_interval_s: longest interval over which the rate budget accrues in one call,
            so a gap in calls never turns into a jump (e.g. the first command long after
            start-up moves the setpoint by at most max_rate_deg_s · max_step_interval_s).
        max_events: bound of the event queue (older events are dropped and counted).

    Call `command(t_s, command_deg)` for every command received and `update(t_s)` from a timer
    (the watchdog and the ramp advance only when the governor is called); send the returned
    setpoint to the actuator. The watchdog is armed by the first accepted command: before it
    (mode IDLE) the setpoint holds the initial position. After a watchdog trip, a new command
    resumes tracking (rate limited, reported); after `stop()`, only `resume()` does.
    `end_stream()` says the stream's end is planned (the plan has ended): the silence after
    the last command then holds and ramps as after a trip, reported at OK level and not counted
    as a trip; a stream that resumes after it is watched again.
    """

    def __init__(
        self,
        limits: SafetyLimits,
        initial_deg: float,
        t_s: float = 0.0,
        *,
        max_step_interval_s: float = 0.02,
        max_events: int = 256,
    ) -> None:
        if not math.isfinite(t_s):
            raise ValueError(f"SafetyGovernor: t_s must be finite, got {t_s!r}")
        if not (math.isfinite(max_step_interval_s) and max_step_interval_s > 0.0):
            raise ValueError(
                f"SafetyGovernor: max_step_interval_s must be > 0, got {max_step_interval_s!r}"
            )
        if not math.isfinite(initial_deg):
            raise ValueError(
                f"SafetyGovernor: initial_deg must be finite (the measured position), "
                f"got {initial_deg!r}"
            )
        self.limits = limits
        self.max_step_interval_s = float(max_step_interval_s)
        self.counters = GovernorCounters()
        self._events: deque[GovernorEvent] = deque(maxlen=max_events)
        self._t = float(t_s)
        self._mode = GovernorMode.IDLE
        self._stopped = False
        self._tripped = False
        self._end_expected = False  # end_stream(): the next silence is the plan's end
        self._end_reason = ""
        self._planned_hold = False  # holding/ramping because the stream ended as planned
        self._hold_until = math.inf
        self._last_command_t = -math.inf
        self._reported_since_status = False
        clamped = min(max(float(initial_deg), limits.min_deg), limits.max_deg)
        if clamped != initial_deg:
            self._emit(
                DiagnosticLevel.WARN,
                "clamped",
                f"initial position {initial_deg:.3f}° outside [{limits.min_deg}, "
                f"{limits.max_deg}]°; setpoint starts at {clamped:.3f}°",
                initial_deg,
                clamped,
            )
        self._setpoint = clamped
        self._target = clamped

    # -- public state ---------------------------------------------------------------------------
    @property
    def setpoint_deg(self) -> float:
        return self._setpoint

    @property
    def setpoint_rad(self) -> float:
        return math.radians(self._setpoint)

    @property
    def mode(self) -> GovernorMode:
        return self._mode

    @property
    def stopped(self) -> bool:
        """True after `stop()` until `resume()`; commands are ignored meanwhile."""
        return self._stopped

    @property
    def t_s(self) -> float:
        return self._t

    @property
    def end_expected(self) -> bool:
        """True after `end_stream()` while the stream still flows (until its silence)."""
        return self._end_expected

    # -- inputs ---------------------------------------------------------------------------------
    def command(self, t_s: float, command_deg: float) -> float:
        """Take one pitch command (degrees) at time t_s; return the setpoint (degrees) at t_s."""
        t = self._checked_time(t_s)
        value = float(command_deg)
        if not math.isfinite(value):
            self.counters.refused += 1
            self._emit(
                DiagnosticLevel.ERROR,
                "refused",
                f"refused non-finite pitch command {value!r}; setpoint kept at "
                f"{self._setpoint:.3f}°",
                value,
                self._setpoint,
            )
            return self._advance(t)
        if self._stopped:
            self.counters.ignored_after_stop += 1
            return self._advance(t)
        lo, hi = self.limits.min_deg, self.limits.max_deg
        target = min(max(value, lo), hi)
        if target != value:
            self.counters.clamped += 1
            self._emit(
                DiagnosticLevel.WARN,
                "clamped",
                f"pitch command {value:.3f}° outside [{lo}, {hi}]°, clamped to {target:.3f}°",
                value,
                target,
            )
        self.counters.accepted += 1
        on_time = t - self._last_command_t <= self.limits.watchdog_timeout_s
        if self._mode is GovernorMode.IDLE or (self._mode is GovernorMode.TRACKING and on_time):
            # Normal case: the new command is the target over the elapsed interval, so a
            # command reachable within the rate limit is the setpoint at once (reactive).
            self._mode = GovernorMode.TRACKING
            self._target = target
            self._last_command_t = t
            setpoint = self._advance(t)
        else:
            # A late command, or one after a trip: let the old state run up to t (the
            # watchdog may trip in between), then track from the setpoint reached.
            setpoint = self._advance(t)
            if self._mode is not GovernorMode.TRACKING:
                if self._tripped:
                    self._emit(
                        DiagnosticLevel.WARN,
                        "resumed",
                        f"command stream resumed after watchdog trip at {self._setpoint:.3f}°",
                    )
                elif self._planned_hold:
                    self._emit(
                        DiagnosticLevel.OK,
                        "resumed",
                        f"command stream resumed after the plan's end at {self._setpoint:.3f}°",
                    )
                self._end_expected = False  # a new stream: its loss trips the watchdog
                self._tripped = False
                self._planned_hold = False
                self._mode = GovernorMode.TRACKING
                self._hold_until = math.inf
            self._target = target
            self._last_command_t = t
        if setpoint != target:
            self.counters.rate_limited += 1
        return setpoint

    def command_rad(self, t_s: float, command_rad: float) -> float:
        """`command` in radians: take a command in rad, return the setpoint in rad."""
        return math.radians(self.command(t_s, math.degrees(command_rad)))

    def update(self, t_s: float) -> float:
        """Advance the governor's time without a command; return the setpoint (degrees)."""
        return self._advance(self._checked_time(t_s))

    def end_stream(self, t_s: float, reason: str = "the command stream has ended") -> float:
        """The command stream's end is planned (the plan has ended): the watchdog is disarmed
        for the silence that follows. Commands still in flight are tracked as before; once none
        has come for watchdog_timeout_s the setpoint holds for hold_s, then ramps to the safe
        angle, reported at OK level (not a trip). A command after that silence starts a new
        stream, watched again."""
        t = self._checked_time(t_s)
        setpoint = self._advance(t)
        if self._mode is GovernorMode.TRACKING:  # holding, ramping or stopped: nothing to end
            self._end_expected = True
            self._end_reason = reason
        return setpoint

    def stop(self, t_s: float, reason: str = "stop requested") -> float:
        """Stop: hold for hold_s, then ramp to the safe angle; commands ignored until resume."""
        t = self._checked_time(t_s)
        setpoint = self._advance(t)
        self.counters.stops += 1
        if not self._stopped:
            self._emit(
                DiagnosticLevel.WARN,
                "stop",
                f"{reason}: holding {self._setpoint:.3f}° for {self.limits.hold_s} s, then "
                f"ramping to {self.limits.safe_angle_deg}° at {self.limits.ramp_rate_deg_s}°/s",
            )
        self._stopped = True
        self._end_expected = self._planned_hold = False  # a stop is no planned end
        if self._mode in (GovernorMode.IDLE, GovernorMode.TRACKING):
            self._enter_hold(t)
        return setpoint

    def resume(self, t_s: float) -> float:
        """Clear a stop: the setpoint stays where it is until the next command."""
        t = self._checked_time(t_s)
        setpoint = self._advance(t)
        if self._stopped:
            self._stopped = False
            self._tripped = False
            self._end_expected = self._planned_hold = False
            self._mode = GovernorMode.IDLE
            self._hold_until = math.inf
            self._target = self._setpoint
            self._emit(DiagnosticLevel.OK, "resumed", f"resumed at {self._setpoint:.3f}°")
        return setpoint

    # -- reporting ------------------------------------------------------------------------------
    def drain_events(self) -> list[GovernorEvent]:
        """Events since the last call, oldest first (the queue is bounded; see counters)."""
        events = list(self._events)
        self._events.clear()
        return events

    def status(self) -> GovernorStatus:
        """Summary for /diagnostics: ERROR while a watchdog trip is active, WARN when stopped or
        when commands were refused/clamped since the previous status, else OK."""
        if self._tripped:
            level, message = DiagnosticLevel.ERROR, "watchdog tripped: no pitch commands"
        elif self._stopped:
            level, message = DiagnosticLevel.WARN, "stopped on request"
        elif self._reported_since_status:
            level, message = DiagnosticLevel.WARN, "pitch commands refused or clamped"
        else:
            level, message = DiagnosticLevel.OK, self._mode.value
        self._reported_since_status = False
        values = {f.name: str(getattr(self.counters, f.name)) for f in fields(self.counters)}
        values["mode"] = self._mode.value
        values["stream_end_expected"] = str(self._end_expected)
        values["setpoint_deg"] = f"{self._setpoint:.4f}"
        return GovernorStatus(level, message, self._mode, self._setpoint, values)

    # -- internals ------------------------------------------------------------------------------
    def _checked_time(self, t_s: float) -> float:
        t = float(t_s)
        if not math.isfinite(t):
            raise ValueError(f"SafetyGovernor: time must be finite, got {t_s!r}")
        if t < self._t:
            # A message older than the last call (reordering, a clock step): no time elapses.
            self.counters.time_reversals += 1
            self._emit(
                DiagnosticLevel.WARN,
                "time_reversed",
                f"time went backwards from {self._t:.6f} s to {t:.6f} s; treated as no time",
            )
            return self._t
        return t

    def _emit(
        self,
        level: DiagnosticLevel,
        kind: str,
        message: str,
        requested_deg: float | None = None,
        applied_deg: float | None = None,
    ) -> None:
        if len(self._events) == self._events.maxlen:
            self.counters.events_dropped += 1
        if level >= DiagnosticLevel.WARN:
            self._reported_since_status = True
        self._events.append(
            GovernorEvent(self._t, level, kind, message, requested_deg, applied_deg)
        )

    def _enter_hold(self, t: float) -> None:
        self._mode = GovernorMode.HOLDING
        self._hold_until = t + self.limits.hold_s
        self._target = self._setpoint

    def _advance(self, t: float) -> float:
        """Run the mode machine from self._t to t; return the setpoint at t."""
        lim = self.limits
        start_setpoint = self._setpoint
        elapsed = t - self._t
        setpoint = self._setpoint
        while self._t < t:
            mode = self._mode
            if mode is GovernorMode.TRACKING:
                trip_t = self._last_command_t + lim.watchdog_timeout_s
                if t <= trip_t:
                    setpoint = _move_toward(
                        setpoint, self._target, lim.max_rate_deg_s * (t - self._t)
                    )
                    self._t = t
                else:
                    dt = max(trip_t - self._t, 0.0)
                    setpoint = _move_toward(setpoint, self._target, lim.max_rate_deg_s * dt)
                    self._t = max(trip_t, self._t)
                    self._setpoint = setpoint
                    then = (
                        f"holding {setpoint:.3f}° for {lim.hold_s} s, then ramping to "
                        f"{lim.safe_angle_deg}° at {lim.ramp_rate_deg_s}°/s"
                    )
                    if self._end_expected:
                        self._end_expected = False  # consumed: this silence is the end
                        self._planned_hold = True
                        self._emit(
                            DiagnosticLevel.OK,
                            "stream_end",
                            f"{self._end_reason}: no pitch command since; {then}",
                        )
                    else:
                        self._tripped = True
                        self.counters.watchdog_trips += 1
                        self._emit(
                            DiagnosticLevel.ERROR,
                            "watchdog",
                            f"no pitch command for {lim.watchdog_timeout_s} s: {then}",
                        )
                    self._enter_hold(self._t)
            elif mode is GovernorMode.HOLDING:
                if t < self._hold_until:
                    self._t = t
                else:
                    self._t = max(self._hold_until, self._t)
                    self._mode = GovernorMode.RAMPING
            elif mode is GovernorMode.RAMPING:
                remaining = abs(lim.safe_angle_deg - setpoint) / lim.ramp_rate_deg_s
                if self._t + remaining <= t:
                    self._t += remaining
                    setpoint = lim.safe_angle_deg
                    self._setpoint = setpoint
                    self._mode = GovernorMode.SAFE
                    self._emit(
                        DiagnosticLevel.OK if self._planned_hold else DiagnosticLevel.WARN,
                        "safe",
                        f"at safe angle {lim.safe_angle_deg}°",
                    )
                else:
                    step = lim.ramp_rate_deg_s * (t - self._t)
                    setpoint = _move_toward(setpoint, lim.safe_angle_deg, step)
                    self._t = t
            elif mode is GovernorMode.SAFE:
                # Normally already there; finishes the ramp if a long gap capped the last step.
                step = lim.ramp_rate_deg_s * (t - self._t)
                setpoint = _move_toward(setpoint, lim.safe_angle_deg, step)
                self._t = t
            else:  # IDLE: holds
                self._t = t
        self._t = t
        # However long the gap since the last call, one call moves by a bounded step.
        max_step = lim.max_rate_deg_s * min(elapsed, self.max_step_interval_s)
        setpoint = _move_toward(start_setpoint, setpoint, max_step)
        # Approach a limit exponentially (time constant limit_approach_s): a rate-limited ramp
        # that stops dead at the limit makes an underdamped position loop overshoot it
        # (ζ = 0.7: ~0.15° at 150°/s); an exponential approach does not (docs/design.md §8).
        if lim.limit_approach_s > 0 and elapsed > 0:
            keep = math.exp(-elapsed / lim.limit_approach_s)
            if setpoint > start_setpoint:
                room = max(lim.max_deg - start_setpoint, 0.0)
                setpoint = min(setpoint, lim.max_deg - room * keep)
            elif setpoint < start_setpoint:
                room = max(start_setpoint - lim.min_deg, 0.0)
                setpoint = max(setpoint, lim.min_deg + room * keep)
        self._setpoint = min(max(setpoint, lim.min_deg), lim.max_deg)
        return self._setpoint
