"""Shared pieces of the graph tests: an in-process observer node that collects topics, the
small plan, campaigns with nodes paused in turn, and the graph on two hosts."""

import json
import os
import signal
import subprocess
import sys
import time
from collections import defaultdict
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from aero_rig.verdict import STREAM_TOPICS
from multisine_gen.campaigns import build_plan
from multisine_gen.plan import ExperimentPlan
from rig_runtime.barrier import ReadinessReport
from rig_runtime.graph import load_graph, package_share
from rig_runtime.interface import DIAGNOSTICS, GRAPH_READY, PITCH_COMMAND
from rig_runtime.launcher import Launcher
from rig_runtime.messages import stamp_to_ns
from rig_runtime.node import CdrSubscription, Node
from rig_testing.netlab import NetLab
from rig_testing.processes import finish, node_process, pause, start_session, wait_for


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
        report = ReadinessReport.from_message(msg)
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


# The runs whose tables are compared use the release-0.1 wing (docs/plant.md, "Presets"): its
# high-offset periods repeat, so Table 1 is testable on the short and small plans.
WING = ("-p", "sim_wing.preset:=repeatable_stall")

# -- the graph on two hosts (rig_testing.netlab) ------------------------------------------------
RIG, WORKSTATION, TOOLS = "rig", "workstation", "tools"
LAB_HOSTS = [RIG, WORKSTATION, TOOLS]  # TOOLS: a third machine for the ros2 command


def pull_cable(lab: NetLab, seconds: float) -> Callable[[Any], None]:
    """A fault: the rig's cable pulled at the switch for ``seconds``, then plugged again."""

    def fault(_campaign: Any) -> None:
        lab.link(RIG, False)
        try:
            time.sleep(seconds)  # the fault's length, not a wait for a peer
        finally:
            lab.link(RIG, True)

    return fault


def rig_launch(host: str, sets: Sequence[str]) -> list[str]:
    """``rig-launch sim.yaml --host HOST -p SET ...`` as this interpreter runs it."""
    sim = str(package_share("aero_rig") / "config" / "sim.yaml")
    command = [sys.executable, "-m", "rig_runtime.launcher", sim, "--host", host]
    return command + [arg for s in sets for arg in ("-p", s)]


def lab_env(lab: NetLab, host: str, base: dict[str, str], static_peers: bool) -> dict[str, str]:
    """The environment of ``host``'s processes: ROS's default discovery range (SUBNET,
    multicast), or ``static_peers``: LOCALHOST with the other hosts in ROS_STATIC_PEERS, as
    ROS 2 documents for reaching named machines. Asynchronous publication, as the one-host
    campaign at full speed."""
    env = {**base, "RMW_FASTRTPS_PUBLICATION_MODE": "ASYNCHRONOUS"}
    env.pop("ROS_STATIC_PEERS", None)
    if static_peers:
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        env["ROS_STATIC_PEERS"] = ";".join(lab.address(h) for h in lab.hosts if h != host)
    else:
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"
    return env


@dataclass
class TwoHostRun:
    """A campaign split over the lab's rig and workstation hosts, as it ended."""

    code: int  # the campaign's exit code
    out: str
    err: str
    rig_code: int  # rig-launch's, stopped by SIGINT once the campaign ended
    rig_log: str
    wall_s: float  # the campaign's, start to exit
    started: float  # epoch seconds of the campaign's start
    fault_at: float | None = None  # epoch seconds of the fault

    @staticmethod
    def summary_of(run: Path) -> dict[str, Any]:
        """The run's campaign.json."""
        return json.loads((run / "campaign.json").read_text())


def two_host_campaign(
    lab: NetLab,
    plan: Path,
    run: Path,
    base_env: dict[str, str],
    *,
    static_peers: bool = False,
    rig_overrides: Sequence[str] = (WING[1],),
    during: Callable[["subprocess.Popen[str]"], None] | None = None,
    real_time_factor: float = 0.0,
    timeout_s: float = 600.0,
) -> TwoHostRun:
    """The simulated graph of config/sim.yaml on two hosts: ``rig-launch --host rig`` on the
    lab's rig (generator, actuator, wing, lift) and ``aero-rig campaign --host workstation``
    on its workstation (identifier, recorder), as a lab runs it on two machines. ``during``
    (given the campaign's process) runs once the identifier holds the first realization, and
    must find the stream running: the run fails if the identifier already holds the plan's
    end (pace such a run with ``real_time_factor``; 0: as fast as the graph goes)."""
    sets = [f"generator.plan:={plan}", f"generator.real_time_factor:={real_time_factor}"]
    sets += rig_overrides
    rig_cmd = rig_launch(RIG, sets)
    cli = [sys.executable, "-m", "aero_rig.cli", "campaign", "--plan", str(plan)]
    cli += ["--host", WORKSTATION, "--out", str(run), "--quiet", "--timeout", str(timeout_s)]
    rig = start_session(lab.command(RIG, rig_cmd), lab_env(lab, RIG, base_env, static_peers))
    fault_at = None
    ended_early = False
    streamed_before_fault = False  # the identifier held the plan's end when the fault came
    try:
        started = time.time()
        proc = start_session(
            lab.command(WORKSTATION, cli), lab_env(lab, WORKSTATION, base_env, static_peers)
        )
        try:
            if during is not None:
                log = run / "logs" / "identifier.log"
                held = wait_for(
                    lambda: (
                        (log.exists() and "realization 0 complete" in log.read_text())
                        or proc.poll() is not None
                    ),
                    timeout_s,
                )
                ended_early = not held or proc.poll() is not None
                if not ended_early:
                    # a refit's reason names "plan end" once the identifier holds the whole plan
                    streamed_before_fault = "plan end" in log.read_text()
                    fault_at = time.time()
                    during(proc)
        finally:
            out, err = finish(proc, timeout_s + 120)
        wall = time.time() - started
    finally:
        if rig.poll() is None:
            os.killpg(rig.pid, signal.SIGINT)
        rig_out, rig_err = finish(rig, 60)
    if ended_early:  # what the campaign and the rig said, and the graph at a stall
        summary = run / "campaign.json"
        state = json.loads(summary.read_text()).get("flow_at_stall") if summary.exists() else None
        raise AssertionError(
            f"the campaign ended before the fault (exit {proc.returncode}):\n{err[-4000:]}\n"
            f"rig (exit {rig.returncode}):\n{(rig_out + rig_err)[-3000:]}\n"
            f"flow_at_stall: {json.dumps(state, indent=1)}"
        )
    if streamed_before_fault:
        raise AssertionError(
            "the identifier held the plan's end before the fault: the stream was over, so the "
            "fault did not cut it (pace the run with real_time_factor)\n" + err[-3000:]
        )
    return TwoHostRun(
        proc.returncode, out, err, rig.returncode, rig_out + rig_err, wall, started, fault_at
    )


# What a run that lost its stream logs (the first wave's failure under load: the actuator ran on
# in real time and its time went backwards); every anomaly is logged as "anomaly: ...".
CORRUPTION_SIGNS = ("running on in real time", "time went backwards", "anomaly:")


def stream_stamps(bag: Path) -> dict[str, list[int]]:
    stamps: dict[str, list[int]] = {}
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic in STREAM_TOPICS]
        for conn, _, raw in reader.messages(connections=conns):
            msg: Any = reader.deserialize(raw, conn.msgtype)
            stamps.setdefault(conn.topic, []).append(stamp_to_ns(msg.header.stamp))
    return stamps


def assert_lossless_and_identical(run: Path, reference: Path) -> None:
    models = json.loads((run / "models.json").read_text())
    assert models["data_quality"]["clean"], models["data_quality"]
    stamps = stream_stamps(run / "bag")
    commands = set(stamps[PITCH_COMMAND.name])
    assert len(commands) == len(stamps[PITCH_COMMAND.name]) > 0
    for topic in STREAM_TOPICS:
        missing = commands - set(stamps[topic])
        assert not missing, f"{topic}: {len(missing)} plan samples missing from the bag"
    for log in (run / "logs").glob("*.log"):
        text = log.read_text()
        for sign in CORRUPTION_SIGNS:
            assert sign not in text, f"{log.name}: {sign!r}"
    for name in ("table1_all_levels.md", "table1_level1.md"):
        assert (run / name).read_bytes() == (reference / name).read_bytes(), name


ROS2 = Path(sys.executable).parent / "ros2"
# The ros2 CLI tests' marks: CI must run them; elsewhere they skip, saying why.
NEEDS_ROS2_TOOLS = [
    pytest.mark.ci_required,
    pytest.mark.skipif(
        not ROS2.exists(),
        reason="the ros2 tools are not in the venv (make test installs them from "
        "../shared/ros2-python; absent here)",
    ),
]
SIM_NODES = ["/generator", "/identifier", "/lift", "/recorder", "/sim_actuator", "/sim_wing"]


class Ros2Graph:
    """A running graph and the real ``ros2`` command in its environment."""

    def __init__(self, env: dict[str, str]) -> None:
        self.env = env

    def ros2(self, *args: str, timeout: float = 60.0) -> str:
        """Run ``ros2 ARGS``: its output (stdout, then stderr, where ros2 param set reports a
        refusal), or an assertion error if it failed."""
        proc = subprocess.run(
            [str(ROS2), *args], env=self.env, capture_output=True, text=True, timeout=timeout
        )
        assert proc.returncode == 0, (args, proc.returncode, proc.stdout, proc.stderr[-2000:])
        return proc.stdout + proc.stderr


@contextmanager
def sim_graph_for_ros2(
    env: dict[str, str], tmp: Path, generator: dict[str, Any]
) -> Iterator[Ros2Graph]:
    """`aero-rig run sim`'s graph as rclpy node processes, with ``generator`` overrides, once
    the ros2 daemon of its domain lists all six nodes (as a user's first ros2 command starts
    it; every later command reads the graph it holds). Stops the daemon and the graph."""
    sim = load_graph(package_share("aero_rig") / "config" / "sim.yaml")
    overrides: dict[str, dict[str, Any]] = {
        "generator": generator,
        "identifier": {"output_dir": str(tmp / "run"), "use_worker": False, "scan": False},
        "recorder": {"output": str(tmp / "run" / "bag")},
    }
    launcher = Launcher(sim, env=env, overrides=overrides, log_dir=tmp / "logs")
    running = Ros2Graph(env)
    launcher.start()
    try:
        running.ros2("daemon", "start")
        deadline = time.monotonic() + 90.0
        listed: list[str] = []
        while time.monotonic() < deadline and listed != SIM_NODES:
            assert launcher.poll() is None, launcher.failure
            listed = sorted(running.ros2("node", "list").split())
        assert listed == SIM_NODES, listed
        yield running
    finally:
        try:
            running.ros2("daemon", "stop")
        finally:
            launcher.stop()
