"""Each node's report of its streams' flow on /diagnostics (flow.py reads it): what each stream
reader has received and each stream writer has sent, every ``period_s``. It is also the node's
heartbeat: a host whose nodes all fall silent is cut off (docs/design.md §3.11)."""

import time
from typing import TYPE_CHECKING

from .diagnostics import OK, diagnostic_array
from .endpoints import CdrPublisher
from .flow import FLOW_PERIOD_S, FLOW_STATUS_SUFFIX, flow_values
from .interface import DIAGNOSTICS

if TYPE_CHECKING:
    from .node import Node

__all__ = ["FlowReport"]


class FlowReport:
    """The flow report of one node (``Node.flow_report``); run_node starts it."""

    def __init__(self, node: "Node") -> None:
        self.node = node
        self.publisher: CdrPublisher | None = None
        self.period_s = FLOW_PERIOD_S
        self._tick = 0.0  # monotonic time of the last report

    def start(self, period_s: float = FLOW_PERIOD_S) -> None:
        if self.publisher is not None:
            return
        node = self.node
        from diagnostic_msgs.msg import DiagnosticArray

        from .qos_profiles import topic_qos

        self.publisher = node.create_publisher(
            DiagnosticArray, DIAGNOSTICS.name, topic_qos(DIAGNOSTICS)
        )
        self.period_s = period_s
        node.create_timer(period_s, self.report)

    def report(self) -> None:
        assert self.publisher is not None
        node = self.node
        self.take_undelivered()
        endpoints = [("writer", p) for p in node.rig_publishers] + [
            ("reader", s) for s in node.rig_subscriptions
        ]
        values = flow_values(
            (kind, e.topic, e.count, e.stamp_ns, e.matched_count())
            for kind, e in endpoints
            if e.streams
        )
        name = node.fq_name + FLOW_STATUS_SUFFIX
        self.publisher.publish(diagnostic_array(name, OK, "", node.fq_name, values))

    def take_undelivered(self) -> None:
        """Take what a stream reader holds but its executor was not woken for: a reader that
        delivered nothing since the last report is asked directly (rmw take, as the executor
        would). What it holds is delivered in order; the samples held for a period or longer
        are counted (``undelivered``) and logged."""
        now = time.monotonic()
        # A tick late by more than a period: this process did not run (paused, starved), and
        # what arrived meanwhile is still queued for its executor. Judge at the next tick.
        ran = now - self._tick <= 2 * self.period_s
        self._tick = now
        held_since = time.time_ns() - int(self.period_s * 1e9)
        for sub in self.node.rig_subscriptions:
            if not sub.streams or sub.count != sub.polled_at or not ran:
                sub.polled_at = sub.count
                continue
            held = 0  # taken samples received a whole period ago or earlier
            handle = sub.handle
            while True:
                # rclpy has no public take for a subscription its executor serves (the
                # executor's own take is Subscription.handle.take_message): the same call.
                try:
                    with handle.handle:
                        info = handle.handle.take_message(handle.msg_type, handle.raw)
                except Exception:  # destroyed while closing: nothing to take
                    break
                if info is None:
                    break
                received = info[1].get("received_timestamp", 0) if len(info) > 1 else 0
                held += 0 < received <= held_since
                handle.callback(info[0])
            sub.polled_at = sub.count
            if held:
                sub.undelivered += held
                self.node.logger.warning(
                    "reader of %s: %d sample(s) were held undelivered for %g s or more (its "
                    "executor was not woken); taken now, the last stamped %d ns",
                    sub.topic,
                    held,
                    self.period_s,
                    sub.stamp_ns,
                )
