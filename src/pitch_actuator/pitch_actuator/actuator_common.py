"""What the simulated and the hardware actuator nodes share: limits, safety, diagnostics.

Both nodes put every command through the same :class:`~pitch_actuator.safety.SafetyGovernor`
(limits, rate limit, NaN refusal, watchdog hold-then-ramp, stop requests) and report it the
same way on ``/diagnostics`` (diagnostic_msgs/DiagnosticArray).
"""

import math
from dataclasses import fields
from typing import Any

from rig_runtime import Node, Parameter
from rig_runtime.diagnostics import diagnostic_array
from rig_runtime.interface import DIAGNOSTICS, PITCH_JOINT, joint_position
from rig_runtime.qos_profiles import DEFAULT_QOS

from .safety import GovernorEvent, SafetyGovernor, SafetyLimits

_DEFAULT = SafetyLimits()  # min_deg, max_deg, max_rate_deg_s: rig_runtime.interface.ActuatorLimits

# One parameter per SafetyLimits field, named as the field (limits_from_params reads them back).
LIMIT_PARAMETERS = [
    Parameter(
        "min_deg", _DEFAULT.min_deg, "lowest pitch setpoint ever sent [deg]", min=-90.0, max=90.0
    ),
    Parameter(
        "max_deg", _DEFAULT.max_deg, "highest pitch setpoint ever sent [deg]", min=-90.0, max=90.0
    ),
    Parameter(
        "max_rate_deg_s",
        _DEFAULT.max_rate_deg_s,
        "setpoint rate limit [deg/s]",
        min=0.1,
        max=2000.0,
    ),
    Parameter(
        "safe_angle_deg",
        _DEFAULT.safe_angle_deg,
        "where the wing goes after a stop or lost commands [deg]",
    ),
    Parameter(
        "watchdog_timeout_s",
        _DEFAULT.watchdog_timeout_s,
        "no command this long trips the watchdog [s]",
        min=0.005,
    ),
    Parameter("hold_s", _DEFAULT.hold_s, "hold still this long after a trip or stop [s]", min=0.0),
    Parameter(
        "ramp_rate_deg_s",
        _DEFAULT.ramp_rate_deg_s,
        "rate of the ramp to the safe angle [deg/s]",
        min=0.01,
    ),
    Parameter(
        "limit_approach_s",
        _DEFAULT.limit_approach_s,
        "time constant of the exponential approach to a limit, against overshoot [s]",
        min=0.0,
        max=1.0,
    ),
    Parameter("initial_deg", 0.0, "pitch at start-up [deg]"),
    Parameter("diagnostics_period_s", 1.0, "period of /diagnostics status [s]", min=0.05),
]


def limits_from_params(params: Any) -> SafetyLimits:
    """The node's limit parameters (LIMIT_PARAMETERS, named as the fields) as SafetyLimits."""
    return SafetyLimits.from_mapping({f.name: params[f.name] for f in fields(SafetyLimits)})


def command_position(msg: Any) -> float:
    """The ``pitch`` joint's position of a JointState command, NaN (refused) if it has none."""
    position = joint_position(msg, PITCH_JOINT)
    return math.nan if position is None else position


TRACKING_TOLERANCE_DEG = 1e-6


class CommandTracking:
    """Anomalies of the command stream, by command stamp (rig_runtime.anomaly).

    A command the actuator did not follow exactly (clamped to a limit, refused as NaN, rate
    limited, held after a watchdog trip or a stop) belongs to a ``not_tracking`` episode that
    lasts until a command is followed again; command stamps that go backwards or skip samples
    are a ``time_discontinuity``. The node passes every command with its stamp, the commanded
    and the applied angle.

    On the rig the governor's rate budget accrues with wall time, and DDS may deliver commands
    in a burst, microseconds apart: a command within the limits that the rate limit alone held
    back (``catch_up=True``) waits for the node's next control tick (``settle``). A tick may
    come microseconds after a command too, so the commands waiting then are followed when the
    setpoint is within ``catch_up_deg`` of the newest of them (one tick's rate budget: the
    setpoint moves toward it at the full rate), or when a later command is followed at once;
    otherwise each is ``not_tracking`` at its own stamp. A stream the actuator cannot follow
    (faster than its rate limit, or held after a trip) falls further behind and is reported.
    """

    def __init__(self, node: Node, fs: float | None = None, catch_up_deg: float = 0.0) -> None:
        self.anomalies = node.anomalies
        self.period_ns = None if fs is None else round(1e9 / fs)
        self.catch_up_deg = catch_up_deg
        self.last_stamp_ns: int | None = None
        self.pending: list[tuple[int, float]] = []  # (stamp, commanded) held back since a tick

    def settle(self, setpoint_deg: float, caught_up: bool = False) -> None:
        """At a control tick: judge the commands held back since the last one (``caught_up``:
        a later command was followed at once, so the setpoint went past them)."""
        pending, self.pending = self.pending, []
        if pending and abs(setpoint_deg - pending[-1][1]) <= max(
            self.catch_up_deg, TRACKING_TOLERANCE_DEG
        ):
            caught_up = True  # on its way to the newest at the full rate
        for stamp_ns, commanded_deg in pending:
            self._judge(stamp_ns, commanded_deg, commanded_deg if caught_up else setpoint_deg)

    def command(
        self, stamp_ns: int, commanded_deg: float, applied_deg: float, catch_up: bool = False
    ) -> None:
        last = self.last_stamp_ns
        if last is not None and self.period_ns is not None:
            step = stamp_ns - last
            if step <= 0 or step > 1.5 * self.period_ns:
                self.anomalies.point(
                    "time_discontinuity",
                    min(last, stamp_ns),
                    max(last, stamp_ns),
                    f"command stamp went from {last} to {stamp_ns} ns "
                    f"({step / self.period_ns:+.2f} samples)",
                )
        self.last_stamp_ns = stamp_ns if last is None else max(last, stamp_ns)
        followed_now = abs(applied_deg - commanded_deg) <= TRACKING_TOLERANCE_DEG
        if catch_up and not followed_now:
            self.pending.append((stamp_ns, commanded_deg))
            return
        if self.pending:  # in stamp order: those held back first
            self.settle(applied_deg, caught_up=followed_now)
        self._judge(stamp_ns, commanded_deg, applied_deg)

    def _judge(self, stamp_ns: int, commanded_deg: float, applied_deg: float) -> None:
        followed = math.isfinite(commanded_deg) and (
            abs(applied_deg - commanded_deg) <= TRACKING_TOLERANCE_DEG
        )
        if followed:
            self.anomalies.clear("not_tracking")
            self.anomalies.end("watchdog", stamp_ns)
        else:
            self.anomalies.mark(
                "not_tracking",
                stamp_ns,
                f"commanded {commanded_deg:.4f}°, applied {applied_deg:.4f}° (clamped, refused, "
                "rate limited, or held after a watchdog trip or stop)",
            )

    def watchdog_tripped(self, detail: str) -> None:
        """The governor's watchdog tripped between commands (rig: wall-clock time): the episode
        starts after the last command and ends with the next command followed exactly."""
        if self.last_stamp_ns is not None:
            self.anomalies.begin("watchdog", self.last_stamp_ns, detail)


class SafetyReporter:
    """Logs governor events and publishes /diagnostics (periodically and on events)."""

    def __init__(self, node: Node, governor: SafetyGovernor, hardware_id: str) -> None:
        self.node = node
        self.governor = governor
        self.hardware_id = hardware_id
        from diagnostic_msgs.msg import DiagnosticArray

        self.pub = node.create_publisher(DiagnosticArray, DIAGNOSTICS.name, DEFAULT_QOS)
        self.extra: dict[str, str] = {}
        node.create_timer(node.get_parameter("diagnostics_period_s").value, self.publish)
        node.create_timer(0.1, self._flush_events)

    def _flush_events(self) -> None:
        events: list[GovernorEvent] = self.governor.drain_events()
        logger = self.node.get_logger()
        for event in events:
            # One call per severity: rclpy refuses a call site whose severity changes.
            if event.level >= 2:
                logger.error(event.message)
            elif event.level == 1:
                logger.warning(event.message)
            else:
                logger.info(event.message)
        if events:
            self.publish()

    def publish(self) -> None:
        status = self.governor.status()
        values = dict(status.values)
        values.update(self.extra)
        msg = diagnostic_array(
            f"{self.node.name}: pitch actuator safety",
            int(status.level),
            status.message,
            self.hardware_id,
            values,
        )
        self.pub.publish(msg)
