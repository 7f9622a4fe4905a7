"""Each node's side of the start barrier (barrier.py): its readiness report on /graph/ready,
published at once and whenever it changes, so that the lead starts the stream only when every
member's endpoints are matched and every member is ready (never after a sleep)."""

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from .barrier import Endpoint, ReadinessReport
from .endpoints import CdrPublisher, endpoint_record
from .interface import GRAPH_READY

if TYPE_CHECKING:
    from .node import Node

__all__ = ["Readiness"]


class Readiness:
    """What one node reports to the start barrier (``Node.readiness``); run_node starts it."""

    def __init__(self, node: "Node") -> None:
        self.node = node
        self.ready = True  # the node's own readiness (default: ready once constructed)
        self.reason = ""
        self.required_inputs: list[str] = []  # create_subscription(required=True)
        self.records: tuple[tuple[str, ...], tuple[str, ...]] = ((), ())
        self._pub: CdrPublisher | None = None
        self._endpoint_cls: Any = None  # aero_rig_interfaces/Endpoint, once started
        self._last_report: ReadinessReport | None = None
        self._last_signature: object = None

    def set_ready(self, ready: bool, reason: str = "") -> None:
        self.ready = bool(ready)
        self.reason = "" if ready else (reason or "not ready")

    def set_records(self, topics: Sequence[str], excluded: Sequence[str] = ()) -> None:
        self.records = (tuple(topics), tuple(excluded))

    def endpoints(self) -> list[Endpoint]:
        """The node's readers and writers with their matched counts (rclpy does not name the
        matched endpoints, so the start barrier compares counts)."""
        node, fq = self.node, self.node.fq_name
        out = [
            endpoint_record(p, "writer", f"{fq}#writer{i}", p.matched_count())
            for i, p in enumerate(node.rig_publishers)
        ]
        out += [
            endpoint_record(s, "reader", f"{fq}#reader{i}", s.matched_count())
            for i, s in enumerate(node.rig_subscriptions)
        ]
        return out

    def report(self) -> ReadinessReport:
        return ReadinessReport(
            node=self.node.fq_name,
            ready=self.ready,
            reason=self.reason,
            endpoints=tuple(self.endpoints()),
            required_inputs=tuple(self.required_inputs),
            records=self.records[0],
            excluded=self.records[1],
        )

    def start(self, period_s: float = 0.05) -> None:
        """Publish the report now and whenever it changes. Every ``period_s`` only the matched
        counts are compared (cheap); the report is rebuilt when they or the node's own
        readiness changed."""
        if self._pub is not None:
            return
        node = self.node
        # The anomaly writer exists before the node reports ready, so the barrier sees it matched
        # to the identifier and the recorder: a first anomaly record is never sent into the void.
        _ = node.anomalies
        from aero_rig_interfaces.msg import Endpoint as EndpointMsg
        from aero_rig_interfaces.msg import ReadinessReport as ReportMsg

        from .qos_profiles import topic_qos

        self._endpoint_cls = EndpointMsg
        self._pub = node.create_publisher(ReportMsg, GRAPH_READY.name, topic_qos(GRAPH_READY))
        self.announce()
        node.create_timer(period_s, self.announce)

    def announce(self) -> None:
        assert self._pub is not None
        counts = tuple(e.matched_count for e in self.endpoints())
        signature = (self.ready, self.reason, counts)
        if signature == self._last_signature:
            return
        self._last_signature = signature
        report = self.report()
        if report != self._last_report:
            self._last_report = report
            self._pub.publish(report.to_message(self._pub.handle.msg_type, self._endpoint_cls))
