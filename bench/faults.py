"""Fault-injection benchmark: the short campaign under load and faults, with what each cost.

Runs `aero-rig campaign --plan short` (the simulated graph of rclpy node processes) once idle
as the reference, then once per fault:

- ``starved``: two busy processes per core at the stream nodes' priority (nice 5), whole run;
- ``paused``: SIGSTOP/SIGCONT of each stream node in turn for 3 s mid-run;
- ``recorder_late``: the recorder started 5 s after the rest of the graph (rig_runtime Launcher);
- ``lift_killed``: kill -9 of the lift node once realization 0 of level 1 is complete;
- ``never_ready``: the identifier missing from the processes but named in the barrier;
- ``frozen``: the generator stopped for 35 s, longer than the simulated actuator's
  30 s stream timeout, so the actuator runs on in real time (the first wave's corruption).

Past the DDS participant lease (issue 21; ``lease`` is
rig_runtime.ros_environment.PARTICIPANT_LEASE_S, Fast DDS's 20 s):

- ``identifier_paused``: the identifier stopped for lease + 5 s right after the start barrier;
- ``sim_actuator_paused_long``, ``sim_wing_paused_long``, ``lift_paused_long``,
  ``generator_paused_long``, ``recorder_paused_long``: that node stopped for lease + 5 s
  mid-run (once the identifier logs its first realization complete); for the recorder,
  ``recorder_gap`` says whether the bag's loss is named (exit 3, each topic that lost samples
  listed) or nothing was lost (a clean run), or else that it was silent;
- ``lift_stopped``, ``generator_stopped``: that node stopped (SIGSTOP) mid-run and never
  resumed (the campaign's own stop sends SIGCONT): the campaign must end at its stall bound
  (lease + 2 status periods without stream progress), naming the stopped node;
  ``fault_to_exit_s`` is the time from the stop to the campaign's exit;
- ``killed_in_final``: kill -9 of the identifier's refit worker during the final
  identification (after the generator's "plan finished" and the identifier's "[final]" refit);
- ``identifier_killed_in_final``: kill -9 of the identifier itself then.

Per case: exit code, samples lost (plan samples without a message on a stream topic of the
bag), periods and sine records excluded, anomalies, whether Table 1 (all levels) is byte for
byte the idle run's, wall time, the start barrier's wait, the final identification recovered
from the bag (campaign.json ``recovered_from_bag``), seconds from the plan's end (the generator's
"plan finished" log stamp) to the campaign's exit, whether the campaign ended by its
``--timeout`` (it must not), and what the fault did.

    .venv/bin/python bench/faults.py [--cases starved,paused,...]
                                     [--timeout S]  # each campaign's --timeout, default 300

Last line: JSON {case: {...}} with those figures; each campaign's output is kept as
``<case>.out`` next to the run directories.
"""

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml
from rosbags.highlevel import AnyReader

from aero_rig.verdict import STREAM_TOPICS
from multisine_gen.plan import ExperimentPlan
from multisine_gen.plan_format import read_plan_message
from rig_runtime.graph import load_graph, package_share
from rig_runtime.interface import EXPERIMENT_PLAN
from rig_runtime.launcher import Launcher, node_command
from rig_runtime.messages import stamp_to_ns, typestore
from rig_runtime.ros_environment import PARTICIPANT_LEASE_S
from rig_testing.processes import (
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
STREAM_NODES = ("sim_actuator", "sim_wing", "lift")
LONG_PAUSE_PAST_LEASE_S = 5.0  # a long pause: the participant lease + this
PLAN_FINISHED = "plan finished"
# a node's log line: "[INFO] [<epoch s>.<fraction>] [<node>]: <message>"
LOG_STAMP = re.compile(r"^\[[A-Z]+\] \[(\d+\.\d+)\]")

# What a fault does to the run's graph, given the campaign's process; a note on what it did.
Fault = Callable[[subprocess.Popen[str]], str | None]


@dataclass
class Run:
    """One campaign (or launcher) run as the benchmark saw it."""

    code: int
    wall: float  # wall seconds from the start to the exit
    text: str  # the campaign's stdout + stderr
    exited_at: float | None = None  # epoch seconds of the exit
    fault: str | None = None  # what the fault did


def _log_has(path: Path, text: str) -> bool:
    return path.exists() and text in path.read_text(errors="replace")


def _log_stamp(path: Path, text: str) -> float | None:
    """The epoch stamp of the first line of a node log holding ``text``."""
    if not path.exists():
        return None
    for line in path.read_text(errors="replace").splitlines():
        if text in line and (match := LOG_STAMP.match(line)):
            return float(match.group(1))
    return None


def _exit_clock(pid: int) -> Callable[[], float | None]:
    """Epoch seconds at which child ``pid`` exits, read after it has (waitid without reaping:
    the process's own wait still reaps it), even while a fault is still being injected."""
    exited: list[float] = []

    def watch() -> None:
        try:
            os.waitid(os.P_PID, pid, os.WEXITED | os.WNOWAIT)
        except ChildProcessError:  # already reaped: the caller's own clock
            return
        exited.append(time.time())

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()

    def when() -> float | None:
        thread.join(timeout=1.0)
        return exited[0] if exited else None

    return when


def campaign(run: Path, extra: list[str], timeout: float, during: Fault | None = None) -> Run:
    """One `aero-rig campaign --plan short`; ``during(proc)`` injects the fault."""
    started = time.monotonic()
    proc = start_session(
        [
            *(sys.executable, "-m", "aero_rig.cli", "campaign", "--plan", "short", "--quiet"),
            *("--out", str(run), "--timeout", f"{timeout:g}", *extra),
        ],
        graph_env(),
    )
    exited_at = _exit_clock(proc.pid)
    note = None
    try:
        if during is not None:
            note = during(proc)
    finally:
        out, err = finish(proc, timeout + 300)
        now = time.time()
    at = exited_at() or now
    return Run(proc.returncode, time.monotonic() - started - (now - at), out + err, at, note)


def recorder_late(run: Path) -> Run:
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
    return Run(max(codes.values(), key=abs), time.monotonic() - started, "", time.time())


def after_log(
    run: Path, log: str, text: str, node: str, fault: Callable[[Any], str | None]
) -> Fault:
    """A ``during`` for :func:`campaign`: ``fault(process of node)`` once ``logs/<log>.log``
    holds ``text`` (bounded wait); says so when the wait or the node is missing."""

    def inject(proc: subprocess.Popen[str]) -> str | None:
        if not wait_for(lambda: _log_has(run / "logs" / f"{log}.log", text), 300):
            return f"not injected: no {text!r} in {log}.log"
        target = node_process(proc.pid, node)
        if target is None:
            return f"not injected: no {node} process"
        return fault(target)

    return inject


def after_first_realization(run: Path, node: str, fault: Callable[[Any], str | None]) -> Fault:
    """``fault(process of node)`` once the identifier has the first realization complete."""
    return after_log(run, "identifier", "realization 0 complete", node, fault)


def after_barrier(run: Path, node: str, fault: Callable[[Any], str | None]) -> Fault:
    """``fault(process of node)`` once the generator has passed its start barrier."""
    return after_log(run, "generator", "start barrier passed", node, fault)


def paused_for(seconds: float) -> Callable[[Any], str | None]:
    """SIGSTOP for ``seconds``, then SIGCONT (the pause is the fault, not a readiness guess)."""

    def fault(target: Any) -> str | None:
        import psutil

        started = time.monotonic()
        try:
            pause(target, seconds)
        except psutil.Error:  # stopped by the campaign while paused
            return f"paused; the process was gone after {time.monotonic() - started:.1f} s"
        return f"paused {seconds:g} s"

    return fault


def stopped_for_good(target: Any) -> str | None:
    """SIGSTOP, never resumed by the bench; stamped so that the exit can be timed from it."""
    target.suspend()
    return f"stopped at {time.time():.3f} (never resumed)"


def killed(target: Any) -> str | None:
    target.kill()
    return f"killed pid {target.pid}"


def kill_in_final(run: Path, node: str) -> Fault:
    """kill -9 of the identifier's refit worker (``node`` "refit_worker") or of ``node`` once the
    generator logged the plan's end and the identifier started its final refit."""
    logs = run / "logs"

    def inject(proc: subprocess.Popen[str]) -> str | None:
        import psutil

        if not wait_for(lambda: _log_has(logs / "generator.log", PLAN_FINISHED), 300):
            return "not injected: the plan did not finish"
        if not wait_for(lambda: _log_has(logs / "identifier.log", "[final]"), 300):
            return "not injected: no final refit in identifier.log"
        identifier = node_process(proc.pid, "identifier")
        if identifier is None:
            return "not injected: no identifier process"
        target = identifier
        if node == "refit_worker":
            workers = []
            for child in identifier.children(recursive=True):
                try:
                    if any("spawn_main" in part for part in child.cmdline()):
                        workers.append(child)
                except psutil.Error:
                    continue
            if not workers:
                return "not injected: no refit worker under the identifier"
            target = workers[0]
        done = _log_has(logs / "identifier.log", "final Table 1")
        target.kill()
        return f"killed {node} (pid {target.pid}); final refit already done then: {done}"

    return inject


def measure(run: Path, reference: Path | None) -> dict[str, Any]:
    """Samples lost in the bag, what the identification excluded, Table 1 against idle."""
    figures: dict[str, Any] = {}
    stamps: dict[str, set[int]] = {t: set() for t in STREAM_TOPICS}
    plan: tuple[ExperimentPlan, int] | None = None  # the last plan message's, and its t0_ns
    try:
        with AnyReader([run / "bag"], default_typestore=typestore()) as reader:
            conns = [
                c for c in reader.connections if c.topic in (*STREAM_TOPICS, EXPERIMENT_PLAN.name)
            ]
            for conn, _, raw in reader.messages(connections=conns):
                msg: Any = reader.deserialize(raw, conn.msgtype)
                if conn.topic == EXPERIMENT_PLAN.name:
                    plan = read_plan_message(msg)
                else:
                    stamps[conn.topic].add(stamp_to_ns(msg.header.stamp))
    except Exception as exc:  # a bag cut by the fault: say so
        figures["bag_error"] = f"{type(exc).__name__}: {exc}"
    if plan is not None:
        executed, t0_ns = plan
        expected = {t0_ns + round(k * 1e9 / executed.fs) for k in range(executed.total_samples)}
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
    summary = run / "campaign.json"
    if summary.exists():
        recovered = json.loads(summary.read_text()).get("recovered_from_bag")
        if recovered is not None:
            recovered = {k: v for k, v in recovered.items() if k != "from"}
        figures["recovered"] = recovered
    return figures


def recorder_gap(figures: dict[str, Any], text: str) -> str:
    """Whether a run's bag loss is named: exit 3 with each topic that lost samples listed among
    the campaign's problems ("  - ..."), or nothing lost and a clean exit; else silent."""
    lost = figures.get("samples_lost")
    if not isinstance(lost, dict):
        return f"no bag to check ({lost}); exit {figures['exit_code']}"
    lossy = [t for t, n in lost.items() if n]
    if not lossy:
        return "nothing lost" + (
            "" if figures["exit_code"] == 0 else f", but exit {figures['exit_code']}"
        )
    listed = [line for line in text.splitlines() if line.startswith("  - ")]
    unnamed = [t for t in lossy if not any(t in line for line in listed)]
    if figures["exit_code"] == 3 and not unnamed:
        return "named: exit 3, " + "; ".join(x.strip("- ") for x in listed if "bag" in x)
    return f"SILENT: samples lost on {lossy}, exit {figures['exit_code']}, not listed: {unnamed}"


def main() -> int:
    long_cases = [f"{n}_paused_long" for n in (*STREAM_NODES, "generator", "recorder")]
    stopped_cases = ["lift_stopped", "generator_stopped"]
    all_cases = [
        *("starved", "paused", "recorder_late", "lift_killed", "never_ready", "frozen"),
        *("identifier_paused", *long_cases, *stopped_cases),
        *("killed_in_final", "identifier_killed_in_final"),
    ]
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", default=",".join(all_cases), help="comma-separated cases")
    parser.add_argument(
        "--timeout", type=float, default=300.0, help="each campaign's --timeout [s]"
    )
    args = parser.parse_args()
    cases = [c for c in args.cases.split(",") if c]
    unknown = sorted(set(cases) - set(all_cases))
    if unknown:
        parser.error(f"unknown case(s) {unknown}; known: {', '.join(all_cases)}")
    long_pause = PARTICIPANT_LEASE_S + LONG_PAUSE_PAST_LEASE_S
    root = Path(tempfile.mkdtemp(prefix="bench_faults_"))
    print(
        f"rclpy: participant lease {PARTICIPANT_LEASE_S:g} s, long pauses "
        f"{long_pause:g} s, campaign timeout {args.timeout:g} s; {os.cpu_count()} cores",
        flush=True,
    )
    results: dict[str, dict[str, Any]] = {}

    def record(name: str, run: Run, reference: Path | None) -> None:
        (root / f"{name}.out").write_text(run.text)  # the campaign's own output, for evidence
        figures: dict[str, Any] = {"exit_code": run.code, "wall_s": round(run.wall, 1)}
        figures |= measure(root / name, reference)
        plan_end = _log_stamp(root / name / "logs" / "generator.log", PLAN_FINISHED)
        if plan_end is not None and run.exited_at is not None:
            figures["plan_end_to_exit_s"] = round(run.exited_at - plan_end, 1)
        else:
            figures["plan_end_to_exit_s"] = None  # the plan never finished
        figures["timed_out"] = "timeout after" in run.text
        if run.fault and (match := re.match(r"stopped at (\d+\.\d+)", run.fault)):
            if run.exited_at is not None:
                figures["fault_to_exit_s"] = round(run.exited_at - float(match.group(1)), 1)
            figures["stall_named"] = "stalled" in run.text and "stopped (SIGSTOP" in run.text
        if run.fault is not None:
            figures["fault"] = run.fault
        if name == "recorder_paused_long":
            figures["recorder_gap"] = recorder_gap(figures, run.text)
        lines = [
            line
            for line in run.text.splitlines()
            if "error" in line.lower() and not line.startswith("|")  # not Table 1's header
        ][-2:]
        if lines:
            figures["error_lines"] = lines
        results[name] = figures
        print(f"{name}: {json.dumps(figures)}", flush=True)

    def run_case(name: str, during: Fault | None = None, extra: list[str] | None = None) -> None:
        record(name, campaign(root / name, extra or [], args.timeout, during), reference)

    record("idle", campaign(root / "idle", [], args.timeout), None)
    reference = root / "idle" / "table1_all_levels.md"

    if "starved" in cases:
        with BusyProcesses(2 * (os.cpu_count() or 2), nice=5):
            run_case("starved")
    if "paused" in cases:

        def pause_each(proc: subprocess.Popen[str]) -> str | None:
            log = root / "paused" / "logs" / "generator.log"
            wait_for(lambda: _log_has(log, "start barrier passed"), 120)
            done = []
            for node in ("generator", "sim_actuator", "sim_wing", "lift", "identifier", "recorder"):
                target = node_process(proc.pid, node)
                if target is not None:
                    pause(target, 3.0)
                    done.append(node)
            return f"paused 3 s each: {', '.join(done)}"

        run_case("paused", pause_each)
    if "recorder_late" in cases:
        record("recorder_late", recorder_late(root / "recorder_late"), reference)
    if "lift_killed" in cases:
        run_case("lift_killed", after_first_realization(root / "lift_killed", "lift", killed))
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
        run_case("never_ready", extra=extra)
    if "frozen" in cases:
        run_case("frozen", after_first_realization(root / "frozen", "generator", paused_for(35.0)))
    if "identifier_paused" in cases:
        name = "identifier_paused"
        run_case(name, after_barrier(root / name, "identifier", paused_for(long_pause)))
    for name in long_cases:
        if name in cases:
            node = name.removesuffix("_paused_long")
            run_case(name, after_first_realization(root / name, node, paused_for(long_pause)))
    for name in stopped_cases:
        if name in cases:
            node = name.removesuffix("_stopped")
            run_case(name, after_first_realization(root / name, node, stopped_for_good))
    if "killed_in_final" in cases:
        run_case("killed_in_final", kill_in_final(root / "killed_in_final", "refit_worker"))
    if "identifier_killed_in_final" in cases:
        name = "identifier_killed_in_final"
        run_case(name, kill_in_final(root / name, "identifier"))
    print(f"run directories: {root}")
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
