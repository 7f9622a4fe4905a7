"""The start barrier: the experiment's t0 waits until every node of the graph is matched.

A sample written on a reliable, volatile topic reaches only the readers its writer has matched
*at the time of the write*; DDS discovery is asynchronous and each side of a link learns of the
other on its own. So a stream that starts as soon as the first subscriber appears loses its
first samples at every reader that is still being discovered (the first wave's 1,000 lost
samples under load). Instead:

- Every node publishes a :class:`ReadinessReport` on ``/graph/ready``
  (aero_rig_interfaces/ReadinessReport, reliable + transient-local, as a latched topic in
  ROS 2): whether the node itself is ready (its application's own condition, e.g. a driver's
  link), and for each of its readers and
  writers the topic, the QoS, its GID and the GIDs of the endpoints it has matched (with
  rclpy, which does not expose matched GIDs, only the matched counts). It publishes again
  whenever that changes.
- The lead node (the generator) holds a :class:`StartBarrier` over the member nodes named by
  the graph description and starts the experiment only when :meth:`StartBarrier.pending` is
  empty: every member reported ready, every compatible writer/reader pair among the members
  is matched on *both* sides, every required input has a publisher, and a recorder has a
  reader on every member's topic that it records. No expected counts are written anywhere:
  the reports describe the graph as it is.

This module is plain data and logic (no middleware), so it is tested in-process.
"""

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

from .interface import GRAPH_READY


@dataclass(frozen=True)
class Endpoint:
    """One reader or writer of a node, as its node sees it."""

    topic: str
    kind: str  # "writer" | "reader"
    gid: str  # a name unique in the graph: "<node>#writer<i>"
    reliable: bool = True
    transient_local: bool = False
    matched_count: int = 0

    def to_dict(self) -> dict[str, object]:
        return {
            "topic": self.topic,
            "kind": self.kind,
            "gid": self.gid,
            "reliable": self.reliable,
            "transient_local": self.transient_local,
            "matched_count": self.matched_count,
        }

    @classmethod
    def from_dict(cls, d: dict[str, object]) -> "Endpoint":
        return cls(
            topic=str(d["topic"]),
            kind=str(d["kind"]),
            gid=str(d["gid"]),
            reliable=bool(d.get("reliable", True)),
            transient_local=bool(d.get("transient_local", False)),
            matched_count=int(d.get("matched_count", 0)),  # type: ignore[call-overload]
        )


ENDPOINT_FIELDS = ("topic", "kind", "gid", "reliable", "transient_local", "matched_count")


def compatible(writer: Endpoint, reader: Endpoint) -> bool:
    """Whether DDS matches this writer with this reader (the QoS that the profiles vary).

    Request/offer rules: a reliable reader needs a reliable writer; a transient-local reader
    needs a transient-local writer.
    """
    if writer.topic != reader.topic:
        return False
    if reader.reliable and not writer.reliable:
        return False
    return not (reader.transient_local and not writer.transient_local)


@dataclass(frozen=True)
class ReadinessReport:
    """What one node tells the barrier (aero_rig_interfaces/ReadinessReport, /graph/ready)."""

    node: str  # fully qualified node name, e.g. "/lift"
    ready: bool
    reason: str = ""  # why not ready (the node's own words)
    endpoints: tuple[Endpoint, ...] = ()
    required_inputs: tuple[str, ...] = ()  # topics that need at least one publisher
    records: tuple[str, ...] = ()  # a recorder: the topics it records ("*": all but excluded)
    excluded: tuple[str, ...] = ()

    def to_message(self, report_cls: Any, endpoint_cls: Any) -> Any:
        """Its aero_rig_interfaces/ReadinessReport message, of the given message classes."""
        return report_cls(
            node=self.node,
            ready=self.ready,
            reason=self.reason,
            endpoints=[endpoint_cls(**e.to_dict()) for e in self.endpoints],
            required_inputs=list(self.required_inputs),
            records=list(self.records),
            excluded=list(self.excluded),
        )

    @classmethod
    def from_message(cls, msg: Any) -> "ReadinessReport":
        """The report of an aero_rig_interfaces/ReadinessReport message."""
        return cls(
            node=str(msg.node),
            ready=bool(msg.ready),
            reason=str(msg.reason),
            endpoints=tuple(
                Endpoint.from_dict({f: getattr(e, f) for f in ENDPOINT_FIELDS})
                for e in msg.endpoints
            ),
            required_inputs=tuple(str(t) for t in msg.required_inputs),
            records=tuple(str(t) for t in msg.records),
            excluded=tuple(str(t) for t in msg.excluded),
        )


def qualify(name: str) -> str:
    """``lift`` -> ``/lift`` (member names in the graph are node names; reports carry FQNs)."""
    return name if name.startswith("/") else "/" + name


@dataclass
class StartBarrier:
    """Decides when every member of the graph is ready and matched (see module docstring).

    ``members``: the fully qualified names of the nodes to wait for (from the graph
    description); ``own``: the lead node's own report (its writers must be matched too).
    """

    members: Sequence[str]
    reports: dict[str, ReadinessReport] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.members = [qualify(m) for m in self.members]

    def update(self, report: ReadinessReport) -> None:
        self.reports[report.node] = report

    def pending(self, own: ReadinessReport | None = None) -> list[str]:
        """What the start still waits for, one line per problem naming the node (empty: go)."""
        problems: list[str] = []
        reports = [self.reports[m] for m in self.members if m in self.reports]
        for member in self.members:
            if member not in self.reports:
                problems.append(
                    f"{member}: no readiness report yet (not started or not on this ROS domain)"
                )
            elif not self.reports[member].ready:
                reason = self.reports[member].reason or "not ready"
                problems.append(f"{member}: {reason}")
        if own is not None:
            if not own.ready:
                problems.append(f"{own.node}: {own.reason or 'not ready'}")
            reports = [own, *(r for r in reports if r.node != own.node)]
        problems += _link_problems(reports)
        return problems


def _link_problems(reports: Iterable[ReadinessReport]) -> list[str]:
    reports = list(reports)
    owner: dict[str, str] = {}
    writers: dict[str, list[Endpoint]] = {}
    readers: dict[str, list[Endpoint]] = {}
    for report in reports:
        for e in report.endpoints:
            if e.topic == GRAPH_READY.name:
                continue  # the barrier's own channel is not part of the experiment
            owner[e.gid] = report.node
            (writers if e.kind == "writer" else readers).setdefault(e.topic, []).append(e)
    problems: list[str] = []
    # Each endpoint must have matched every compatible member endpoint on the other side.
    for topic in sorted(set(writers) | set(readers)):
        for side_list, other_list in (
            (writers.get(topic, []), readers.get(topic, [])),
            (readers.get(topic, []), writers.get(topic, [])),
        ):
            for e in side_list:
                others = [
                    o
                    for o in other_list
                    if (compatible(e, o) if e.kind == "writer" else compatible(o, e))
                ]
                if e.matched_count < len(others):
                    problems.append(
                        f"{owner[e.gid]}: its {e.kind} of {topic} has matched "
                        f"{e.matched_count} of {len(others)} member endpoints"
                    )
    for report in reports:
        own_readers = {e.topic: e for e in report.endpoints if e.kind == "reader"}
        for topic in report.required_inputs:
            reader = own_readers.get(topic)
            if reader is None or reader.matched_count < 1:
                problems.append(f"{report.node}: no publisher of its input {topic} yet")
        for topic in sorted(writers):
            wanted = topic in report.records or (
                "*" in report.records and topic not in report.excluded
            )
            if wanted and topic not in own_readers:
                problems.append(f"{report.node}: not recording {topic} yet")
    return problems
