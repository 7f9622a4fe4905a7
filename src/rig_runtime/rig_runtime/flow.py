"""The flow of the graph's streams: what each reader has received and each writer has sent,
and what that says about the graph (docs/design.md §3.11).

Every graph node (``run_node``) reports, every :data:`FLOW_PERIOD_S` on ``/diagnostics``, the
flow of its reliable keep-all endpoints (the ``stream`` profile, qos.py): per writer and reader,
how many messages it has passed and the header stamp of the last one (every stream type begins
with a std_msgs/Header). One ``DiagnosticStatus`` per node, named ``"<node>: flow"``, its
``hardware_id`` the node's fully qualified name, one value per endpoint::

    key "writer /pitch/state"  value "<count> <stamp ns> <matched>"
    key "reader /pitch/command"  value "<count> <stamp ns> <matched>"

(``matched``: the endpoints of the other side it is matched with, as rclpy counts them.)

:class:`FlowWatch` judges those reports (the campaign's monitor feeds it):

- **A stuck reader** stops receiving while its writer goes on: its node still reports (the
  process runs), and for :data:`STUCK_S` its writer has been ahead of it (reported later
  samples after the reader last moved) while its last stamp stood still. A paused or starved
  process reports nothing, so a paused reader or writer is not mistaken for a stuck one (the
  launcher names stopped processes).
- **A partition:** every node of another host falls silent at once for :data:`SILENT_S`
  while a node of this host still reports: the network between the hosts, or that host, is
  down. One paused node is not a partition; a partition of one node is indistinguishable
  from its host stopping, and is named as either.
"""

from collections.abc import Callable, Iterable, Mapping
from collections.abc import Set as AbstractSet
from dataclasses import dataclass, field
from typing import Any

FLOW_PERIOD_S = 0.5  # each node's flow report [s]
STUCK_S = 1.5  # a running reader whose stamp stood still this long while its writer went on
SILENT_S = 1.5  # every node of a host silent this long: a partition (3 reports missed)
FLOW_STATUS_SUFFIX = ": flow"
WRITER, READER = "writer", "reader"


@dataclass(frozen=True)
class EndpointFlow:
    """What one endpoint has passed: messages, and the header stamp of the last (0: none)."""

    count: int
    stamp_ns: int
    matched: int = -1  # -1: not reported


def flow_values(endpoints: Iterable[tuple[str, str, int, int, int]]) -> dict[str, str]:
    """The report's values from ``(kind, topic, count, stamp_ns, matched)`` per endpoint."""
    return {
        f"{kind} {topic}": f"{count} {stamp} {matched}"
        for kind, topic, count, stamp, matched in endpoints
    }


def parse_flow(values: Mapping[str, str]) -> dict[tuple[str, str], EndpointFlow]:
    """``{(kind, topic): flow}`` from a report's values; values that are not flow are skipped."""
    out: dict[tuple[str, str], EndpointFlow] = {}
    for key, value in values.items():
        kind, _, topic = key.partition(" ")
        if kind not in (WRITER, READER) or not topic.startswith("/"):
            continue
        try:
            numbers = [int(x) for x in value.split()]
        except ValueError:
            continue
        if len(numbers) not in (2, 3):
            continue
        out[(kind, topic)] = EndpointFlow(*numbers)
    return out


def flow_reports(msg: Any) -> Iterable[tuple[str, dict[tuple[str, str], EndpointFlow]]]:
    """``(node, flows)`` for each flow status of a diagnostic_msgs/DiagnosticArray."""
    for status in msg.status:
        if str(status.name).endswith(FLOW_STATUS_SUFFIX):
            yield str(status.hardware_id), parse_flow({kv.key: kv.value for kv in status.values})


@dataclass(frozen=True)
class FlowEvent:
    """What the watch concluded, when (the caller's clock) and the facts behind it."""

    kind: str  # "stuck", "receiving", "partition", "rejoined"
    at: float
    text: str
    detail: dict[str, Any]

    def to_dict(self) -> dict[str, Any]:
        return {"event": self.kind, "at_s": round(self.at, 3), "text": self.text, **self.detail}


@dataclass
class _Reader:
    stamp_ns: int
    count: int
    moved_at: float  # when its stamp last moved
    matched: int = -1  # writers it is matched with, at its last report
    behind_since: float | None = None  # since when its writer has been ahead of it, unmoved
    stuck: bool = False


@dataclass
class _Writer:
    node: str
    stamp_ns: int
    moved_at: float


@dataclass
class FlowWatch:
    """Judges the nodes' flow reports: stuck readers, and partitions from ``remote`` hosts.

    ``remote``: ``{node fq name: host}`` of the nodes other machines run (empty: one machine,
    no partition to judge); ``local``: this machine's nodes. ``describe_stamp`` names a stamp
    for the text (e.g. a plan sample).
    """

    remote: Mapping[str, str] = field(default_factory=dict)
    # this machine's nodes: a partition is judged against them (empty: any node not remote)
    local: AbstractSet[str] = field(default_factory=frozenset)
    describe_stamp: Callable[[int], str] = field(default=lambda ns: f"stamped {ns} ns")
    stuck_s: float = STUCK_S
    silent_s: float = SILENT_S
    events: list[FlowEvent] = field(default_factory=list)
    heard: dict[str, float] = field(default_factory=dict)  # node: when it last reported
    # node: its last report, per (kind, topic)
    latest: dict[str, dict[tuple[str, str], EndpointFlow]] = field(default_factory=dict)
    _readers: dict[tuple[str, str], _Reader] = field(default_factory=dict)  # (node, topic)
    _writers: dict[str, _Writer] = field(default_factory=dict)  # topic
    _partitioned: dict[str, float] = field(default_factory=dict)  # host: silent since
    _told: int = 0  # events returned by check()
    _hosts: dict[str, list[str]] = field(default_factory=dict)  # host: its nodes (of remote)

    def __post_init__(self) -> None:
        for node, host in self.remote.items():
            self._hosts.setdefault(host, []).append(node)

    def report(self, now: float, node: str, flows: Mapping[tuple[str, str], EndpointFlow]) -> None:
        """One node's flow report, received at ``now``."""
        self.heard[node] = now
        self.latest[node] = dict(flows)
        for (kind, topic), flow in flows.items():
            if kind == WRITER:
                writer = self._writers.get(topic)
                if writer is None or flow.stamp_ns > writer.stamp_ns:
                    self._writers[topic] = _Writer(node, flow.stamp_ns, now)
                continue
            reader = self._readers.get((node, topic))
            if reader is not None:
                reader.matched = flow.matched
            if reader is None or flow.stamp_ns != reader.stamp_ns:
                self._readers[(node, topic)] = _Reader(flow.stamp_ns, flow.count, now, flow.matched)
                if reader is not None and reader.stuck:
                    self._emit(
                        "receiving",
                        now,
                        f"reader of {topic} at {node} receives again, "
                        f"{self.describe_stamp(flow.stamp_ns)}",
                        topic=topic,
                        node=node,
                    )

    def check(self, now: float) -> list[FlowEvent]:
        """The events concluded since the last call (also those its reports concluded)."""
        self._check_readers(now)
        self._check_hosts(now)
        new, self._told = self.events[self._told :], len(self.events)
        return new

    def stuck_readers(self) -> list[tuple[str, str]]:
        """``(node, topic)`` of the readers stuck now."""
        return [key for key, reader in self._readers.items() if reader.stuck]

    def partitioned(self) -> dict[str, float]:
        """``{host: silent since}`` of the hosts cut off now."""
        return dict(self._partitioned)

    def silent(self, now: float) -> dict[str, float | None]:
        """``{node: seconds since its last report}`` of the nodes not heard within two report
        periods (None: never heard), the graph's nodes as given and those that reported."""
        nodes = sorted({*self.remote, *self.local, *self.heard})
        return {
            n: (round(now - self.heard[n], 1) if n in self.heard else None)
            for n in nodes
            if not self._running(n, now)
        }

    def graph_state(self, now: float) -> dict[str, Any]:
        """What every node last reported: how long ago, and per endpoint the messages it passed,
        its last sample and the endpoints it is matched with; the record of a stall (a stuck
        reader, a deaf observer and a stopped writer read differently here)."""
        return {
            node: {
                "heard_s_ago": round(now - self.heard[node], 1),
                "endpoints": {
                    f"{kind} {topic}": {
                        "count": flow.count,
                        "last": self.describe_stamp(flow.stamp_ns),
                        "matched": flow.matched,
                    }
                    for (kind, topic), flow in sorted(flows.items())
                },
            }
            for node, flows in sorted(self.latest.items())
        }

    def _check_readers(self, now: float) -> None:
        for (node, topic), reader in self._readers.items():
            writer = self._writers.get(topic)
            if reader.stuck or writer is None or writer.node == node:
                continue
            # The writer went on: it sent later samples after the reader last moved, and it
            # runs now, or it went on for two reports (a writer paused right after its last
            # report may have samples in flight that the reader will get once it runs again).
            ahead = writer.stamp_ns > reader.stamp_ns and writer.moved_at > reader.moved_at
            went_on = ahead and (
                self._running(writer.node, now)
                or writer.moved_at - reader.moved_at >= 2 * FLOW_PERIOD_S
            )
            if not went_on or not self._running(node, now):
                # behind while it does not run (paused, starved) is not stuck: once it runs
                # again it has STUCK_S to catch up
                reader.behind_since = None
                continue
            if reader.behind_since is None:
                reader.behind_since = now
            if now - reader.behind_since >= self.stuck_s:
                reader.stuck = True
                self._emit(
                    "stuck",
                    now,
                    f"reader stuck: {topic} at {node} has received nothing for "
                    f"{now - reader.behind_since:.1f} s while its writer {writer.node} went on; "
                    f"its last sample is {self.describe_stamp(reader.stamp_ns)} ({reader.count} "
                    f"received), the writer's {self.describe_stamp(writer.stamp_ns)}"
                    + (
                        f"; it is matched with {reader.matched} writer(s)"
                        if reader.matched >= 0
                        else ""
                    ),
                    topic=topic,
                    node=node,
                    writer=writer.node,
                    last_stamp_ns=reader.stamp_ns,
                    received=reader.count,
                    matched=reader.matched,
                    writer_stamp_ns=writer.stamp_ns,
                    behind_s=round(now - reader.behind_since, 3),
                )

    def _running(self, node: str, now: float) -> bool:
        """Whether ``node`` reported within two report periods (and some slack)."""
        return now - self.heard.get(node, float("-inf")) <= 2 * FLOW_PERIOD_S + 0.25

    def _check_hosts(self, now: float) -> None:
        for host, nodes in sorted(self._hosts.items()):
            last = [self.heard[n] for n in nodes if n in self.heard]
            others = [
                t
                for n, t in self.heard.items()
                if (n in self.local if self.local else self.remote.get(n) != host)
            ]
            if host in self._partitioned:
                if last and max(last) > self._partitioned[host]:
                    since = self._partitioned.pop(host)
                    self._emit(
                        "rejoined",
                        now,
                        f"host {host!r} heard again after {now - since:.1f} s of silence",
                        host=host,
                        silent_s=round(now - since, 3),
                    )
                continue
            if len(last) < len(nodes) or not others:
                continue  # not every node heard yet, or nothing to compare with
            since = max(last)
            if now - since >= self.silent_s and now - max(others) < self.silent_s:
                self._partitioned[host] = since
                self._emit(
                    "partition",
                    now,
                    f"partition: no node of host {host!r} ({', '.join(sorted(nodes))}) heard for "
                    f"{now - since:.1f} s while this host's are: the network to {host!r} is "
                    "down, or that host stopped",
                    host=host,
                    nodes=sorted(nodes),
                    silent_s=round(now - since, 3),
                )

    def _emit(self, kind: str, now: float, text: str, **detail: Any) -> None:
        self.events.append(FlowEvent(kind, now, text, detail))
