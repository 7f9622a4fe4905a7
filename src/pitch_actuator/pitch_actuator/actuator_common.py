"""What the simulated and the hardware actuator nodes share: limits, safety, diagnostics.

Both nodes put every command through the same :class:`~pitch_actuator.safety.SafetyGovernor`
(limits, rate limit, NaN refusal, watchdog hold-then-ramp, stop requests) and report it the
same way on ``/diagnostics`` (diagnostic_msgs/DiagnosticArray).
"""

import math
from dataclasses import fields
from typing import Any

from rig_runtime.diagnostics import diagnostic_array

from rig_runtime import Node, Parameter

from .safety import ActuatorLimits, GovernorEvent, SafetyGovernor

LIMIT_PARAMETERS = [
    Parameter("min_deg", -10.0, "lowest pitch setpoint ever sent [deg]", min=-90.0, max=90.0),
    Parameter("max_deg", 35.0, "highest pitch setpoint ever sent [deg]", min=-90.0, max=90.0),
    Parameter("max_rate_deg_s", 150.0, "setpoint rate limit [deg/s]", min=0.1, max=2000.0),
    Parameter("safe_angle_deg", 0.0, "where the wing goes after a stop or lost commands [deg]"),
    Parameter("watchdog_timeout_s", 0.25, "no command this long trips the watchdog [s]", min=0.005),
    Parameter("hold_s", 1.0, "hold still this long after a trip or stop [s]", min=0.0),
    Parameter("ramp_rate_deg_s", 5.0, "rate of the ramp to the safe angle [deg/s]", min=0.01),
    Parameter(
        "limit_approach_s",
        0.02,
        "time constant of the exponential approach to a limit, against overshoot [s]",
        min=0.0,
        max=1.0,
    ),
    Parameter("initial_deg", 0.0, "pitch at start-up [deg]"),
    Parameter("diagnostics_period_s", 1.0, "period of /diagnostics status [s]", min=0.05),
]


def limits_from_params(params: Any) -> ActuatorLimits:
    """The node's limit parameters (LIMIT_PARAMETERS, named as the fields) as ActuatorLimits."""
    return ActuatorLimits.from_mapping({f.name: params[f.name] for f in fields(ActuatorLimits)})


def command_position(msg: Any) -> float:
    """The ``pitch`` joint's position of a JointState command (NaN if absent)."""
    names = list(msg.name)
    positions = msg.position
    if "pitch" in names:
        index = names.index("pitch")
    elif not names and len(positions) == 1:
        index = 0
    else:
        return math.nan
    return float(positions[index]) if index < len(positions) else math.nan


class SafetyReporter:
    """Logs governor events and publishes /diagnostics (periodically and on events)."""

    def __init__(self, node: Node, governor: SafetyGovernor, hardware_id: str) -> None:
        self.node = node
        self.governor = governor
        self.hardware_id = hardware_id
        self.pub = node.create_publisher("diagnostic_msgs/msg/DiagnosticArray", "/diagnostics")
        self.extra: dict[str, str] = {}
        self._last_publish = 0.0
        self._pending = False
        node.create_timer(node.params["diagnostics_period_s"], self.publish)
        node.create_timer(0.1, self._flush_events)

    def _flush_events(self) -> None:
        events: list[GovernorEvent] = self.governor.drain_events()
        for event in events:
            log = self.node.logger.error if event.level >= 2 else self.node.logger.warning
            if event.level == 0:
                log = self.node.logger.info
            log("%s", event.message)
        if events:
            self.publish()

    def publish(self) -> None:
        status = self.governor.status()
        values = dict(status.values)
        values.update(self.extra)
        msg = diagnostic_array(
            self.node,
            f"{self.node.name}: pitch actuator safety",
            int(status.level),
            status.message,
            self.hardware_id,
            values,
        )
        self.pub.publish(msg)
