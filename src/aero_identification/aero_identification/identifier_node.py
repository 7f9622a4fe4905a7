"""Identifier node: buffers periods while the experiment runs and refits the models online.

Subscribes ``/experiment/plan`` (aero_rig_interfaces/ExperimentPlan, latched; gives t0 and the
segments), ``/pitch/state`` (measured pitch -> input, degrees), ``/wing/coefficients`` (C_l ->
output) and ``/experiment/segment`` (aero_rig_interfaces/SegmentEvent). Samples are aligned by
stamp into the plan's periods (period_assembly.py); periods with gaps, duplicates or invalid
samples are excluded and reported. After every completed multisine realization and every
completed sine test it re-clusters and refits BLA, BLA state space and PNLSS (pipeline.py) in a
worker process, so intake never stalls, and publishes ``/identification/model``
(aero_rig_interfaces/IdentificationModel, latched: summary fields and the whole record as JSON,
model_message.py) and ``/identification/status`` (DiagnosticArray, latched). After
``plan_end`` it runs the final identification, writes models and the report (Table 1
Markdown/CSV, PNG figures) to ``output_dir`` and, with ``exit_after_final``, exits (the
campaign's end).

Adaptive runs (``adaptive``; docs/design.md §7.9): after each measured multisine period the
node judges the level's periods so far by the stop and extend rules (adaptive.py) and calls the
generator's ``/experiment/control`` service (aero_rig_interfaces/srv/ControlExperiment: end the
realization, finish the level, add a realization, go on; multisine_gen.revision) without
waiting for the answer, which it logs when it comes (a refusal, with the generator's reason, as
a warning). It reports itself not ready to the start barrier until that service is there, so
the plan never starts without it. It follows the plan's revisions on ``/experiment/plan``, and
models.json (``experiment``) gives the multisine time per level, planned against executed, and
every decision.

Data quality: ``/experiment/anomaly`` records (rig_runtime.anomaly) exclude the periods and sine
records they touch; every plan sample is accounted for on both channels. What was lost or
excluded is named in ``/identification/status``, ``models.json`` (``data_quality``), the
report (``data_quality.md``, and a note above Table 1) and the final log lines.

This module is the rclpy shell: parameters (identifier_settings.py), subscriptions, publishers
and timers. The work is identification_session.IdentificationSession's, which imports no ROS.
"""

import math
import sys
from collections.abc import Mapping, Sequence
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray

from aero_rig_interfaces.msg import Anomaly as AnomalyMsg
from aero_rig_interfaces.msg import ExperimentPlan as ExperimentPlanMsg
from aero_rig_interfaces.msg import IdentificationModel, LevelSummary, SegmentEvent, TableCell
from aero_rig_interfaces.srv import ControlExperiment
from multisine_gen.plan import PlanError
from multisine_gen.plan_format import segment_event_from_message
from multisine_gen.revision import PlanRequest
from rig_runtime import Node, run_node, set_stamp, stamp_to_ns
from rig_runtime.diagnostics import diagnostic_array
from rig_runtime.interface import (
    EXPERIMENT_ANOMALY,
    EXPERIMENT_CONTROL,
    EXPERIMENT_PLAN,
    EXPERIMENT_SEGMENT,
    IDENTIFICATION_MODEL,
    IDENTIFICATION_STATUS,
    PITCH_JOINT,
    PITCH_STATE,
    WING_COEFFICIENTS,
    joint_position,
)
from rig_runtime.params import ParameterSet
from rig_runtime.qos_profiles import QOS_BY_NAME, topic_qos

from .identification_session import IdentificationSession
from .identifier_settings import PARAMETERS, identifier_settings
from .model_message import model_message_fields, model_stamp_ns

TIMER_PERIOD_S = 0.1  # intake timer: refits start, worker results are collected
# The readiness reason of an adaptive run's identifier until the generator's service is there.
WAITING_FOR_CONTROL = f"waiting for the {EXPERIMENT_CONTROL.name} service"


def check_parameters(p: ParameterSet | Mapping[str, Any]) -> None:
    """What the identifier refuses at its start (ValueError): settings that do not make an
    identification configuration. The launchers run it before any node starts
    (rig_runtime.launcher.check_node)."""
    identifier_settings(p.as_dict() if isinstance(p, ParameterSet) else dict(p))


class IdentifierNode(Node):
    """The identifier node's publishers, subscriptions and timers over its
    :class:`IdentificationSession` (which publishes through :meth:`publish_model`,
    :meth:`publish_status`, :meth:`send_request` and stops the node with :meth:`stop`)."""

    NODE_NAME = "identifier"
    PARAMETERS = PARAMETERS

    def __init__(self, argv: Sequence[str] | None = None) -> None:
        super().__init__(self.NODE_NAME, self.PARAMETERS, argv)
        settings = identifier_settings(self.parameter_values())
        # rclpy's create_client (rig_runtime.Node does not wrap it). The start barrier does not
        # see services: the node says it is not ready until the generator's is there.
        self.control_client = (
            self.create_client(ControlExperiment, EXPERIMENT_CONTROL.name)
            if settings.adaptive
            else None
        )
        self.control_ready = self.control_client is None
        if not self.control_ready:
            self.set_ready(False, WAITING_FOR_CONTROL)
        # The session imports no ROS: it logs through the node's Python logger (forwarded to
        # this node's rcl logger, rig_runtime.node_logging).
        self.session = IdentificationSession(
            settings,
            self.logger,
            self,
            max_early_samples=lambda: int(self.get_parameter("max_early_samples").value),
            exit_after_final=lambda: bool(self.get_parameter("exit_after_final").value),
        )
        self.on_shutdown(self.session.close)
        self.model_pub = self.create_publisher(
            IdentificationModel, IDENTIFICATION_MODEL.name, topic_qos(IDENTIFICATION_MODEL)
        )
        self.status_pub = self.create_publisher(
            DiagnosticArray, IDENTIFICATION_STATUS.name, topic_qos(IDENTIFICATION_STATUS)
        )
        self.create_subscription(
            ExperimentPlanMsg,
            EXPERIMENT_PLAN.name,
            self.on_plan,
            topic_qos(EXPERIMENT_PLAN),
            required=True,
        )
        # The pitch and coefficients streams on the serialized path (node.py).
        input_qos = QOS_BY_NAME[settings.input_qos]
        depth = None if settings.input_qos == "stream" else 2000
        self.create_subscription(
            PITCH_STATE.type,
            PITCH_STATE.name,
            self.on_state,
            input_qos,
            depth=depth,
            required=True,
        )
        self.create_subscription(
            WING_COEFFICIENTS.type,
            WING_COEFFICIENTS.name,
            self.on_coefficients,
            input_qos,
            depth=depth,
            required=True,
        )
        self.create_subscription(
            SegmentEvent,
            EXPERIMENT_SEGMENT.name,
            self.on_segment,
            topic_qos(EXPERIMENT_SEGMENT),
            required=True,
        )
        self.create_subscription(
            AnomalyMsg, EXPERIMENT_ANOMALY.name, self.on_anomaly, topic_qos(EXPERIMENT_ANOMALY)
        )
        # A pause past the DDS lease (the node's pause watch, rig_runtime.node) is logged there
        # and goes into the next status at once; the holes it leaves follow as gaps.
        self.on_paused(lambda _seconds: self.publish_status())
        self.create_timer(TIMER_PERIOD_S, self.on_timer)
        self.create_timer(1.0, self.publish_status)
        self.publish_status()

    # -- subscriptions and the timer --------------------------------------------------------
    def on_plan(self, msg: Any) -> None:
        self.session.on_plan(msg)

    def on_anomaly(self, msg: Any) -> None:
        self.session.on_anomaly(msg)

    def on_state(self, msg: Any) -> None:
        pitch = joint_position(msg, PITCH_JOINT)
        value = math.nan if pitch is None else math.degrees(pitch)
        self.session.intake.add("u", stamp_to_ns(msg.header.stamp), value)

    def on_coefficients(self, msg: Any) -> None:
        self.session.intake.add("y", stamp_to_ns(msg.header.stamp), float(msg.vector.x))

    def on_segment(self, msg: Any) -> None:
        try:
            event = segment_event_from_message(msg)
        except PlanError as exc:
            self.logger.error("%s: %s; ignored", EXPERIMENT_SEGMENT.name, exc)
            return
        self.session.on_segment(event)

    def on_timer(self) -> None:
        if not self.control_ready:
            self.check_control()
        self.session.on_timer()

    def check_control(self) -> None:
        """An adaptive run's readiness: ready once the generator's service is there."""
        assert self.control_client is not None
        if self.control_client.service_is_ready():
            self.control_ready = True
            self.set_ready(True)
            self.logger.info("%s: the generator's service is there", EXPERIMENT_CONTROL.name)

    # -- what the session publishes -------------------------------------------------------
    def publish_model(self, payload: dict[str, Any], stamp_ns: int) -> None:
        fields = model_message_fields(payload)
        fields["levels"] = [LevelSummary(**level) for level in fields["levels"]]
        for table in ("table1", "table1_level1"):
            fields[table] = [TableCell(**cell) for cell in fields[table]]
        msg = IdentificationModel(**fields)
        set_stamp(msg.header.stamp, model_stamp_ns(payload, stamp_ns))
        self.model_pub.publish(msg)

    def send_request(self, request: PlanRequest) -> None:
        """Call the generator's service; the answer is logged when it comes (never waited
        for: the executor runs the intake meanwhile)."""
        client = self.control_client
        assert client is not None  # an adaptive run's
        what = f"{request.action.replace('_', ' ')} on level {request.level}"
        if not client.service_is_ready():
            self.logger.warning(
                "%s: the generator's service is gone; %s (period ending at sample %d) not sent",
                EXPERIMENT_CONTROL.name,
                what,
                request.after_k,
            )
            return
        future = client.call_async(ControlExperiment.Request(**request.to_fields()))
        future.add_done_callback(lambda done: self.on_answer(what, done))

    def on_answer(self, what: str, future: Any) -> None:
        """The generator's answer to one request."""
        try:
            response = future.result()
        except Exception as exc:  # rclpy sets the client's failure on the future
            self.logger.error("%s: %s: no answer: %s", EXPERIMENT_CONTROL.name, what, exc)
            return
        if response is None:  # cancelled (the node is shutting down)
            return
        if not response.accepted:
            self.logger.warning("the generator refused %s: %s", what, response.message)
        elif response.message:
            self.logger.info(
                "the generator accepted %s: plan revision %d from sample %d: %s",
                what,
                response.revision,
                response.from_k,
                response.message,
            )

    def publish_status(self) -> None:
        level, values = self.session.status(self.paused_s)
        msg = diagnostic_array(
            f"{self.name}: identification", level, values["state"], "identifier", values
        )
        self.status_pub.publish(msg)

    def stop(self, exit_code: int) -> None:
        self.request_shutdown(exit_code)


def main(argv: list[str] | None = None) -> int:
    return run_node(IdentifierNode, argv, description=__doc__ or "")


if __name__ == "__main__":
    sys.exit(main())
