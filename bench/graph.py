"""Graph benchmark: the short plan through the simulated process graph of rclpy nodes.


Phase 1 (throughput): the whole campaign graph (generator, sim actuator, sim wing, lift,
identifier, recorder) runs the short plan as fast as it can (real_time_factor 0); prints the
real-time factor, samples lost (commands without a coefficients sample, from the bag), the
identifier's refit times, and CPU time and peak memory per node. With ``--view`` the Rerun view
node (save mode, ``campaign.rrd``) runs beside it, as ``aero-rig campaign --rerun save`` adds
it: its CPU is then one of the nodes', and ``view_received`` counts what it took of each stream
(it reads them best effort, so a view that cannot keep up shows as fewer samples).
Phase 2 (latency): the graph at real-time pace for ``--latency-seconds``; an observer in this
process timestamps the arrival of each /pitch/command sample and of its /wing/coefficients
sample (same stamp): end-to-end latency p50/p99.

    .venv/bin/python bench/graph.py [--plan short] [--latency-seconds 20] [--view]
    .venv/bin/python bench/graph.py --campaign [--before TREE] [--view] [--real-time-factor X]

``--campaign`` runs ``aero-rig campaign --plan default`` as a user does (asynchronous Fast DDS
publication, no view) and splits its wall time, from the node logs, into the start (processes
up, start barrier), streaming (barrier to the generator's plan end) and the final
identification (plan end to the report). ``--before TREE`` first runs the same campaign with the
code of another checkout (its ``src/*`` on PYTHONPATH, this venv), so that before and after are
measured in one run, and compares their tables byte for byte. ``--real-time-factor X`` paces
the campaign (``aero-rig campaign --real-time-factor X``): then the final identification's
split says how long after the plan's end a paced run's report comes. With ``--view`` the
campaign runs with ``--rerun save``: ``view`` gives what the view missed against the plan (its
last report: pitch and C_l samples, tap frames drawn) and ``rrd_rows`` the rows of each entity
path of the finished ``campaign.rrd``, read back with Rerun's reader.

Last line: JSON {"rclpy": {...}} (or {"before": ..., "after": ..., "tables_identical": ...}
with ``--campaign``), with real_time_factor, wall_s, samples, samples_lost,
latency_p50_ms, latency_p99_ms, refit_s (list), max_refit_s, node_cpu_s, node_peak_mb,
refit_memory_mb (per refit: identifier node, worker at the job's start, worker peak),
identifier_mb_by_quarter, table1_sha256, and with ``--view`` view_received.
"""

import argparse
import hashlib
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import psutil
from rosbags.highlevel import AnyReader

from aero_rig.cli.common import config_path, with_view
from aero_rig.cli.monitor import CampaignMonitor
from rig_runtime.graph import load_graph
from rig_runtime.interface import PITCH_COMMAND, WING_COEFFICIENTS
from rig_runtime.launcher import Launcher
from rig_runtime.messages import stamp_to_ns
from rig_testing.processes import graph_env, join_graph, unique_domain_id


def _sample_processes(
    launcher: Launcher,
    peaks: dict[str, float],
    cpu: dict[str, float],
    trace: dict[str, list[float]] | None = None,
) -> None:
    for proc in launcher.processes:
        try:
            p = psutil.Process(proc.process.pid)
            mem = own = p.memory_info().rss
            times = p.cpu_times()
            total = times.user + times.system
            for child in p.children(recursive=True):  # the identifier's worker process
                mem += child.memory_info().rss
                ct = child.cpu_times()
                total += ct.user + ct.system
        except psutil.Error:
            continue
        peaks[proc.spec.name] = max(peaks.get(proc.spec.name, 0.0), mem / 2**20)
        if trace is not None:
            trace.setdefault(proc.spec.name, []).append(mem / 2**20)
            trace.setdefault(proc.spec.name + " (process only)", []).append(own / 2**20)
        cpu[proc.spec.name] = max(cpu.get(proc.spec.name, 0.0), total)


def throughput(plan: str, run_dir: Path, view: bool = False) -> dict[str, Any]:
    graph = load_graph(config_path("sim.yaml"))
    if view:
        graph = with_view(graph, "save", run_dir / "campaign.rrd")
    overrides: dict[str, dict[str, Any]] = {
        "generator": {"plan": plan, "real_time_factor": 0.0},
        "recorder": {"output": str(run_dir / "bag")},
        "identifier": {"output_dir": str(run_dir), "exit_after_final": True},
    }
    launcher = Launcher(graph, overrides=overrides, log_dir=run_dir / "logs")
    monitor = CampaignMonitor()
    peaks: dict[str, float] = {}
    cpu: dict[str, float] = {}
    trace: dict[str, list[float]] = {}
    t0 = time.monotonic()
    launcher.start()
    t_first = None
    try:
        while launcher.poll() is None:
            monitor.spin(0.25)
            if t_first is None and monitor.k > 0:
                t_first = time.monotonic()
            _sample_processes(launcher, peaks, cpu, trace)
            if time.monotonic() - t0 > 1800:
                raise RuntimeError("graph did not finish within 30 minutes")
    finally:
        monitor.close()
        launcher.stop()
    wall = time.monotonic() - t0
    with AnyReader([run_dir / "bag"]) as reader:
        stamps: dict[str, set[int]] = {PITCH_COMMAND.name: set(), WING_COEFFICIENTS.name: set()}
        conns = [c for c in reader.connections if c.topic in stamps]
        for conn, _, raw in reader.messages(connections=conns):
            msg: Any = reader.deserialize(raw, conn.msgtype)
            stamps[conn.topic].add(stamp_to_ns(msg.header.stamp))
    models = json.loads((run_dir / "models.json").read_text())
    status_refits = []
    refit_memory = []
    log = (run_dir / "logs" / "identifier.log").read_text(errors="replace")
    for line in log.splitlines():
        if "done in" in line and "refit" in line:
            status_refits.append(float(line.split("done in")[1].split("s")[0]))
            memory = re.search(r"resident (\d+) MB at start, peak (\d+) MB; node (\d+) MB", line)
            if memory:  # [node, worker at the job's start, worker peak] in MB
                refit_memory.append([int(memory[3]), int(memory[1]), int(memory[2])])
    experiment_s = monitor.total / monitor.fs
    extra: dict[str, Any] = {}
    if view:  # the view's last count of what it received (ViewNode.log_stats, on its shutdown)
        counts = re.findall(r"received (.*) errors=", (run_dir / "logs" / "view.log").read_text())
        extra["view_received"] = {
            k: int(v) for k, v in (item.split("=") for item in counts[-1].split())
        }
        extra.update(view_figures(run_dir))
    return {
        **extra,
        "wall_s": round(wall, 2),
        "experiment_s": experiment_s,
        "real_time_factor": round(experiment_s / wall, 2),
        "samples": len(stamps[PITCH_COMMAND.name]),
        "samples_lost": len(stamps[PITCH_COMMAND.name] - stamps[WING_COEFFICIENTS.name]),
        "refit_s": status_refits,
        "max_refit_s": max(status_refits) if status_refits else None,
        "node_cpu_s": {k: round(v, 1) for k, v in cpu.items()},
        "node_peak_mb": {k: round(v, 1) for k, v in peaks.items()},
        # Per refit, from the identifier's log: [node resident size after the refit, worker
        # resident size at the job's start (its input included), worker peak during the job].
        "refit_memory_mb": refit_memory,
        # Largest identifier memory (node + refit worker) in each quarter of the run.
        "identifier_mb_by_quarter": [
            round(float(np.max(q)), 1) for q in np.array_split(trace.get("identifier", [0.0]), 4)
        ],
        "identifier_node_only_mb_by_quarter": [
            round(float(np.max(q)), 1)
            for q in np.array_split(trace.get("identifier (process only)", [0.0]), 4)
        ],
        "table1_all_levels": models["table1"]["markdown"],
    }


def latency(seconds: float, run_dir: Path) -> dict[str, Any]:
    from rig_runtime.node import Node

    graph = load_graph(config_path("sim.yaml"))
    keep = {"generator", "sim_actuator", "sim_wing", "lift"}
    graph = type(graph)(graph.name, tuple(n for n in graph.nodes if n.name in keep), graph.source)
    overrides = {"generator": {"plan": "short", "real_time_factor": 1.0}}
    node = Node("bench_latency", argv=[])
    sent: dict[int, int] = {}
    delays: list[float] = []

    def on_command(msg: Any) -> None:
        sent[stamp_to_ns(msg.header.stamp)] = time.perf_counter_ns()

    def on_coefficients(msg: Any) -> None:
        t = sent.pop(stamp_to_ns(msg.header.stamp), None)
        if t is not None:
            delays.append((time.perf_counter_ns() - t) / 1e6)

    warmup = 400  # the first 2 s: processes still loading (numba cache, first messages)

    node.create_subscription(PITCH_COMMAND.type, PITCH_COMMAND.name, on_command, PITCH_COMMAND.qos)
    node.create_subscription(
        WING_COEFFICIENTS.type, WING_COEFFICIENTS.name, on_coefficients, WING_COEFFICIENTS.qos
    )
    launcher = Launcher(graph, overrides=overrides, log_dir=run_dir / "latency_logs")
    launcher.start()
    try:
        node.spin_until(lambda: len(delays) > 0, 60)
        node.spin_until(lambda: launcher.poll() is not None, seconds)
    finally:
        launcher.stop()
        node.close()
    d = np.array(delays[warmup:]) if len(delays) > warmup else np.array([np.nan])
    return {
        "latency_samples": len(d),
        "latency_max_ms": round(float(np.max(d)), 3),
        "latency_p50_ms": round(float(np.percentile(d, 50)), 3),
        "latency_p99_ms": round(float(np.percentile(d, 99)), 3),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--plan", default="short", help="plan for the throughput phase")
    parser.add_argument("--latency-seconds", type=float, default=20.0)
    parser.add_argument("--keep", default=None, help="keep the run directories here")
    parser.add_argument("--view", action="store_true", help="run the Rerun view node beside it")
    parser.add_argument("--campaign", action="store_true", help="the default campaign's split")
    parser.add_argument("--before", default=None, help="with --campaign: a checkout to compare")
    parser.add_argument(
        "--real-time-factor",
        type=float,
        default=0.0,
        help="with --campaign: experiment s per wall s (0: as fast as the graph takes)",
    )
    args = parser.parse_args()
    if args.campaign:
        return compare_campaigns(args)
    print(json.dumps({"rclpy": run_graph(args)}))
    return 0


TABLES = ("table1_all_levels.md", "table1_all_levels.csv", "table1_level1.md",
          "table1_level1.csv", "clustering.md", "data_quality.md")  # fmt: skip
LOG_EPOCH = re.compile(r"^\[\w+\] \[(\d+\.\d+)\]")


def _epoch_of(log: Path, text: str) -> float:
    """The stamp of the first line of a node log that contains ``text``."""
    for line in log.read_text(errors="replace").splitlines():
        match = LOG_EPOCH.match(line)
        if match and text in line:
            return float(match[1])
    raise RuntimeError(f"{log}: no line with {text!r}")


def campaign_split(run_dir: Path, started: float, ended: float) -> dict[str, Any]:
    """Wall time of a finished campaign run, split by the generator's log lines."""
    generator = run_dir / "logs" / "generator.log"
    barrier = _epoch_of(generator, "start barrier passed")
    plan_end = _epoch_of(generator, "plan finished")
    summary = json.loads((run_dir / "campaign.json").read_text())
    return {
        "wall_s": round(ended - started, 1),
        "experiment_s": summary["experiment_s"],
        "real_time_factor": round(summary["experiment_s"] / (ended - started), 2),
        "start_s": round(barrier - started, 1),
        "streaming_s": round(plan_end - barrier, 1),
        "streaming_real_time_factor": round(summary["experiment_s"] / (plan_end - barrier), 2),
        "final_identification_s": round(ended - plan_end, 1),
        "clean": summary["clean"],
    }


VIEW_REPORT = re.compile(
    r"view: of (?P<planned>\d+) plan samples missed (?P<command>\d+) commands, "
    r"(?P<state>\d+) states, (?P<coefficients>\d+) C_l and (?P<taps>\d+) tap samples; "
    r"drew (?P<drawn>\d+) of (?P<frames>\d+) Cp frames"
)


def view_figures(run_dir: Path) -> dict[str, Any]:
    """What the view missed (its report at shutdown, logs/view.log) and the .rrd's rows."""
    from aero_rig.view.readback import entity_rows

    reports = VIEW_REPORT.findall((run_dir / "logs" / "view.log").read_text(errors="replace"))
    if not reports:  # e.g. --before a checkout whose view did not report
        return {"view": None, "rrd_rows": entity_rows(run_dir / "campaign.rrd")}
    planned, command, state, cl, taps, drawn, frames = map(int, reports[-1])
    return {
        "view": {
            "plan_samples": planned,
            "missed_commands": command,
            "missed_states": state,
            "missed_cl": cl,
            "missed_tap_samples": taps,
            "cp_frames_drawn": drawn,
            "cp_frames_planned": frames,
            "cp_frames_missed_percent": round(100.0 * (frames - drawn) / frames, 3),
        },
        "rrd_rows": entity_rows(run_dir / "campaign.rrd"),
    }


def run_campaign(
    run_dir: Path, tree: Path | None, view: bool = False, real_time_factor: float = 0.0
) -> dict[str, Any]:
    """``aero-rig campaign --plan default`` (this checkout, or ``tree``'s code), timed, at
    ``real_time_factor`` (0: as fast as the graph takes); with ``view``, ``--rerun save`` and
    what the view missed."""
    env = dict(os.environ)
    if tree is not None:
        env["PYTHONPATH"] = os.pathsep.join(str(p) for p in sorted((tree / "src").glob("*")))
    cmd = [str(Path(sys.executable).with_name("aero-rig")), "campaign", "--plan", "default"]
    cmd += ["--rerun", "save"] if view else []
    cmd += ["--real-time-factor", str(real_time_factor)]
    started = time.time()
    proc = subprocess.run([*cmd, "--out", str(run_dir), "--quiet"], env=env, text=True,
                          capture_output=True, timeout=3600)  # fmt: skip
    ended = time.time()
    if proc.returncode != 0:
        raise RuntimeError(f"campaign failed ({proc.returncode}): {proc.stderr[-3000:]}")
    figures = campaign_split(run_dir, started, ended)
    return figures | (view_figures(run_dir) if view else {})


def _same_file(a: Path, b: Path) -> bool:
    """Byte-identical files (False when either is missing)."""
    return a.exists() and b.exists() and a.read_bytes() == b.read_bytes()


def compare_campaigns(args: argparse.Namespace) -> int:
    results: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="bench_campaign_") as tmp:
        base = Path(args.keep or tmp)
        runs: list[tuple[str, Path | None]] = []
        if args.before:
            runs.append(("before", Path(args.before).resolve()))
        runs.append(("after", None))
        for name, tree in runs:
            print(f"== {name}: aero-rig campaign --plan default ({tree or 'this checkout'})")
            results[name] = run_campaign(base / name, tree, args.view, args.real_time_factor)
            print(json.dumps(results[name]))
        if args.before:
            results["tables_identical"] = {t: _same_file(base / "before" / t, base / "after" / t)
                                           for t in TABLES}  # fmt: skip
            print(f"tables byte-identical (cmp): {results['tables_identical']}")
    print(json.dumps(results))
    return 0 if all(results.get("tables_identical", {"": True}).values()) else 1


def run_graph(args: argparse.Namespace) -> dict[str, Any]:
    env = graph_env(unique_domain_id())
    join_graph(env)
    with tempfile.TemporaryDirectory(prefix="bench_graph_") as tmp:
        run_dir = Path(args.keep or tmp) / "rclpy"
        figures = throughput(args.plan, run_dir / "run", args.view)
        table = figures.pop("table1_all_levels")
        figures.update(latency(args.latency_seconds, run_dir))
    print(table)
    print(
        f"throughput: {figures['experiment_s']} s of experiment in {figures['wall_s']} s "
        f"= {figures['real_time_factor']}x real time, {figures['samples_lost']} of "
        f"{figures['samples']} samples lost"
    )
    print(f"refits: {figures['refit_s']} s")
    print(f"cpu per node [s]: {figures['node_cpu_s']}")
    if "view_received" in figures:
        print(f"the view received (of {figures['samples']} samples): {figures['view_received']}")
    print(f"peak memory per node [MB]: {figures['node_peak_mb']}")
    print(
        "identifier memory per refit [MB] (node, worker at start, worker peak): "
        f"{figures['refit_memory_mb']}"
    )
    print(
        f"latency /pitch/command -> /wing/coefficients at real time: p50 "
        f"{figures['latency_p50_ms']} ms, p99 {figures['latency_p99_ms']} ms "
        f"({figures['latency_samples']} samples)"
    )
    figures["table1_sha256"] = hashlib.sha256(table.encode()).hexdigest()[:16]
    return figures


if __name__ == "__main__":
    sys.exit(main())
