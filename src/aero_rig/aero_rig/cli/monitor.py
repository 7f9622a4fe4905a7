"""The campaign's in-process observer: the plan, the progress, the identifier's state and the
flow of the streams (rig_runtime.flow)."""

import time
from collections.abc import Collection, Mapping
from typing import Any

from multisine_gen.plan import PlanError
from multisine_gen.plan_format import read_plan_message, segment_event_from_message
from rig_runtime.flow import FlowWatch, flow_reports
from rig_runtime.interface import (
    DIAGNOSTICS,
    EXPERIMENT_PLAN,
    EXPERIMENT_SEGMENT,
    IDENTIFICATION_STATUS,
)

from .liveness import Liveness, stall_bound_s


class CampaignMonitor:
    """In-process observer: progress from segment events, end from the identifier's status."""

    def __init__(
        self, remote: Mapping[str, str] | None = None, local: Collection[str] = ()
    ) -> None:
        """``remote``: ``{node fq name: host}`` of the graph's nodes that other machines run;
        ``local``: those this machine runs."""
        from rig_runtime.node import Node

        self.liveness = Liveness(stall_bound_s())
        self.t0_ns: int | None = None  # the stamp of plan sample 0
        self.flow = FlowWatch(dict(remote or {}), set(local), describe_stamp=self.describe_stamp)
        self.node = Node("aero_rig_campaign", argv=[])
        self.total = 0
        self.revision = -1  # of the plan held (an adaptive run revises it)
        self.fs = 0.0  # the plan's sample rate [Hz]
        self.k = 0
        self.state = ""
        self.model: dict[str, Any] | None = None
        self.node.create_subscription(
            EXPERIMENT_PLAN.type, EXPERIMENT_PLAN.name, self._plan, EXPERIMENT_PLAN.qos
        )
        self.node.create_subscription(
            EXPERIMENT_SEGMENT.type, EXPERIMENT_SEGMENT.name, self._segment, EXPERIMENT_SEGMENT.qos
        )
        self.node.create_subscription(
            IDENTIFICATION_STATUS.type,
            IDENTIFICATION_STATUS.name,
            self._status,
            IDENTIFICATION_STATUS.qos,
        )

        self.node.create_subscription(
            DIAGNOSTICS.type, DIAGNOSTICS.name, self._diagnostics, DIAGNOSTICS.qos, depth=100
        )

    def describe_stamp(self, stamp_ns: int) -> str:
        """``sample k`` of the plan for a stream stamp (t0 + k/fs), else the stamp."""
        if not stamp_ns:
            return "none"
        if self.t0_ns is None or not self.fs:
            return f"stamped {stamp_ns} ns"
        return f"sample {round((stamp_ns - self.t0_ns) * self.fs / 1e9)}"

    def _diagnostics(self, msg: Any) -> None:
        """The generator's stream heartbeat (generator_node.publish_diagnostics) and every
        node's flow report (rig_runtime.flow)."""
        now = time.monotonic()
        for node, flows in flow_reports(msg):
            self.flow.report(now, node, flows)
        for status in msg.status:
            if status.hardware_id != "generator":
                continue
            values = {kv.key: kv.value for kv in status.values}
            try:
                published = int(values.get("samples_published", ""))
            except ValueError:
                continue
            self.liveness.stream(time.monotonic(), values.get("state", ""), published)

    def _plan(self, msg: Any) -> None:
        try:
            plan, t0_ns = read_plan_message(msg)
        except PlanError:
            return  # the identifier refuses it, naming why, and the graph stops
        if plan.revision < self.revision:
            return
        self.revision = plan.revision
        self.t0_ns = t0_ns
        self.total = plan.total_samples
        self.fs = plan.fs
        self.liveness.total = plan.total_samples
        self.liveness.plan_seen(time.monotonic())

    def _segment(self, msg: Any) -> None:
        try:
            event = segment_event_from_message(msg)
        except PlanError:
            return  # not an event of this plan format: no progress to read from it
        if event.get("event") == "end":
            self.k = int(event["start_k"]) + int(event["length"])
        elif event.get("event") in ("plan_end", "plan_aborted"):
            if event.get("event") == "plan_end":
                self.total = self.liveness.total = int(event.get("samples", self.total))
            self.k = self.total
            self.liveness.plan_ended(time.monotonic())

    def _status(self, msg: Any) -> None:
        values = {kv.key: kv.value for status in msg.status for kv in status.values}
        if "state" not in values:
            return
        self.state = values["state"]
        try:
            samples = (int(values.get("pitch_samples", 0)), int(values.get("cl_samples", 0)))
        except ValueError:
            samples = (0, 0)
        self.liveness.status(time.monotonic(), self.state, samples)

    def spin(self, seconds: float) -> None:
        self.node.spin_until(lambda: False, seconds)

    def close(self) -> None:
        self.node.close()
