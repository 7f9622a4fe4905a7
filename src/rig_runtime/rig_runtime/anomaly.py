"""Anomalies: what went wrong with the experiment's samples, by stamp range.

Any node that knows that a stretch of the stream is not what the plan asked for (the actuator
ran on without commands, its watchdog tripped, a command was clamped or refused, a scanner frame
was lost, a state had no finite pitch, the lift had no pitch for a taps sample, ...) publishes
an :class:`Anomaly` on ``/experiment/anomaly`` (aero_rig_interfaces/Anomaly, "events" QoS:
reliable, keep-last 1000). The identifier and the offline fit exclude every period and sine
record whose stamps the range touches and name the anomaly in their reports; the recorder
keeps them in the bag. An episode whose end is not known yet (a free-run in progress) is
published open (``open`` true) and published again, under the same ``id``, when it ends.

This module is plain data (no middleware): the identification reads it as well.
"""

import json
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any


@dataclass(frozen=True)
class Anomaly:
    """A stamp range [first_ns, last_ns] of the experiment that must not be trusted."""

    id: str  # unique per episode: "<node>/<kind>/<n>"; a re-publication replaces it
    node: str
    kind: str  # free_run | watchdog | clamped | refused | time_discontinuity | frame_loss | ...
    first_ns: int
    last_ns: int | None  # None: still going on
    detail: str = ""

    def to_json(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> "Anomaly":
        try:
            d = json.loads(text)
            last = d.get("last_ns")
            return cls(
                id=str(d["id"]),
                node=str(d["node"]),
                kind=str(d["kind"]),
                first_ns=int(d["first_ns"]),
                last_ns=None if last is None else int(last),
                detail=str(d.get("detail", "")),
            )
        except (ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"not an anomaly record: {text[:120]!r} ({exc})") from None

    def to_fields(self) -> dict[str, Any]:
        """The fields of its aero_rig_interfaces/Anomaly message (open: last_ns not known)."""
        return {
            "id": self.id,
            "node": self.node,
            "kind": self.kind,
            "first_ns": self.first_ns,
            "open": self.last_ns is None,
            "last_ns": 0 if self.last_ns is None else self.last_ns,
            "detail": self.detail,
        }

    @classmethod
    def from_message(cls, msg: Any) -> "Anomaly":
        """The record of an /experiment/anomaly message: an aero_rig_interfaces/Anomaly, or the
        std_msgs/String JSON of a bag recorded before the rig had its own messages."""
        if hasattr(msg, "data"):
            return cls.from_json(str(msg.data))
        return cls(
            id=str(msg.id),
            node=str(msg.node),
            kind=str(msg.kind),
            first_ns=int(msg.first_ns),
            last_ns=None if msg.open else int(msg.last_ns),
            detail=str(msg.detail),
        )

    def label(self) -> str:
        """``node kind: detail``: how reports name the anomaly."""
        head = f"{self.node} {self.kind}"
        return f"{head}: {self.detail}" if self.detail else head

    def describe(self) -> str:
        end = "still open" if self.last_ns is None else f"{self.last_ns}"
        text = f"{self.node} {self.kind} [{self.first_ns} .. {end}] ns"
        return f"{text}: {self.detail}" if self.detail else text


PublishFn = Callable[[Anomaly], None]


class AnomalyLog:
    """Builds a node's anomaly records: point events, and episodes that stay open until closed.

    ``publish`` is called with every record to send (a node passes its publisher's send).
    Consecutive marks of one kind form one episode (a run of invalid samples is one record,
    not thousands): :meth:`mark` opens or extends it, :meth:`clear` closes it.
    """

    def __init__(self, node_name: str, publish: PublishFn) -> None:
        self.node = node_name.lstrip("/") or node_name
        self._publish = publish
        self._count = 0
        self.open: dict[str, Anomaly] = {}
        self._extent: dict[str, int] = {}  # last stamp marked in each open episode
        self.published: list[Anomaly] = []

    def _new_id(self, kind: str) -> str:
        self._count += 1
        return f"{self.node}/{kind}/{self._count}"

    def _send(self, anomaly: Anomaly) -> None:
        self.published.append(anomaly)
        self._publish(anomaly)

    def point(self, kind: str, first_ns: int, last_ns: int | None = None, detail: str = "") -> None:
        """A closed range (a single stamp when ``last_ns`` is omitted)."""
        last = first_ns if last_ns is None else last_ns
        lo, hi = min(first_ns, last), max(first_ns, last)
        self._send(Anomaly(self._new_id(kind), self.node, kind, lo, hi, detail))

    def begin(self, kind: str, first_ns: int, detail: str = "") -> None:
        """Open an episode (published at once as open-ended); no-op if one is open."""
        if kind in self.open:
            return
        anomaly = Anomaly(self._new_id(kind), self.node, kind, first_ns, None, detail)
        self.open[kind] = anomaly
        self._extent[kind] = first_ns
        self._send(anomaly)

    def mark(self, kind: str, stamp_ns: int, detail: str = "") -> None:
        """This stamp belongs to the kind's episode (opened if needed)."""
        if kind not in self.open:
            self.begin(kind, stamp_ns, detail)
        self._extent[kind] = max(self._extent[kind], stamp_ns)

    def end(self, kind: str, last_ns: int | None = None, detail: str | None = None) -> None:
        """Close the kind's open episode at ``last_ns`` (default: the last stamp marked)."""
        anomaly = self.open.pop(kind, None)
        extent = self._extent.pop(kind, None)
        if anomaly is None:
            return
        last = extent if last_ns is None else max(last_ns, anomaly.first_ns)
        closed = Anomaly(
            anomaly.id,
            anomaly.node,
            anomaly.kind,
            anomaly.first_ns,
            last,
            anomaly.detail if detail is None else detail,
        )
        self._send(closed)

    def clear(self, kind: str) -> None:
        """A good sample: close the kind's episode at its last marked stamp, if one is open."""
        if kind in self.open:
            self.end(kind)

    def close_all(self) -> None:
        """At shutdown: close every open episode at its last marked stamp."""
        for kind in list(self.open):
            self.end(kind)
