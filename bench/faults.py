"""Fault-injection benchmark: the short campaign under load and faults, with what each cost.

Runs `aero-rig campaign --plan short` (the simulated process graph on Cyclone DDS) once idle
as the reference, then once per fault:

- ``starved``: two busy processes per core at the stream nodes' priority (nice 5), whole run;
- ``paused``: SIGSTOP/SIGCONT of each stream node in turn for 3 s mid-run;
- ``recorder_late``: the recorder started 5 s after the rest of the graph (rig_runtime Launcher);
- ``lift_killed``: kill -9 of the lift node once realization 0 of level 1 is complete;
- ``never_ready``: the identifier missing from the processes but named in the barrier;
- ``generator_frozen``: the generator stopped for 35 s, longer than the simulated actuator's
  30 s stream timeout, so the actuator runs on in real time (the first wave's corruption).

Per case: exit code, samples lost (plan samples without a message on a stream topic of the
bag), periods and sine records excluded, anomalies, whether Table 1 (all levels) is byte for
byte the idle run's, wall time, and the start barrier's wait.

    .venv/bin/python bench/faults.py [--cases starved,paused,...]

Last line: JSON {case: {...}} with those figures.
"""

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml
from rosbags.highlevel import AnyReader

from aero_rig.verdict import STREAM_TOPICS
from rig_runtime.graph import load_graph, package_share
from rig_runtime.interface import EXPERIMENT_PLAN
from rig_runtime.launcher import Launcher, node_command
from rig_runtime.messages import stamp_to_ns
from rig_runtime.testing import (
    BusyProcesses,
    finish,
    graph_env,
    join_graph,
    node_process,
    pause,
    start_session,
    wait_for,
)

SIM = package_share("aero_rig") / "config" / "sim.yaml"
MEMBERS = ["sim_actuator", "sim_wing", "lift", "identifier", "recorder"]


def _log_has(path: Path, text: str) -> bool:
    return path.exists() and text in path.read_text(errors="replace")


def campaign(
    run: Path, extra: list[str], during: Callable[[subprocess.Popen[str]], None] | None = None
) -> tuple[int, float, str]:
    """One `aero-rig campaign --plan short`; ``during(proc)`` injects the fault."""
    started = time.monotonic()
    proc = start_session(
        [
            *(sys.executable, "-m", "aero_rig.cli", "campaign", "--plan", "short", "--quiet"),
            *("--out", str(run), "--timeout", "900", *extra),
        ],
        graph_env(),
    )
    try:
        if during is not None:
            during(proc)
    finally:
        out, err = finish(proc, 1200)
    return proc.returncode, time.monotonic() - started, out + err


def recorder_late(run: Path) -> tuple[int, float, str]:
    """The graph without its recorder, which is started 5 s later by hand."""
    env = graph_env()
    join_graph(env)
    full = load_graph(SIM)
    graph = type(full)(full.name, tuple(n for n in full.nodes if n.name != "recorder"))
    run.mkdir(parents=True)
    launcher = Launcher(
        graph,
        env=env,
        overrides={
            "generator": {"plan": "short", "real_time_factor": 0.0, "barrier_nodes": MEMBERS},
            "identifier": {"output_dir": str(run), "exit_after_final": True},
        },
        log_dir=run / "logs",
    )
    started = time.monotonic()
    recorder = None
    try:
        launcher.start()
        wait_for(lambda: _log_has(run / "logs" / "generator.log", "plan "), 60)
        time.sleep(5.0)  # the fault: a recorder 5 s late
        with (run / "logs" / "recorder.log").open("wb") as log:
            recorder = subprocess.Popen(
                node_command(full.node("recorder"), {"output": str(run / "bag")}),
                env=env,
                stdout=log,
                stderr=subprocess.STDOUT,
            )
        wait_for(lambda: launcher.poll() is not None, 900)
    finally:
        codes = launcher.stop()
        if recorder is not None:
            recorder.send_signal(signal.SIGINT)
            recorder.wait(timeout=30)
    return max(codes.values(), key=abs), time.monotonic() - started, ""


def after_first_realization(
    run: Path, node: str, fault: Callable[[Any], None]
) -> Callable[[subprocess.Popen[str]], None]:
    """A ``during`` for :func:`campaign`: ``fault(process of node)`` once the identifier has
    the first realization complete."""

    def inject(proc: subprocess.Popen[str]) -> None:
        log = run / "logs" / "identifier.log"
        wait_for(lambda: _log_has(log, "realization 0 complete"), 300)
        target = node_process(proc.pid, node)
        if target is not None:
            fault(target)

    return inject


def measure(run: Path, reference: Path | None) -> dict[str, Any]:
    """Samples lost in the bag, what the identification excluded, Table 1 against idle."""
    figures: dict[str, Any] = {}
    stamps: dict[str, set[int]] = {t: set() for t in STREAM_TOPICS}
    plan: dict[str, Any] | None = None
    try:
        with AnyReader([run / "bag"]) as reader:
            conns = [
                c for c in reader.connections if c.topic in (*STREAM_TOPICS, EXPERIMENT_PLAN.name)
            ]
            for conn, _, raw in reader.messages(connections=conns):
                msg: Any = reader.deserialize(raw, conn.msgtype)
                if conn.topic == EXPERIMENT_PLAN.name:
                    plan = json.loads(msg.data)
                else:
                    stamps[conn.topic].add(stamp_to_ns(msg.header.stamp))
    except Exception as exc:  # a bag cut by the fault: say so
        figures["bag_error"] = f"{type(exc).__name__}: {exc}"
    if plan is not None:
        expected = {
            plan["t0_ns"] + round(k * 1e9 / plan["fs"]) for k in range(plan["total_samples"])
        }
        figures["samples_lost"] = {t: len(expected - stamps[t]) for t in STREAM_TOPICS}
    else:
        figures["samples_lost"] = "no plan in the bag (nothing was streamed)"
    models = run / "models.json"
    if models.exists():
        quality = json.loads(models.read_text()).get("data_quality", {})
        figures["periods_excluded"] = len(quality.get("excluded_periods", []))
        figures["sines_excluded"] = len(quality.get("excluded_sines", []))
        figures["anomalies"] = quality.get("anomalies", [])
        figures["clean"] = quality.get("clean")
    table = run / "table1_all_levels.md"
    if reference is not None and table.exists():
        figures["table1_identical"] = table.read_bytes() == reference.read_bytes()
    else:
        figures["table1_identical"] = None if reference is None else "no table"
    log = run / "logs" / "generator.log"
    if log.exists() and "start barrier passed after " in log.read_text():
        figures["barrier_wait_s"] = float(
            log.read_text().split("start barrier passed after ")[1].split(" s")[0]
        )
    return figures


def main() -> int:
    all_cases = ["starved", "paused", "recorder_late", "lift_killed", "never_ready", "frozen"]
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", default=",".join(all_cases), help="comma-separated cases")
    args = parser.parse_args()
    cases = [c for c in args.cases.split(",") if c]
    root = Path(tempfile.mkdtemp(prefix="bench_faults_"))
    results: dict[str, dict[str, Any]] = {}

    def record(name: str, code: int, wall: float, text: str, reference: Path | None) -> None:
        figures = {"exit_code": code, "wall_s": round(wall, 1), **measure(root / name, reference)}
        lines = [line for line in text.splitlines() if "error" in line.lower()][-2:]
        if lines:
            figures["error_lines"] = lines
        results[name] = figures
        print(f"{name}: {json.dumps(figures)}", flush=True)

    code, wall, text = campaign(root / "idle", [])
    record("idle", code, wall, text, None)
    reference = root / "idle" / "table1_all_levels.md"

    def after_t0(proc: subprocess.Popen[str], name: str) -> None:
        log = root / name / "logs" / "generator.log"
        wait_for(lambda: _log_has(log, "start barrier passed"), 120)

    if "starved" in cases:
        with BusyProcesses(2 * (os.cpu_count() or 2), nice=5):
            record("starved", *campaign(root / "starved", []), reference)
    if "paused" in cases:

        def pause_each(proc: subprocess.Popen[str]) -> None:
            after_t0(proc, "paused")
            for node in ("generator", "sim_actuator", "sim_wing", "lift", "identifier", "recorder"):
                target = node_process(proc.pid, node)
                if target is not None:
                    pause(target, 3.0)

        record("paused", *campaign(root / "paused", [], pause_each), reference)
    if "recorder_late" in cases:
        record("recorder_late", *recorder_late(root / "recorder_late"), reference)
    if "lift_killed" in cases:
        kill_lift = after_first_realization(root / "lift_killed", "lift", lambda p: p.kill())
        record("lift_killed", *campaign(root / "lift_killed", [], kill_lift), reference)
        fit = subprocess.run(
            [
                *(sys.executable, "-m", "aero_rig.cli", "fit", str(root / "lift_killed" / "bag")),
                *("--out", str(root / "lift_killed" / "fit")),
            ],
            env=graph_env(),
            capture_output=True,
            text=True,
            timeout=600,
        )
        results["lift_killed"]["fit_exit_code"] = fit.returncode
        results["lift_killed"]["fit_realizations"] = [
            line.strip() for line in fit.stdout.splitlines() if "realization" in line
        ][1:]
    if "never_ready" in cases:
        graph = yaml.safe_load(SIM.read_text())
        graph["nodes"] = [n for n in graph["nodes"] if n["name"] != "identifier"]
        path = root / "no_identifier.yaml"
        path.write_text(yaml.safe_dump(graph))
        extra = ["--graph", str(path), "-p", "generator.start_timeout_s:=10"]
        extra += ["-p", f"generator.barrier_nodes:=[{', '.join(MEMBERS)}]"]
        record("never_ready", *campaign(root / "never_ready", extra), reference)
    if "frozen" in cases:
        freeze_generator = after_first_realization(
            root / "frozen", "generator", lambda p: pause(p, 35.0)
        )
        record("frozen", *campaign(root / "frozen", [], freeze_generator), reference)
    print(f"run directories: {root}")
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
