"""Simulated actuator node (docs/design.md §5-§6): the position loop of dynamics.py behind the
shared safety layer.

Reactive: every ``/pitch/command`` sample k yields one ``/pitch/state`` sample k with the same
stamp, so a simulated run is deterministic for a seed whatever the speed. The state carries the
joint ``pitch`` (logged position: noise, quantisation; velocity) and, as simulation ground
truth, the joint ``alpha_true`` (true pitch + free-stream gust), which only the simulated wing
reads. Experiment time advances with the commands, so pauses of a slow graph are harmless.
The command stream counts as lost when its publisher has left the graph (DDS matching) for
``watchdog_timeout_s``, or when no command came for ``stream_timeout_s`` of wall time even
though a publisher is still there (a hung generator); then the node keeps stepping the model in
real time: the governor holds, then ramps to the safe angle, as the rig would
(stream_watchdog.py). ``/pitch/stop`` (std_msgs/Bool): true = stop (hold, then safe angle),
false = resume.

Every sample stepped without a command is reported as a ``free_run`` anomaly on
``/experiment/anomaly``, like every command not followed exactly (``not_tracking``: clamped,
refused, rate limited, held) and every jump of the command stamps (``time_discontinuity``): the
identification excludes the periods they touch.
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
    ALPHA_TRUE_JOINT,
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
from .dynamics import ActuatorModel, ActuatorParams
from .safety import SafetyGovernor
from .stream_watchdog import SilentStreamWatchdog

PARAMETERS = [
    *LIMIT_PARAMETERS,
    Parameter("fs", 200.0, "command and state sample rate [Hz]", min=1.0, max=10000.0),
    Parameter("seed", 0, "seed of the encoder noise and the gust", min=0),
    Parameter("natural_frequency_hz", 15.0, "position loop natural frequency [Hz]", min=0.1),
    Parameter("damping_ratio", 0.7, "position loop damping ratio", min=0.01, max=10.0),
    Parameter("delay_s", 0.001, "command delay [s]", min=0.0, max=0.1),
    Parameter("actuator_rate_limit_deg_s", 250.0, "physical rate limit [deg/s]", min=1.0),
    Parameter("noise_std_deg", 0.01, "logged-pitch noise std [deg]", min=0.0),
    Parameter("encoder_step_deg", 0.005, "logged-pitch quantisation [deg]", min=0.0),
    Parameter("gust_std_deg", 0.2, "free-stream gust on alpha, std [deg]", min=0.0),
    Parameter("gust_time_constant_s", 0.1, "gust correlation time [s]", min=1e-3),
    Parameter(
        "stream_timeout_s",
        30.0,
        "wall time without commands, publisher still present, after which the simulation runs "
        "on in real time [s]",
        min=0.01,
    ),
    Parameter(
        "state_qos", "stream", "QoS of /pitch/state", choices=("stream", "sensor", "default")
    ),
]


class SimActuatorNode(Node):
    NODE_NAME = "sim_actuator"
    PARAMETERS = PARAMETERS

    def __init__(self, argv: Sequence[str] | None = None) -> None:
        super().__init__(self.NODE_NAME, self.PARAMETERS, argv)
        p = self.parameter_values()
        self.fs = p["fs"]
        self.limits = limits_from_params(p)
        self.model = ActuatorModel(
            ActuatorParams(
                natural_frequency_hz=p["natural_frequency_hz"],
                damping_ratio=p["damping_ratio"],
                delay_s=p["delay_s"],
                max_rate_deg_s=p["actuator_rate_limit_deg_s"],
                noise_std_deg=p["noise_std_deg"],
                encoder_step_deg=p["encoder_step_deg"],
                gust_std_deg=p["gust_std_deg"],
                gust_time_constant_s=p["gust_time_constant_s"],
                initial_deg=min(max(p["initial_deg"], p["min_deg"]), p["max_deg"]),
            ),
            fs=self.fs,
            seed=p["seed"],
        )
        self.governor = SafetyGovernor(self.limits, initial_deg=p["initial_deg"], t_s=0.0)
        # The command and state streams on the serialized path (node.py).
        self.state_pub = self.create_publisher(
            PITCH_STATE.type, PITCH_STATE.name, QOS_BY_NAME[p["state_qos"]]
        )
        self.reporter = SafetyReporter(self, self.governor, "sim_actuator")
        self.command_sub = self.create_subscription(
            PITCH_COMMAND.type,
            PITCH_COMMAND.name,
            self.on_command,
            topic_qos(PITCH_COMMAND),
            required=True,
        )
        self.create_subscription(Bool, PITCH_STOP.name, self.on_stop, DEFAULT_QOS)
        # After the plan's end the generator may leave: running on is then the expected end of
        # the run, not an anomaly of the experiment.
        self.create_subscription(
            SegmentEvent, EXPERIMENT_SEGMENT.name, self.on_segment, topic_qos(EXPERIMENT_SEGMENT)
        )
        self.plan_ended = False
        self.t_origin_ns: int | None = None
        self.last_stamp_ns: int | None = None
        self.watchdog = SilentStreamWatchdog(
            self.fs, p["stream_timeout_s"], self.limits.watchdog_timeout_s
        )
        self.tracking = CommandTracking(self, self.fs)
        self.create_timer(1.0 / self.fs, self.on_timer)

    def _time_s(self, stamp_ns: int) -> float:
        if self.t_origin_ns is None:
            # The actuator was at rest one sample before the first command, so that command is
            # reachable within the rate limit like every later one (governor time starts at 0).
            self.t_origin_ns = stamp_ns - round(1e9 / self.fs)
        return (stamp_ns - self.t_origin_ns) / 1e9

    def _step_and_publish(self, setpoint_rad: float, stamp_ns: int) -> None:
        sample = self.model.step(setpoint_rad)
        msg = new_message(
            PITCH_STATE.type,
            name=[PITCH_JOINT, ALPHA_TRUE_JOINT],
            position=[sample.position_rad, sample.alpha_true_rad],
            velocity=[sample.velocity_rad_s, sample.velocity_rad_s],
        )
        set_stamp(msg.header.stamp, stamp_ns)
        self.state_pub.publish(msg)
        self.last_stamp_ns = stamp_ns

    def on_command(self, msg: Any) -> None:
        stamp_ns = stamp_to_ns(msg.header.stamp)
        if self.watchdog.command(time.monotonic()):
            self.anomalies.end("free_run")
            self.get_logger().warning("commands resumed: free run ended")
        commanded = command_position(msg)
        setpoint = self.governor.command_rad(self._time_s(stamp_ns), commanded)
        self.tracking.command(stamp_ns, math.degrees(commanded), math.degrees(setpoint))
        self._step_and_publish(setpoint, stamp_ns)

    def on_segment(self, msg: SegmentEvent) -> None:
        if msg.event == "plan_end":
            self.plan_ended = True
            # The silence after the last command is the plan's end, not a lost stream.
            self.governor.end_stream(self.governor.t_s, "the plan has ended")

    def on_stop(self, msg: Bool) -> None:
        t = self._time_s(self.last_stamp_ns or time.time_ns())
        if msg.data:
            self.governor.stop(t, "stop requested on /pitch/stop")
        else:
            self.governor.resume(t)

    def on_timer(self) -> None:
        # Without commands the actuator lives on in real time: hold, then ramp to safe.
        if self.last_stamp_ns is None:
            return
        publisher_count = getattr(self.command_sub, "publisher_count", None)
        present = publisher_count is None or publisher_count() > 0
        now = time.monotonic()
        due = self.watchdog.due(now, present, self.governor.stopped)
        if not due:
            return
        if self.plan_ended:
            if not self.watchdog.running_on:
                self.get_logger().info(
                    "the plan has ended and its commands stopped: holding, then ramping to the "
                    "safe angle in real time"
                )
            for _ in range(due):
                stamp_ns = self.last_stamp_ns + round(1e9 / self.fs)
                self._step_and_publish(
                    math.radians(self.governor.update(self._time_s(stamp_ns))), stamp_ns
                )
                self.watchdog.stepped()
            return
        if not self.watchdog.running_on:
            first_ns = self.last_stamp_ns + round(1e9 / self.fs)
            detail = (
                f"no command for {self.watchdog.silent_s(now):.2f} s "
                f"({'publisher still there' if present else 'no command publisher left'}): "
                "running on in real time (hold, then ramp to the safe angle)"
            )
            self.get_logger().warning(detail)
            self.anomalies.begin("free_run", first_ns, detail)
        for _ in range(due):
            stamp_ns = self.last_stamp_ns + round(1e9 / self.fs)
            setpoint_deg = self.governor.update(self._time_s(stamp_ns))
            self._step_and_publish(math.radians(setpoint_deg), stamp_ns)
            self.anomalies.mark("free_run", stamp_ns)
            self.watchdog.stepped()


def main(argv: list[str] | None = None) -> int:
    return run_node(SimActuatorNode, argv, description=__doc__ or "")


if __name__ == "__main__":
    sys.exit(main())
