"""Identifier node: buffers periods while the experiment runs and refits the models online.

Subscribes ``/experiment/plan`` (latched; gives t0 and the segments), ``/pitch/state``
(measured pitch -> input, degrees), ``/wing/coefficients`` (C_l -> output) and
``/experiment/segment``. Samples are aligned by stamp into the plan's periods (period_assembly.py);
periods with gaps, duplicates or invalid samples are excluded and reported. After every
completed multisine realization and every completed sine test it re-clusters and refits BLA,
BLA state space and PNLSS (pipeline.py) in a worker process, so intake never stalls, and
publishes ``/identification/model`` (JSON, latched) and ``/identification/status``
(DiagnosticArray, latched). After ``plan_end`` it runs the final identification, writes models
and the report (Table 1 Markdown/CSV, PNG figures) to ``output_dir`` and, with
``exit_after_final``, exits (the campaign's end).

Adaptive runs (``adaptive``; docs/design.md §7.9): after each measured multisine period the
node judges the level's periods so far by the stop and extend rules (adaptive.py) and sends
the generator a request on ``/experiment/control`` (end the realization, finish the level, add
a realization, go on; multisine_gen.revision). It follows the plan's revisions on
``/experiment/plan``, and models.json (``experiment``) gives the multisine time per level,
planned against executed, and every decision.

Data quality: ``/experiment/anomaly`` records (rig_runtime.anomaly) exclude the periods and sine
records they touch; every plan sample is accounted for on both channels. What was lost or
excluded is named in ``/identification/status``, ``models.json`` (``data_quality``), the
report (``data_quality.md``, and a note above Table 1) and the final log lines.

This module is the rclpy shell: parameters (identifier_settings.py), subscriptions, publishers
and timers. The work is identification_session.IdentificationSession's, which imports no ROS.
"""

import json
import math
import sys
from collections.abc import Mapping, Sequence
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from std_msgs.msg import String

from multisine_gen.revision import PlanRequest
from rig_runtime import Node, run_node, stamp_to_ns
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

TIMER_PERIOD_S = 0.1  # intake timer: refits start, worker results are collected


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
        self.control_pub = (
            self.create_publisher(String, EXPERIMENT_CONTROL.name, topic_qos(EXPERIMENT_CONTROL))
            if settings.adaptive
            else None
        )
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
            String, IDENTIFICATION_MODEL.name, topic_qos(IDENTIFICATION_MODEL)
        )
        self.status_pub = self.create_publisher(
            DiagnosticArray, IDENTIFICATION_STATUS.name, topic_qos(IDENTIFICATION_STATUS)
        )
        self.create_subscription(
            String, EXPERIMENT_PLAN.name, self.on_plan, topic_qos(EXPERIMENT_PLAN), required=True
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
            String,
            EXPERIMENT_SEGMENT.name,
            self.on_segment,
            topic_qos(EXPERIMENT_SEGMENT),
            required=True,
        )
        self.create_subscription(
            String, EXPERIMENT_ANOMALY.name, self.on_anomaly, topic_qos(EXPERIMENT_ANOMALY)
        )
        # A pause past the DDS lease (the node's pause watch, rig_runtime.node) is logged there
        # and goes into the next status at once; the holes it leaves follow as gaps.
        self.on_paused(lambda _seconds: self.publish_status())
        self.create_timer(TIMER_PERIOD_S, self.session.on_timer)
        self.create_timer(1.0, self.publish_status)
        self.publish_status()

    # -- subscriptions --------------------------------------------------------------------
    def on_plan(self, msg: String) -> None:
        self.session.on_plan(msg.data)

    def on_anomaly(self, msg: String) -> None:
        self.session.on_anomaly(msg.data)

    def on_state(self, msg: Any) -> None:
        pitch = joint_position(msg, PITCH_JOINT)
        value = math.nan if pitch is None else math.degrees(pitch)
        self.session.intake.add("u", stamp_to_ns(msg.header.stamp), value)

    def on_coefficients(self, msg: Any) -> None:
        self.session.intake.add("y", stamp_to_ns(msg.header.stamp), float(msg.vector.x))

    def on_segment(self, msg: String) -> None:
        self.session.on_segment(json.loads(msg.data))

    # -- what the session publishes -------------------------------------------------------
    def publish_model(self, payload: dict[str, Any]) -> None:
        self.model_pub.publish(String(data=json.dumps(payload, allow_nan=True)))

    def send_request(self, request: PlanRequest) -> None:
        assert self.control_pub is not None  # an adaptive run's
        self.control_pub.publish(String(data=request.to_json()))

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
