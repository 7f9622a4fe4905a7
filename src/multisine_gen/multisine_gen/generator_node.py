"""Generator node: streams the experiment plan as pitch commands (docs/design.md §4-§5).

Publishes ``/pitch/command`` (sensor_msgs/JointState, joint ``pitch``, position in rad) sample by
sample with stamps t0 + k/fs, the plan on ``/experiment/plan`` (aero_rig_interfaces/ExperimentPlan,
latched; the whole plan as JSON in ``plan_json``, stamped t0) and an event per segment start/end on
``/experiment/segment`` (aero_rig_interfaces/SegmentEvent, stamped with the segment's first or
last sample; multisine_gen.plan_format). Pacing: the wall clock times
``real_time_factor`` (1 on the rig; 0 = as fast as the graph takes). With ``flow_control`` the
generator never runs more than ``max_lead_samples`` ahead of the last ``/wing/coefficients``
stamp the lift reports on ``/wing/coefficients/progress``, a credit that makes a simulated run
lossless and deterministic whatever the speed (pacing.py).

Start barrier (rig_runtime.barrier): t0 is taken, and the plan published, only when every node
named in ``barrier_nodes`` (filled in from the graph description by rig-launch, aero-rig and the
ROS launch files) has reported ready on ``/graph/ready`` and every reader and writer among them
is matched on both sides, so the first sample reaches every node and the recorder. A node that
is not ready after ``start_timeout_s`` stops the generator with an error naming it and what it
still waits for; nothing has moved then.

Adaptive runs (``adaptive``; docs/design.md §7.9): the generator serves the identifier's
requests on the ``/experiment/control`` service (aero_rig_interfaces/srv/ControlExperiment;
multisine_gen.revision: end the realization, finish the level, add a realization, go on) within
``adaptive_min_periods``, ``adaptive_min_realizations`` and ``adaptive_max_realizations``. A
request it carries out becomes the plan's next revision, which it publishes on
``/experiment/plan`` (latched; every sample already sent unchanged) with a ``decision`` event on
``/experiment/segment`` naming the request, its reason and the change, and answers accepted with
the change; a request it cannot carry out is refused, logged, recorded as a ``refused`` event
and answered with the reason, and changes nothing. The service exists in every run, so a caller
always gets an answer: outside an adaptive run every request is refused (:data:`NOT_ADAPTIVE`),
logged and not recorded. With ``flow_control`` (simulation) and a client of the service in the
graph, the stream holds at the end of each measured multisine period until the identifier's
request on that period has come, so a simulated adaptive run is deterministic; the hold ends
without it when the client is gone, or after the DDS participant lease, logged. On the rig the
stream never holds: a request takes effect at the next period boundary after it arrives.

Every second it publishes its progress on ``/diagnostics`` (name ``<node>: stream``): its state
(``barrier``, ``streaming``, ``holding``, ``waiting for credit``, ``finished``), the samples
published of the plan's total, and the credit's limit; the campaign's liveness follows it
(aero_rig/cli/liveness.py).

At the end of the plan it publishes a ``plan_end`` event and keeps the plan latched until
stopped; stopped early, it publishes ``plan_aborted`` and the actuator's watchdog holds and then
ramps to the safe angle.
"""

import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

from diagnostic_msgs.msg import DiagnosticArray
from std_msgs.msg import Header

from aero_rig_interfaces.msg import ExperimentPlan as ExperimentPlanMsg
from aero_rig_interfaces.msg import ReadinessReport as ReadinessReportMsg
from aero_rig_interfaces.msg import SegmentEvent
from aero_rig_interfaces.srv import ControlExperiment
from rig_runtime import Node, Parameter, new_message, run_node, set_stamp, stamp_to_ns
from rig_runtime.barrier import ReadinessReport, StartBarrier
from rig_runtime.diagnostics import OK, WARN, diagnostic_array
from rig_runtime.interface import (
    DIAGNOSTICS,
    EXPERIMENT_CONTROL,
    EXPERIMENT_PLAN,
    EXPERIMENT_SEGMENT,
    GRAPH_READY,
    PITCH_COMMAND,
    PITCH_JOINT,
    WING_PROGRESS,
    ActuatorLimits,
)
from rig_runtime.params import ParameterSet
from rig_runtime.qos_profiles import topic_qos
from rig_runtime.ros_environment import PARTICIPANT_LEASE_S

from .campaigns import default_plan, short_plan
from .pacing import StreamPacer
from .plan import ExperimentPlan
from .plan_format import plan_from_json, plan_message, segment_event, segment_event_fields
from .revision import (
    Adaptation,
    RefusedRequestError,
    RequestError,
    request_from_fields,
    revise,
)

_LIMITS = ActuatorLimits()  # the defaults of the limit parameters

PARAMETERS = [
    Parameter("plan", "short", "experiment plan: 'default', 'short' or a plan JSON file"),
    Parameter("seed", 0, "seed of the plan's random phases and detection lines", min=0),
    Parameter(
        "real_time_factor",
        1.0,
        "experiment seconds per wall second; 0 = as fast as the graph takes",
        min=0.0,
        max=1000.0,
    ),
    Parameter(
        "flow_control",
        True,
        "wait for the lift's /wing/coefficients/progress (simulation); false on the rig",
    ),
    Parameter("max_lead_samples", 1000, "most samples ahead of the last coefficients", min=1),
    Parameter("wait_for_subscribers", 1, "command subscribers to wait for before t0", min=0),
    Parameter(
        "barrier_nodes",
        [],
        "nodes that must report ready and matched before t0 (set from the graph description)",
        element_type=str,
    ),
    Parameter(
        "start_timeout_s", 60.0, "give up waiting for the barrier after this long [s]", min=0.1
    ),
    Parameter("exit_at_end", False, "exit after the plan (else keep the plan latched)"),
    Parameter("min_deg", _LIMITS.min_deg, "actuator lower limit the plan is checked against [deg]"),
    Parameter("max_deg", _LIMITS.max_deg, "actuator upper limit the plan is checked against [deg]"),
    Parameter(
        "max_rate_deg_s",
        _LIMITS.max_rate_deg_s,
        "actuator rate limit the plan is checked against",
        min=0.1,
    ),
    Parameter(
        "adaptive",
        False,
        "serve the identifier's requests on /experiment/control (aero-rig campaign --adaptive, "
        "with the identifier's adaptive); false: refuse every request, play the plan as designed",
    ),
    # Bounds on the identifier's requests in adaptive runs (multisine_gen.revision).
    Parameter(
        "adaptive_min_periods",
        Adaptation.min_periods,
        "adaptive runs: fewest measured periods of a realization",
        min=1,
    ),
    Parameter(
        "adaptive_min_realizations",
        Adaptation.min_realizations,
        "adaptive runs: fewest realizations of a level (2 keep the distortions separable)",
        min=1,
    ),
    Parameter(
        "adaptive_max_realizations",
        Adaptation.max_realizations,
        "adaptive runs: most realizations a level may grow to",
        min=1,
    ),
]

DEG = 3.141592653589793 / 180.0


def load_plan(spec: str, seed: int) -> ExperimentPlan:
    """'default', 'short' or a JSON file written by plan_format.plan_to_json()."""
    if spec == "default":
        return default_plan(seed=seed)
    if spec == "short":
        return short_plan(seed=seed)
    path = Path(spec)
    if not path.exists():
        raise ValueError(f"parameter 'plan' = {spec!r}: not 'default', 'short' or an existing file")
    return plan_from_json(path.read_text())


def check_parameters(
    p: ParameterSet | Mapping[str, Any],
) -> tuple[ActuatorLimits, Adaptation, ExperimentPlan]:
    """What the generator refuses before it publishes anything: adaptive bounds that cannot
    hold, a plan that does not load, or one that would leave the actuator's limits (ValueError).
    The launchers run it before any node starts (rig_runtime.launcher.check_node)."""
    limits = ActuatorLimits(
        min_deg=p["min_deg"], max_deg=p["max_deg"], max_rate_deg_s=p["max_rate_deg_s"]
    )
    adaptation = Adaptation(
        p["adaptive_min_periods"], p["adaptive_min_realizations"], p["adaptive_max_realizations"]
    )
    plan = load_plan(p["plan"], p["seed"])
    plan.validate(limits)
    return limits, adaptation, plan


DIAGNOSTICS_PERIOD_S = 1.0  # the progress heartbeat on /diagnostics

# The answer to every request outside an adaptive run.
NOT_ADAPTIVE = (
    "not an adaptive run: the generator plays its plan as designed (start it with "
    "adaptive:=true / aero-rig campaign --adaptive)"
)


class ControlAnswer(NamedTuple):
    """The generator's answer to one request (the ControlExperiment response's fields)."""

    accepted: bool  # false: refused, the plan is unchanged
    message: str  # refused: why; accepted: the change made (empty: none)
    revision: int  # the plan's revision after the request
    from_k: int = -1  # the first revised sample (-1: nothing revised)


class GeneratorNode(Node):
    NODE_NAME = "generator"
    PARAMETERS = PARAMETERS

    def __init__(self, argv: Sequence[str] | None = None) -> None:
        super().__init__(self.NODE_NAME, self.PARAMETERS, argv)
        p = self.parameter_values()
        # Refuse before publishing anything if the plan would leave the actuator's limits.
        self.limits, self.adaptation, plan = check_parameters(p)
        self.adaptive = bool(p["adaptive"])
        self.plan_id = str(p["plan"])
        self.fs = plan.fs
        self._use(plan)
        self.planned_samples = self.total
        # Adaptive runs: plan indices of the periods judged (requests in), where the stream
        # holds now, and since when.
        self.judged: set[int] = set()
        self.hold_since: float | None = None
        self.hold_s = PARTICIPANT_LEASE_S
        # The command stream on the serialized path (node.py).
        self.cmd_pub = self.create_publisher(
            PITCH_COMMAND.type, PITCH_COMMAND.name, topic_qos(PITCH_COMMAND)
        )
        self.plan_pub = self.create_publisher(
            ExperimentPlanMsg, EXPERIMENT_PLAN.name, topic_qos(EXPERIMENT_PLAN)
        )
        self.seg_pub = self.create_publisher(
            SegmentEvent, EXPERIMENT_SEGMENT.name, topic_qos(EXPERIMENT_SEGMENT)
        )
        self.k = 0
        self.t0_ns: int | None = None
        self.finished = False
        self.created = time.monotonic()
        self.pacer = StreamPacer(
            self.total,
            self.fs,
            real_time_factor=p["real_time_factor"],
            flow_control=p["flow_control"],
            max_lead=p["max_lead_samples"],
        )
        self.barrier = StartBarrier(p["barrier_nodes"])
        self.wait_for_subscribers = p["wait_for_subscribers"]
        self.start_timeout_s = p["start_timeout_s"]
        self.exit_at_end = p["exit_at_end"]
        self.barrier_checked = 0.0
        self.barrier_logged = time.monotonic()
        if p["flow_control"]:
            self.create_subscription(
                Header,
                WING_PROGRESS.name,
                self.on_progress,
                topic_qos(WING_PROGRESS),
                required=True,
            )
        self.create_subscription(
            ReadinessReportMsg, GRAPH_READY.name, self.on_ready, topic_qos(GRAPH_READY), depth=256
        )
        # In every run, so that a request always gets an answer (NOT_ADAPTIVE outside an
        # adaptive one); rclpy's create_service (rig_runtime.Node does not wrap it).
        self.control_srv = self.create_service(
            ControlExperiment, EXPERIMENT_CONTROL.name, self.on_control
        )
        self.diag_pub = self.create_publisher(
            DiagnosticArray, DIAGNOSTICS.name, topic_qos(DIAGNOSTICS)
        )
        self.create_timer(0.002, self.tick)
        self.create_timer(DIAGNOSTICS_PERIOD_S, self.publish_diagnostics)
        self.on_shutdown(self.abort_report)
        self.get_logger().info(
            f"plan {p['plan']}: {self.total} samples ({self.plan.duration_s:.1f} s at "
            f"{self.fs:g} Hz), {len(self.plan.segments)} segments"
        )

    def _use(self, plan: ExperimentPlan) -> None:
        """Stream ``plan`` from here on (the first plan, or a revision)."""
        self.plan = plan
        self.command_deg = plan.command_deg()
        self.total = len(self.command_deg)
        self.starts = {s.start_k: s for s in plan.segments}
        self.ends = {s.stop_k - 1: s for s in plan.segments}

    def _publish_plan(self) -> None:
        assert self.t0_ns is not None
        fields = plan_message(
            self.plan,
            self.t0_ns,
            adaptation=self.adaptation.to_dict() if self.adaptive else None,
            plan_id=self.plan_id,
        )
        msg = ExperimentPlanMsg(**fields)
        set_stamp(msg.header.stamp, self.t0_ns)
        self.plan_pub.publish(msg)

    # -- adaptive runs ------------------------------------------------------------------------
    def on_control(
        self, request: ControlExperiment.Request, response: ControlExperiment.Response
    ) -> ControlExperiment.Response:
        """The /experiment/control service: one request of the identifier, answered."""
        answer = self.control(
            request.action, request.level, request.after_k, request.reason, request.more
        )
        response.accepted = answer.accepted
        response.message = answer.message
        response.revision = answer.revision
        response.from_k = answer.from_k
        return response

    def control(
        self, action: str, level: int, after_k: int, reason: str = "", more: bool = False
    ) -> ControlAnswer:
        """Decide on one request (multisine_gen.revision): carry it out as the plan's next
        revision, or refuse it; record the decision on /experiment/segment (adaptive runs)."""
        revision_now = self.plan.revision
        if not self.adaptive:
            self.get_logger().warning(f"refused {action} on level {level}: {NOT_ADAPTIVE}")
            return ControlAnswer(False, NOT_ADAPTIVE, revision_now)
        record: dict[str, Any] = {"t0_ns": self.t0_ns, "at_k": self.k}
        try:
            request = request_from_fields(action, level, after_k, reason, more)
        except RequestError as exc:
            self.get_logger().error(
                f"{EXPERIMENT_CONTROL.name}: bad request refused, the plan is unchanged: {exc}"
            )
            bad = {"request": str(action), "reason": str(reason)}
            self._event(record | bad | {"event": "refused", "why": str(exc)}, self.k)
            return ControlAnswer(False, str(exc), revision_now)
        record |= {"request": request.action, "level": request.level, "after_k": request.after_k}
        record["reason"] = request.reason
        if self.t0_ns is None or self.finished:
            why = "the plan has not started" if self.t0_ns is None else "the plan has ended"
            self.get_logger().warning(f"refused {request.action} on level {request.level}: {why}")
            self._event(record | {"event": "refused", "why": why}, self.k)
            return ControlAnswer(False, why, revision_now)
        if not request.more:
            self.judged.add(request.after_k)  # the last request on that period
        late = self.k - 1 - request.after_k  # samples published past the judged period
        if request.action == "go_on":
            self._event(record | {"event": "decision", "change": ""}, self.k)
            return ControlAnswer(True, "", revision_now)
        try:
            revision = revise(self.plan, self.k, request, self.adaptation, self.limits)
        except (RequestError, RefusedRequestError) as exc:
            self.get_logger().warning(
                f"refused {request.action} on level {request.level} ({request.reason}): {exc}"
            )
            self._event(record | {"event": "refused", "why": str(exc)}, self.k)
            return ControlAnswer(False, str(exc), revision_now)
        self._use(revision.plan)
        self.pacer.total = self.total
        self._publish_plan()
        after = f", {late} samples after the judged period" if late > 0 else ""
        self.get_logger().info(
            f"plan revision {revision.plan.revision} from sample {revision.from_k}{after}: "
            f"{revision.change} ({request.reason})"
        )
        self._event(
            record
            | {
                "event": "decision",
                "change": revision.change,
                "revision": revision.plan.revision,
                "from_k": revision.from_k,
                "samples": self.total,
            },
            record["at_k"],
        )
        return ControlAnswer(True, revision.change, revision.plan.revision, revision.from_k)

    def _holds(self, k: int) -> bool:
        """Whether sample k waits for the identifier's request on the period that ends at k-1
        (an adaptive simulation with a client of the service; module docstring)."""
        segment = self.ends.get(k - 1)
        if (
            segment is None
            or segment.kind != "multisine"
            or not self.pacer.flow_control
            or (k - 1) in self.judged
        ):
            self.hold_since = None
            return False
        if not self.adaptive or self.count_clients(EXPERIMENT_CONTROL.name) == 0:
            return False
        now = time.monotonic()
        if self.hold_since is None:
            self.hold_since = now
        if now - self.hold_since > self.hold_s:
            self.get_logger().warning(
                f"no request on the period ending at sample {k - 1} within the DDS lease "
                f"({self.hold_s:g} s): going on with the plan as it stands"
            )
            self.judged.add(k - 1)
            self.hold_since = None
            return False
        return True

    def on_progress(self, msg: Header) -> None:
        """The lift's latest coefficients stamp (std_msgs/Header): the credit."""
        if self.t0_ns is None:
            return
        self.pacer.credit(round((stamp_to_ns(msg.stamp) - self.t0_ns) * self.fs / 1e9))

    def on_ready(self, msg: ReadinessReportMsg) -> None:
        try:
            self.barrier.update(ReadinessReport.from_message(msg))
        except (ValueError, KeyError) as exc:
            self.get_logger().warning(f"ignored a malformed readiness report: {exc}")
        self.barrier_checked = 0.0  # look again at the next tick

    def stamp_ns(self, k: int) -> int:
        assert self.t0_ns is not None
        return self.t0_ns + round(k * 1e9 / self.fs)

    def _event(self, payload: dict[str, Any], k: int) -> None:
        """Publish one /experiment/segment event, stamped with plan sample ``k`` (none before
        t0: a request refused before the start)."""
        msg = SegmentEvent(**segment_event_fields(payload))
        if self.t0_ns is not None:
            set_stamp(msg.header.stamp, self.stamp_ns(k))
        self.seg_pub.publish(msg)

    def pending(self) -> list[str]:
        """What the start still waits for (empty: every member ready and matched)."""
        wanted = self.wait_for_subscribers
        waiting = self.barrier.pending(self.readiness_report())
        subscribers = self.cmd_pub.subscription_count()
        if subscribers < wanted:
            waiting.append(
                f"{self.fq_name}: {subscribers} of {wanted} subscribers "
                "on /pitch/command (is the actuator node running?)"
            )
        if self.adaptive and self.count_clients(EXPERIMENT_CONTROL.name) == 0:
            # The identifier's requests decide the plan from the first period on: its client
            # must be in this node's graph before t0, or the first hold would not wait for it.
            waiting.append(
                f"{self.fq_name}: no client of {EXPERIMENT_CONTROL.name} yet (adaptive run: "
                "is the identifier running with adaptive true?)"
            )
        return waiting

    def _start(self) -> bool:
        now = time.monotonic()
        if now - self.barrier_checked < 0.02:
            return False
        self.barrier_checked = now
        waiting = self.pending()
        if waiting:
            timeout_s = self.start_timeout_s
            if now - self.created > timeout_s:
                self.get_logger().error(
                    f"start barrier: not ready after {timeout_s:.0f} s, nothing was sent: "
                    + "; ".join(waiting)
                )
                self.request_shutdown(1)
            elif now - self.barrier_logged > 5.0:
                self.barrier_logged = now
                self.get_logger().info("start barrier waits for: " + "; ".join(waiting))
            return False
        self.t0_ns = time.time_ns()
        self.pacer.start(time.monotonic())
        self._publish_plan()
        self.get_logger().info(
            f"start barrier passed after {now - self.created:.2f} s "
            f"({len(self.barrier.members)} nodes ready and matched); t0 = {self.t0_ns} ns; "
            "streaming"
        )
        return True

    def tick(self) -> None:
        if self.finished:
            return
        if self.t0_ns is None and not self._start():
            return
        target = self.pacer.target(time.monotonic())
        t0_s = self.t0_ns / 1e9  # type: ignore[operator]
        while self.k < min(target, self.total):
            k = self.k
            if self._holds(k):
                break
            segment = self.starts.get(k)
            if segment is not None:
                event = segment_event(segment, "start", t0_s, self.fs) | {"t0_ns": self.t0_ns}
                self._event(event, segment.start_k)
            msg = new_message(
                PITCH_COMMAND.type,
                name=[PITCH_JOINT],
                position=[self.command_deg[k] * DEG],
            )
            set_stamp(msg.header.stamp, self.stamp_ns(k))
            self.cmd_pub.publish(msg)
            segment = self.ends.get(k)
            if segment is not None:
                event = segment_event(segment, "end", t0_s, self.fs) | {"t0_ns": self.t0_ns}
                self._event(event, segment.stop_k - 1)
            self.k += 1
        if self.k >= self.total:
            self.finished = True
            self._event(
                {
                    "event": "plan_end",
                    "samples": self.total,
                    "fs": self.fs,
                    "planned_samples": self.planned_samples,
                    "revision": self.plan.revision,
                    "t0_ns": self.t0_ns,
                },
                self.total - 1,  # the last sample published
            )
            self.get_logger().info(
                f"plan finished: {self.total} samples published ({self.planned_samples} "
                f"planned, revision {self.plan.revision})"
            )
            if self.exit_at_end:
                self.request_shutdown(0)

    def stream_state(self) -> str:
        """Where the stream stands: what the campaign's liveness and ``ros2 topic echo`` see."""
        if self.finished:
            return "finished"
        if self.t0_ns is None:
            return "barrier"
        if self.hold_since is not None:
            return "holding"
        if self.pacer.flow_control and self.k >= self.pacer.credit_until:
            return "waiting for credit"
        return "streaming"

    def publish_diagnostics(self) -> None:
        state = self.stream_state()
        values = {
            "state": state,
            "samples_published": self.k,
            "plan_samples": self.total,
            "plan_revision": self.plan.revision,
        }
        if self.pacer.flow_control:
            values["credit_until"] = self.pacer.credit_until
        level = WARN if state == "waiting for credit" else OK
        self.diag_pub.publish(
            diagnostic_array(f"{self.name}: stream", level, state, "generator", values)
        )

    def abort_report(self) -> None:
        """At shutdown: a plan stopped before its end is reported as aborted."""
        if self.t0_ns is not None and not self.finished:
            event = {"event": "plan_aborted", "samples": self.k, "t0_ns": self.t0_ns}
            self._event(event, max(self.k - 1, 0))  # the last sample published
            self.get_logger().warning(
                f"stopped at sample {self.k} of {self.total}; the actuator holds, then ramps to "
                "its safe angle"
            )


def main(argv: list[str] | None = None) -> int:
    return run_node(GeneratorNode, argv, description=__doc__ or "")


if __name__ == "__main__":
    sys.exit(main())
