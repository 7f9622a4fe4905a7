"""The rig's interface contract: every topic with its type and QoS, and the joint names.

This is the one place the graph's interface is written (docs/design.md §4). Nodes, the view,
the offline fit, the launch files and the tests take names, types and QoS from here; a topic
name written as a literal elsewhere is a second copy that can drift. The pitch actuator's limits
(:class:`ActuatorLimits`), which the plan is checked against and the actuator enforces, are part
of the contract too.

The module imports nothing but the standard library and :mod:`rig_runtime.qos`, so the ROS
launch files and offline tools can use it without loading a middleware.

Types are ROS 2 interface names from ros-jazzy-common-interfaces and the rig's own
aero_rig_interfaces (src/aero_rig_interfaces: the experiment's events, the identifier's models,
the start barrier's reports and the control service); values on the wire are SI
(angles in rad, pressures in Pa) as REP 103 asks. A node may offer another QoS where its
parameters say so (``state_qos``, ``taps_qos``, the lift node's ``qos``); ``qos`` below is
the profile every node of the project uses by default (names from :data:`rig_runtime.qos.PROFILES`).
"""

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any, Self

__all__ = [
    "ALPHA_TRUE_JOINT",
    "DIAGNOSTICS",
    "EXPERIMENT_ANOMALY",
    "EXPERIMENT_CONTROL",
    "EXPERIMENT_PLAN",
    "EXPERIMENT_SEGMENT",
    "GRAPH_READY",
    "IDENTIFICATION_MODEL",
    "IDENTIFICATION_STATUS",
    "PITCH_COMMAND",
    "PITCH_JOINT",
    "PITCH_STATE",
    "PITCH_STOP",
    "PRESSURE_TAPS",
    "PRESSURE_TARE",
    "RECORDED_TOPICS",
    "SERVICES",
    "TOPICS",
    "WING_COEFFICIENTS",
    "WING_PROGRESS",
    "ActuatorLimits",
    "LimitsError",
    "Service",
    "Topic",
    "joint_position",
]


@dataclass(frozen=True)
class Topic:
    """One topic of the graph: name, ROS 2 type, default QoS profile, and what it carries."""

    name: str
    type: str
    qos: str
    content: str


PITCH_COMMAND = Topic(
    "/pitch/command",
    "sensor_msgs/msg/JointState",
    "stream",
    "pitch set-point of joint 'pitch' [rad]; sample k of the plan stamped t0 + k/fs",
)
PITCH_STATE = Topic(
    "/pitch/state",
    "sensor_msgs/msg/JointState",
    "stream",
    "measured pitch [rad] and rate [rad/s] of joint 'pitch' (simulation adds 'alpha_true')",
)
PITCH_STOP = Topic(
    "/pitch/stop", "std_msgs/msg/Bool", "default", "true: the actuator holds and stops"
)
PRESSURE_TAPS = Topic(
    "/pressure/taps",
    "sensor_msgs/msg/PointCloud2",
    "stream",
    "49 tap pressures [Pa] as points x, y, z (tap position) and p; one cloud per scan",
)
PRESSURE_TARE = Topic(
    "/pressure/tare", "std_msgs/msg/Bool", "default", "true: the scanner re-zeroes its channels"
)
WING_COEFFICIENTS = Topic(
    "/wing/coefficients",
    "geometry_msgs/msg/Vector3Stamped",
    "stream",
    "x = C_l, y = C_d (pressure drag), z = C_m,c/4 by pressure integration, stamped as the taps",
)
WING_PROGRESS = Topic(
    "/wing/coefficients/progress",
    "std_msgs/msg/Header",
    "default",
    "the stamp of the lift's latest /wing/coefficients sample, at most every 5 ms: the credit "
    "of a simulated stream's flow control (multisine_gen.pacing)",
)
EXPERIMENT_PLAN = Topic(
    "/experiment/plan",
    "aero_rig_interfaces/msg/ExperimentPlan",
    "latched",
    "the experiment plan: id, revision, t0, rate, levels and realizations as fields, the whole "
    "plan as JSON in plan_json (multisine_gen.plan_format); every sample rebuildable",
)
EXPERIMENT_SEGMENT = Topic(
    "/experiment/segment",
    "aero_rig_interfaces/msg/SegmentEvent",
    "events",
    "an event at each segment boundary of the plan, plan_end or plan_aborted, and an adaptive "
    "run's decisions on the control requests (multisine_gen.plan_format)",
)
EXPERIMENT_ANOMALY = Topic(
    "/experiment/anomaly",
    "aero_rig_interfaces/msg/Anomaly",
    "events",
    "a stretch of the experiment that must be excluded, by stamp range (rig_runtime.anomaly)",
)
IDENTIFICATION_STATUS = Topic(
    "/identification/status",
    "diagnostic_msgs/msg/DiagnosticArray",
    "latched",
    "the identifier's state: periods buffered, clusters, refit progress, data quality",
)
IDENTIFICATION_MODEL = Topic(
    "/identification/model",
    "aero_rig_interfaces/msg/IdentificationModel",
    "latched",
    "the latest models: refit, levels, clusters and Table 1's cells as fields, the whole record "
    "(BLA, clusters, linear SS, PNLSS, predictions) as JSON in model_json",
)
GRAPH_READY = Topic(
    "/graph/ready",
    "aero_rig_interfaces/msg/ReadinessReport",
    "latched",
    "each node's readiness report, for the start barrier (rig_runtime.barrier)",
)
DIAGNOSTICS = Topic(
    "/diagnostics",
    "diagnostic_msgs/msg/DiagnosticArray",
    "default",
    "ROS diagnostics: safety events, link state, tap exclusions, each node's stream flow",
)

TOPICS: tuple[Topic, ...] = (
    PITCH_COMMAND,
    PITCH_STATE,
    PITCH_STOP,
    PRESSURE_TAPS,
    PRESSURE_TARE,
    WING_COEFFICIENTS,
    WING_PROGRESS,
    EXPERIMENT_PLAN,
    EXPERIMENT_SEGMENT,
    EXPERIMENT_ANOMALY,
    IDENTIFICATION_STATUS,
    IDENTIFICATION_MODEL,
    GRAPH_READY,
    DIAGNOSTICS,
)

# What a run records (the recorder's `topics` in config/recorder.yaml, and the ROS launch
# files' `record:=true`): the experiment's data, what the offline fit must exclude, the
# identifier's results and the diagnostics. Commands to the rig (stop, tare), the lift's
# progress (the coefficients' stamps again) and the start barrier's reports are not data.
RECORDED_TOPICS: tuple[Topic, ...] = tuple(
    t for t in TOPICS if t not in (PITCH_STOP, PRESSURE_TARE, WING_PROGRESS, GRAPH_READY)
)


@dataclass(frozen=True)
class Service:
    """One service of the graph: name, ROS 2 type, and what it does."""

    name: str
    type: str
    content: str


EXPERIMENT_CONTROL = Service(
    "/experiment/control",
    "aero_rig_interfaces/srv/ControlExperiment",
    "adaptive runs: the identifier's request to the generator after each measured period (end "
    "the realization, finish the level, add a realization, go on; multisine_gen.revision); the "
    "generator answers accepted or refused with its reason, and refuses outside an adaptive run",
)
SERVICES: tuple[Service, ...] = (EXPERIMENT_CONTROL,)

# Joint names in sensor_msgs/JointState.
PITCH_JOINT = "pitch"  # the wing's pitch angle (geometric angle of attack) [rad]
ALPHA_TRUE_JOINT = "alpha_true"  # simulation only: the plant's true angle [rad]


def joint_position(msg: Any, name: str = PITCH_JOINT) -> float | None:
    """Position of joint ``name`` in a sensor_msgs/JointState, or None.

    None when the message does not name the joint, has no position for it, or the position
    is not finite: a message without the joint is not a sample of it (no positional guess).
    """
    names: Sequence[str] = list(msg.name)
    if name not in names:
        return None
    index = names.index(name)
    position = msg.position
    if index >= len(position):
        return None
    value = float(position[index])
    return value if math.isfinite(value) else None


class LimitsError(ValueError):
    """Actuator limits that cannot be used (nothing may move with them)."""


@dataclass(frozen=True)
class ActuatorLimits:
    """What the pitch actuator accepts, in degrees and seconds as in the parameter files.

    The one declaration of the limits and their defaults: the plan checks
    (``multisine_gen.plan``), the generator node, both actuator nodes and their safety governor
    (``pitch_actuator.safety.SafetyLimits`` adds its watchdog and ramp settings) take them from
    here, and the parameter files in aero_rig/config hold the same values (a test checks).

    Attributes:
        min_deg, max_deg: allowed pitch range [deg].
        max_rate_deg_s: largest pitch rate [deg/s].

    Every field must be a finite number, min_deg < max_deg and max_rate_deg_s > 0
    (LimitsError otherwise); a subclass's fields are checked for being finite numbers too.
    """

    min_deg: float = -10.0
    max_deg: float = 35.0
    max_rate_deg_s: float = 150.0

    def __post_init__(self) -> None:
        name = type(self).__name__
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise LimitsError(f"{name}.{f.name} must be a number, got {value!r}")
            if not math.isfinite(value):
                raise LimitsError(f"{name}.{f.name} must be finite, got {value!r}")
        if not self.min_deg < self.max_deg:
            raise LimitsError(
                f"{name}: min_deg ({self.min_deg}) must be below max_deg ({self.max_deg}); "
                "fix the parameter file"
            )
        if self.max_rate_deg_s <= 0.0:
            raise LimitsError(f"{name}.max_rate_deg_s must be > 0, got {self.max_rate_deg_s}")

    @classmethod
    def from_mapping(cls, values: Mapping[str, object]) -> Self:
        """Limits from a parameter mapping (e.g. a YAML section); unknown keys are refused."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise LimitsError(
                f"unknown actuator limit parameter(s) {unknown}; expected some of {sorted(known)}"
            )
        return cls(**{k: float(v) for k, v in values.items()})  # type: ignore[arg-type]

    def as_dict(self) -> dict[str, float]:
        return {f.name: float(getattr(self, f.name)) for f in fields(self)}
