"""Shared pieces of the graph tests: an in-process observer node that collects topics."""

import sys
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from multisine_gen.campaigns import build_plan
from multisine_gen.plan import ExperimentPlan
from rig_runtime.barrier import ReadinessReport
from rig_runtime.interface import DIAGNOSTICS, GRAPH_READY
from rig_runtime.messages import stamp_to_ns
from rig_runtime.node import CdrSubscription, Node
from rig_runtime.testing import finish, node_process, pause, start_session, wait_for


class Observer:
    """In-process subscriber (an rclpy node) keeping (stamp_ns, values) per topic."""

    def __init__(self, topics: dict[str, tuple[str, str]]) -> None:
        self.node = Node("test_observer", argv=[])
        self.data: dict[str, list[tuple[int, Any]]] = defaultdict(list)
        self.subs: list[CdrSubscription] = []
        for topic, (type_name, qos) in topics.items():

            def store(msg: Any, topic: str = topic) -> None:
                self._store(topic, msg)

            sub = self.node.create_subscription(type_name, topic, store, qos_profile=qos)
            self.subs.append(sub)

    def _store(self, topic: str, msg: Any) -> None:
        header = getattr(msg, "header", None)
        stamp = stamp_to_ns(header.stamp) if header is not None else 0
        self.data[topic].append((stamp, msg))

    def wait_matched(self, timeout_s: float = 30.0) -> bool:
        """Spin until every subscription has a matched publisher (discovery done)."""
        return self.node.spin_until(
            lambda: all(sub.publisher_count() > 0 for sub in self.subs), timeout_s
        )

    def spin_until(self, predicate: Any, timeout_s: float) -> bool:
        return self.node.spin_until(predicate, timeout_s)

    def stamps(self, topic: str) -> np.ndarray:
        return np.array([s for s, _ in self.data[topic]], dtype=np.int64)

    def counts(self) -> str:
        """What arrived, per topic: count, first and last stamp (for a failure's message)."""
        lines = []
        for topic, items in sorted(self.data.items()):
            first, last = (items[0][0], items[-1][0]) if items else (0, 0)
            lines.append(f"{topic}: {len(items)} messages, stamps {first}..{last} ns\n")
        return "".join(lines)

    def close(self) -> None:
        self.node.close()


def subscribe_diagnostics(
    node: Node, name_part: str, entries: list[Any], hardware_id: bool = False
) -> Any:
    """Append the values (dict) of every /diagnostics status whose name holds ``name_part`` to
    ``entries`` (as ``(hardware_id, values)`` with ``hardware_id=True``)."""

    def on_array(msg: Any) -> None:
        for status in msg.status:
            if name_part in status.name:
                values = {kv.key: kv.value for kv in status.values}
                entries.append((status.hardware_id, values) if hardware_id else values)

    return node.create_subscription(DIAGNOSTICS.type, DIAGNOSTICS.name, on_array)


def wait_diagnostics(
    node: Node,
    entries: list[Any],
    predicate: Any,
    timeout_s: float = 10.0,
    values: Any = lambda entry: entry,
) -> Any:
    """Spin until the latest collected status satisfies ``predicate``; return that entry."""
    ok = node.spin_until(lambda: bool(entries) and predicate(values(entries[-1])), timeout_s)
    assert ok, f"diagnostics never satisfied the check; last: {entries[-1:]}"
    return entries[-1]


class PeerReaders:
    """The readers of the nodes under test, from their readiness reports on /graph/ready (what
    the start barrier reads): a test that publishes to a node waits until that node's reader
    has matched the test's writer, not only the other way round. Fast DDS drops what a
    reliable, volatile writer sends before the reader side has matched it."""

    def __init__(self, node: Node) -> None:
        self.reports: dict[str, ReadinessReport] = {}
        node.create_subscription(GRAPH_READY.type, GRAPH_READY.name, self._on_report, "latched")

    def _on_report(self, msg: Any) -> None:
        report = ReadinessReport.from_json(msg.data)
        self.reports[report.node] = report

    def matched(self, topics: list[str]) -> bool:
        """Every topic has a reader in some node's report, and every such reader is matched."""
        return self._matched("reader", topics)

    def writers_matched(self, topics: list[str]) -> bool:
        """Every topic has a writer in some node's report, and every such writer has matched a
        reader (the test's own, once the node under test has seen it)."""
        return self._matched("writer", topics)

    def _matched(self, kind: str, topics: list[str]) -> bool:
        ends = [
            e
            for r in self.reports.values()
            for e in r.endpoints
            if e.kind == kind and e.topic in topics
        ]
        return {e.topic for e in ends} >= set(topics) and all(e.matched_count > 0 for e in ends)


def small_plan_design() -> ExperimentPlan:
    """A small plan for the graph tests that need a whole campaign but not the short plan's
    Table 1 (the fault tests, the launch test): the short plan's grid and level design, one
    level (6.6°), two realizations of 2 periods, one 1 Hz sine: 13,764 samples, 69 s of
    experiment against the short plan's 225 s."""
    return build_plan(
        N=2_000,
        f_min_hz=0.1,
        f_max_hz=1.98,
        offsets_deg=(6.6,),
        realizations=2,
        periods=2,
        settle_periods=1,
        crest_factor_reduction=False,
        sine_frequencies_hz=(1.0,),
        sine_offsets_deg=(5.9,),
        sine_min_periods=5,
        sine_min_duration_s=0.0,
        sine_settle_s=0.0,
        baseline=None,
        ramp_rate_deg_s=10.0,
        seed=0,
        limits=None,
    )


# The campaign's processes in the order they are paused (campaign_paused_in_turn).
CAMPAIGN_NODES = ("generator", "sim_actuator", "sim_wing", "lift", "identifier", "recorder")


def campaign_paused_in_turn(
    args: Sequence[str], run: Path, env: dict[str, str], seconds: float = 3.0
) -> tuple[int, str, str, list[str]]:
    """``aero-rig campaign *args --out run``, each of its nodes SIGSTOPped for ``seconds`` in
    turn once the start barrier has passed, until the run ends. Its exit code, stdout, stderr
    and the nodes paused (tests/test_campaign.py's paused-in-turn test, bench/paused_sync.py)."""
    cli = [sys.executable, "-m", "aero_rig.cli", "campaign", *args, "--out", str(run)]
    proc = start_session(cli, env)
    paused: list[str] = []
    try:
        log = run / "logs" / "generator.log"
        assert wait_for(lambda: log.exists() and "start barrier passed" in log.read_text(), 120)
        for node in CAMPAIGN_NODES:
            target = node_process(proc.pid, node)
            if target is None or proc.poll() is not None:
                break
            pause(target, seconds)
            paused.append(node)
    finally:
        out, err = finish(proc, 600)
    return proc.returncode, out, err, paused
