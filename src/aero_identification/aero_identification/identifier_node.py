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
from typing import Any

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

from .identification_session import IdentificationSession
from .identifier_settings import PARAMETERS, identifier_settings

TIMER_PERIOD_S = 0.1  # intake timer: refits start, worker results are collected


def check_parameters(p: ParameterSet) -> None:
    """What the identifier refuses at its start (ValueError): settings that do not make an
    identification configuration. The launchers run it before any node starts
    (rig_runtime.launcher.check_node)."""
    identifier_settings(p.as_dict())


class Identifier:
    """The identifier node's publishers, subscriptions and timers over its
    :class:`IdentificationSession` (which publishes through :meth:`publish_model`,
    :meth:`publish_status`, :meth:`send_request` and stops the node with :meth:`stop`)."""

    def __init__(self, node: Node) -> None:
        p = node.params
        self.node = node
        settings = identifier_settings(p.as_dict())
        self.control_pub = (
            node.create_publisher(
                EXPERIMENT_CONTROL.type, EXPERIMENT_CONTROL.name, EXPERIMENT_CONTROL.qos
            )
            if settings.adaptive
            else None
        )
        self.session = IdentificationSession(
            settings,
            node.logger,
            self,
            max_early_samples=lambda: int(p["max_early_samples"]),
            exit_after_final=lambda: bool(p["exit_after_final"]),
        )
        self.model_pub = node.create_publisher(
            IDENTIFICATION_MODEL.type, IDENTIFICATION_MODEL.name, IDENTIFICATION_MODEL.qos
        )
        self.status_pub = node.create_publisher(
            IDENTIFICATION_STATUS.type, IDENTIFICATION_STATUS.name, IDENTIFICATION_STATUS.qos
        )
        node.create_subscription(
            EXPERIMENT_PLAN.type,
            EXPERIMENT_PLAN.name,
            self.on_plan,
            EXPERIMENT_PLAN.qos,
            required=True,
        )
        node.create_subscription(
            PITCH_STATE.type,
            PITCH_STATE.name,
            self.on_state,
            settings.input_qos,
            depth=None if settings.input_qos == "stream" else 2000,
            required=True,
        )
        node.create_subscription(
            WING_COEFFICIENTS.type,
            WING_COEFFICIENTS.name,
            self.on_coefficients,
            settings.input_qos,
            depth=None if settings.input_qos == "stream" else 2000,
            required=True,
        )
        node.create_subscription(
            EXPERIMENT_SEGMENT.type,
            EXPERIMENT_SEGMENT.name,
            self.on_segment,
            EXPERIMENT_SEGMENT.qos,
            required=True,
        )
        node.create_subscription(
            EXPERIMENT_ANOMALY.type,
            EXPERIMENT_ANOMALY.name,
            self.on_anomaly,
            EXPERIMENT_ANOMALY.qos,
        )
        # A pause past the DDS lease (the node's pause watch, rig_runtime.node) is logged there
        # and goes into the next status at once; the holes it leaves follow as gaps.
        node.on_paused(lambda _seconds: self.publish_status())
        node.create_timer(TIMER_PERIOD_S, self.session.on_timer)
        node.create_timer(1.0, self.publish_status)
        self.publish_status()

    # -- subscriptions --------------------------------------------------------------------
    def on_plan(self, msg: Any) -> None:
        self.session.on_plan(msg.data)

    def on_anomaly(self, msg: Any) -> None:
        self.session.on_anomaly(msg.data)

    def on_state(self, msg: Any) -> None:
        pitch = joint_position(msg, PITCH_JOINT)
        value = math.nan if pitch is None else math.degrees(pitch)
        self.session.intake.add("u", stamp_to_ns(msg.header.stamp), value)

    def on_coefficients(self, msg: Any) -> None:
        self.session.intake.add("y", stamp_to_ns(msg.header.stamp), float(msg.vector.x))

    def on_segment(self, msg: Any) -> None:
        self.session.on_segment(json.loads(msg.data))

    # -- what the session publishes -------------------------------------------------------
    def publish_model(self, payload: dict[str, Any]) -> None:
        self.model_pub.publish(
            self.node.new_message("std_msgs/msg/String", data=json.dumps(payload, allow_nan=True))
        )

    def send_request(self, request: PlanRequest) -> None:
        assert self.control_pub is not None  # an adaptive run's
        self.control_pub.publish(
            self.node.new_message(EXPERIMENT_CONTROL.type, data=request.to_json())
        )

    def publish_status(self) -> None:
        level, values = self.session.status(self.node.paused_s)
        msg = diagnostic_array(
            self.node,
            f"{self.node.name}: identification",
            level,
            values["state"],
            "identifier",
            values,
        )
        self.status_pub.publish(msg)

    def stop(self, exit_code: int) -> None:
        self.node.request_shutdown(exit_code)

    def close(self) -> None:
        self.session.close()


def main(argv: list[str] | None = None) -> int:
    return run_node(Identifier, "identifier", PARAMETERS, argv, description=__doc__ or "")


if __name__ == "__main__":
    sys.exit(main())
