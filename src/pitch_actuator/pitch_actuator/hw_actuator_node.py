"""Hardware actuator node: pitch commands to the real-time position controller over UDP.

Every ``/pitch/command`` goes through the shared safety layer (limits, rate limit, NaN refusal,
watchdog hold-then-ramp, ``/pitch/stop``) and is sent as a setpoint over the PWAC UDP protocol
(docs/protocols.md) with a sequence number; the controller applies only setpoints newer than
the last it applied. Feedback arrives at the controller's rate and is published on
``/pitch/state`` with the controller's acquisition stamps (``stamp_source: controller``, for a
PTP-synchronised controller clock) or the host receive time (``stamp_source: host``). Link
health (loss, duplicates, reordering, feedback age) goes to ``/diagnostics``.

Start barrier: the node reports ready only once the controller has answered (its first
feedback), so the experiment cannot start against a controller that is off or unreachable.
Commands not followed exactly and watchdog trips are reported on ``/experiment/anomaly``.
"""

import math
import sys
import time
from collections.abc import Sequence
from typing import Any

from std_msgs.msg import Bool

from aero_rig_interfaces.msg import SegmentEvent
from rig_runtime import Node, Parameter, new_message, run_node, set_stamp, stamp_to_ns
from rig_runtime.interface import (
    EXPERIMENT_SEGMENT,
    PITCH_COMMAND,
    PITCH_JOINT,
    PITCH_STATE,
    PITCH_STOP,
)
from rig_runtime.qos_profiles import DEFAULT_QOS, QOS_BY_NAME, topic_qos

from .actuator_common import (
    LIMIT_PARAMETERS,
    CommandTracking,
    SafetyReporter,
    command_position,
    limits_from_params,
)
from .controller_link import ControllerLink, ControllerLinkConfig
from .controller_protocol import Feedback, Status
from .safety import GovernorMode, SafetyGovernor

PARAMETERS = [
    *LIMIT_PARAMETERS,
    Parameter("controller_host", "127.0.0.1", "IP address of the position controller"),
    Parameter("controller_port", 5700, "UDP port of the position controller", min=1, max=65535),
    Parameter("bind_host", "0.0.0.0", "local interface for feedback"),
    Parameter("bind_port", 0, "local UDP port for feedback (0 = any)", min=0, max=65535),
    Parameter(
        "heartbeat_period_s",
        0.05,
        "heartbeat period when no setpoint flows [s]",
        min=0.001,
        max=1.0,
    ),
    Parameter(
        "update_rate_hz", 200.0, "safety/watchdog update and feedback poll rate [Hz]", min=10.0
    ),
    Parameter(
        "stamp_source", "controller", "stamp of /pitch/state", choices=("controller", "host")
    ),
    Parameter(
        "state_qos", "sensor", "QoS of /pitch/state", choices=("stream", "sensor", "default")
    ),
]


class HwActuatorNode(Node):
    NODE_NAME = "hw_actuator"
    PARAMETERS = PARAMETERS

    def __init__(self, argv: Sequence[str] | None = None) -> None:
        super().__init__(self.NODE_NAME, self.PARAMETERS, argv)
        p = self.parameter_values()
        self.limits = limits_from_params(p)
        self.link = ControllerLink(
            ControllerLinkConfig(
                controller_host=p["controller_host"],
                controller_port=p["controller_port"],
                bind_host=p["bind_host"],
                bind_port=p["bind_port"],
                heartbeat_period_s=p["heartbeat_period_s"],
            )
        )
        self.t_origin = time.monotonic()
        self.governor = SafetyGovernor(self.limits, initial_deg=p["initial_deg"], t_s=0.0)
        self.sent_setpoint_deg: float | None = None
        self.on_shutdown(lambda: self.link.close(hold=True))
        # The command and state streams on the serialized path (node.py).
        self.state_pub = self.create_publisher(
            PITCH_STATE.type, PITCH_STATE.name, QOS_BY_NAME[p["state_qos"]]
        )
        self.reporter = SafetyReporter(
            self, self.governor, f"pwac://{p['controller_host']}:{p['controller_port']}"
        )
        self.create_subscription(
            PITCH_COMMAND.type,
            PITCH_COMMAND.name,
            self.on_command,
            topic_qos(PITCH_COMMAND),
            required=True,
        )
        # One control tick's rate budget: what a command arriving just before a tick can still
        # lag by although the setpoint follows it at the full rate.
        self.tracking = CommandTracking(
            self, catch_up_deg=self.limits.max_rate_deg_s / p["update_rate_hz"]
        )
        self.trips = 0
        self.set_ready(
            False,
            f"no feedback from the position controller at "
            f"{p['controller_host']}:{p['controller_port']} yet",
        )
        self.create_subscription(Bool, PITCH_STOP.name, self.on_stop, DEFAULT_QOS)
        # The silence after the plan's last command is its end, not a lost stream.
        self.create_subscription(
            SegmentEvent, EXPERIMENT_SEGMENT.name, self.on_segment, topic_qos(EXPERIMENT_SEGMENT)
        )
        self.create_timer(1.0 / p["update_rate_hz"], self.on_timer)
        self.create_timer(p["diagnostics_period_s"], self.update_link_diagnostics)
        self.published = 0
        self.controller_stamps = p["stamp_source"] == "controller"
        self.get_logger().info(
            f"controller link {self.link.local_address} -> {self.link.controller_address}"
        )

    def _now(self) -> float:
        return time.monotonic() - self.t_origin

    def _send(self, setpoint_deg: float) -> None:
        # Resend only what changed; the heartbeat keeps the controller's watchdog fed.
        if setpoint_deg != self.sent_setpoint_deg:
            self.link.send_setpoint(math.radians(setpoint_deg))
            self.sent_setpoint_deg = setpoint_deg

    def on_command(self, msg: Any) -> None:
        commanded_deg = math.degrees(command_position(msg))
        setpoint_deg = self.governor.command(self._now(), commanded_deg)
        # Within the limits and tracking, only the rate limit can hold a command back: over
        # wall time, for commands delivered in a burst. It is judged at the next control tick.
        catch_up = (
            self.limits.min_deg <= commanded_deg <= self.limits.max_deg
            and self.governor.mode is GovernorMode.TRACKING
        )
        self.tracking.command(
            stamp_to_ns(msg.header.stamp), commanded_deg, setpoint_deg, catch_up=catch_up
        )
        self._send(setpoint_deg)

    def on_segment(self, msg: SegmentEvent) -> None:
        if msg.event == "plan_end":
            self.governor.end_stream(self._now(), "the plan has ended")

    def on_stop(self, msg: Bool) -> None:
        if msg.data:
            self._send(self.governor.stop(self._now(), "stop requested on /pitch/stop"))
        else:
            self.governor.resume(self._now())

    def on_timer(self) -> None:
        # Watchdog and ramp advance with time even when commands stop.
        setpoint_deg = self.governor.update(self._now())
        self._send(setpoint_deg)
        self.tracking.settle(setpoint_deg)
        if self.governor.counters.watchdog_trips > self.trips:
            self.trips = self.governor.counters.watchdog_trips
            self.tracking.watchdog_tripped("no pitch command within the watchdog timeout")
        for feedback in self.link.poll():
            if self.published == 0:
                self.set_ready(True)
            self.publish_state(feedback)
            # After a controller-side watchdog hold only a new setpoint resumes motion.
            if feedback.status & Status.WATCHDOG and self.governor.mode.value == "tracking":
                self.sent_setpoint_deg = None

    def publish_state(self, feedback: Feedback) -> None:
        msg = new_message(
            PITCH_STATE.type,
            name=[PITCH_JOINT],
            position=[feedback.position_rad],
            velocity=[feedback.velocity_rad_s],
        )
        stamp = feedback.stamp_ns if self.controller_stamps else time.time_ns()
        set_stamp(msg.header.stamp, stamp)
        self.state_pub.publish(msg)
        self.published += 1
        if feedback.status & Status.LIMIT:
            self.reporter.extra["controller_limit"] = "target clamped by controller hard limits"

    def update_link_diagnostics(self) -> None:
        stats = self.link.statistics()
        fb = stats.feedback
        self.reporter.extra.update(
            {
                "feedback_received": str(fb.received),
                "feedback_lost": str(fb.lost),
                "feedback_duplicated": str(fb.duplicated),
                "feedback_reordered": str(fb.reordered),
                "controller_rx_lost": str(stats.controller_rx_lost),
                "setpoints_sent": str(stats.setpoints_sent),
                "last_feedback_age_s": f"{stats.last_feedback_age_s:.3f}"
                if stats.last_feedback_age_s is not None
                else "never",
                "states_published": str(self.published),
            }
        )
        if stats.last_feedback_age_s is None or stats.last_feedback_age_s > 0.5:
            self.get_logger().warning("no feedback from the controller for > 0.5 s")


def main(argv: list[str] | None = None) -> int:
    return run_node(HwActuatorNode, argv, description=__doc__ or "")


if __name__ == "__main__":
    sys.exit(main())
