"""``aero-rig campaign``: the simulated campaign end to end.

Launches the simulated graph (generator, simulated actuator, simulated wing, lift, identifier,
recorder, optionally the Rerun view) as processes, runs the plan to its end, waits for the
final identification, stops everything and prints Table 1 and the run directory (bag, models,
report, .rrd). A run that lost or excluded data lists what on its last lines and exits with
code 3 unless ``--allow-excluded``.
"""

import argparse
import json
import os
import shlex
import signal
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rig_runtime import ros_environment
from rig_runtime.flow import FlowWatch
from rig_runtime.graph import GraphError, load_graph, yaml_scalar
from rig_runtime.launcher import Launcher, parse_overrides
from rig_runtime.signals import StopSignals

from ..recovery import recover_from_bag, recover_from_whole_bag, samples_missed
from ..verdict import run_problems
from .common import (
    EXIT_FAILED,
    EXIT_NOT_CLEAN,
    EXIT_OK,
    EXIT_USAGE,
    VIEW_MODES,
    add_override_option,
    checked_ros_environment,
    config_path,
    merge_overrides,
    new_run_dir,
    with_view,
)
from .monitor import CampaignMonitor
from .progress import Progress

MAX_LISTED_PROBLEMS = 40  # more are in the run's data_quality.md


@dataclass
class Outcome:
    """How the launch-and-monitor loop ended."""

    reason: str | None  # what ended it: the launcher's poll, a timeout, "interrupted"
    codes: dict[str, int]  # exit code per node
    wall: float  # wall seconds from start to stop
    total: int  # plan samples (0: the plan was never seen)
    fs: float  # the plan's sample rate [Hz]
    stalled: str | None = None  # the identifier or the stream stalled (liveness.py)
    plan_ended: bool = False  # the generator said the plan ended (plan_end on the segments)
    flow_events: list[dict[str, Any]] = field(default_factory=list)  # rig_runtime.flow
    # every node's last flow report when the run stalled (FlowWatch.graph_state)
    flow_at_stall: dict[str, Any] | None = None


def add_parser(subparsers: Any) -> None:
    p = subparsers.add_parser("campaign", help="run the simulated campaign end to end")
    p.add_argument("--plan", default="default", help="default | short | plan JSON file")
    p.add_argument("--seed", type=int, default=0, help="plan seed (phases, detection lines)")
    p.add_argument(
        "--real-time-factor",
        type=float,
        default=0.0,
        help="experiment s per wall s; 0 = as fast as the graph takes (default)",
    )
    p.add_argument("--out", default=None, help="run directory (default runs/<date-time>)")
    p.add_argument("--rerun", choices=VIEW_MODES, default="off", help="live Rerun view")
    p.add_argument("--graph", default=None, help="graph YAML (default aero_rig config/sim.yaml)")
    p.add_argument(
        "--host",
        dest="hosts",
        action="append",
        default=None,
        metavar="NAME",
        help="start only the nodes the graph places on host NAME (repeatable); the other hosts "
        "run `rig-launch GRAPH --host OTHER` (docs/ros_machine.md §6)",
    )
    p.add_argument("--timeout", type=float, default=0.0, help="give up after S wall seconds")
    p.add_argument(
        "--quiet",
        action="store_true",
        help="no progress (shown as a bar on a terminal, else as a line per state or 30 s)",
    )
    p.add_argument(
        "--adaptive",
        action="store_true",
        help="let the identifier end realizations and levels that converged and add "
        "realizations where they did not (identifier and generator parameter adaptive; "
        "docs/design.md §7.9)",
    )
    p.add_argument(
        "--allow-excluded",
        action="store_true",
        help="exit 0 even if data were lost or excluded (they are still listed)",
    )
    add_override_option(p)
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    checked_ros_environment()
    user_overrides = parse_overrides(args.overrides)
    graph = load_graph(Path(args.graph) if args.graph else config_path("sim.yaml"))
    run_dir = new_run_dir(args.out)
    rrd = run_dir / "campaign.rrd" if args.rerun == "save" else None
    graph = with_view(graph, args.rerun, rrd)
    overrides = merge_overrides(campaign_overrides(args, run_dir), user_overrides)
    if not args.hosts:  # a simulated campaign on one machine stays on it, unless a range is set
        ros_environment.localhost_by_default(os.environ)
    print(f"aero-rig: campaign '{args.plan}' -> {run_dir}", file=sys.stderr)
    try:
        launcher = Launcher(graph, overrides=overrides, log_dir=run_dir / "logs", hosts=args.hosts)
        check_campaign_host(launcher)
        launcher.check()  # the plan and every parameter, before any node starts
    except (KeyError, GraphError) as exc:
        print(f"aero-rig: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if args.real_time_factor == 0:  # as fast as the graph takes: throughput, not latency
        fast = ros_environment.asynchronous_publication()
        if fast:
            launcher.env.update(fast)
            print(
                "aero-rig: Fast DDS publishes asynchronously "
                f"({ros_environment.PUBLICATION_MODE_ENV}; set it to SYNCHRONOUS to keep "
                "rmw_fastrtps's default)",
                file=sys.stderr,
            )
    if launcher.remote_nodes:
        print(other_hosts_note(launcher), file=sys.stderr)
    outcome = launch_and_monitor(launcher, timeout=args.timeout, quiet=args.quiet)
    recovered = None
    if outcome.stalled and not launcher.failure:
        recovered = recover_from_bag(run_dir, launcher, outcome.stalled, say)
        if recovered is None:
            launcher.failure = outcome.stalled
    elif launcher.failed_node == "identifier" and outcome.plan_ended:
        # The identifier died after the plan's end (in its final identification): the graph
        # was stopped, and the recorder closed a bag that holds the whole plan, or says what
        # it lacks (then the failure stands).
        failure = launcher.failure or ""
        recovered = recover_from_whole_bag(run_dir, launcher, outcome.total, failure, say)
        if recovered is not None:
            launcher.failure = None
    elif not launcher.failure and (missed := samples_missed(run_dir)):
        # The identifier finished without samples the recorder may hold (it was paused past
        # the DDS lease, which dropped it as a reader): the bag decides.
        recovered = recover_from_whole_bag(run_dir, launcher, outcome.total, missed, say)
    if launcher.failure:
        print(f"aero-rig: campaign failed: {launcher.failure}", file=sys.stderr)
        print(
            f"aero-rig: node logs in {run_dir / 'logs'}; the bag so far: {run_dir / 'bag'}",
            file=sys.stderr,
        )
        return EXIT_FAILED
    return summarise(
        run_dir,
        outcome,
        allow_excluded=args.allow_excluded,
        recovered=recovered,
        publication=launcher.env.get(ros_environment.PUBLICATION_MODE_ENV, "SYNCHRONOUS"),
    )


def say(text: str) -> None:
    """One line for the user on stderr, prefixed as the verb's other lines."""
    print(f"aero-rig: {text}", file=sys.stderr)


def check_campaign_host(launcher: Launcher) -> None:
    """GraphError unless this machine starts the nodes whose outputs the campaign reads: the
    node that ends the graph (the identifier), the recorder (the bag) and the view."""
    needed = [
        n.name
        for n in launcher.remote_nodes
        if n.stops_graph or (n.package, n.executable) in (("rig_runtime", "recorder"),
                                                         ("aero_rig", "view"))
    ]  # fmt: skip
    if needed:
        hosts = sorted({n.host for n in launcher.remote_nodes if n.name in needed})
        raise GraphError(
            f"aero-rig campaign reads the outputs of {', '.join(needed)}: run it on their host "
            f"(--host {' --host '.join(hosts)}), and `rig-launch` on the others"
        )


def other_hosts_note(launcher: Launcher) -> str:
    """What this machine starts, and the command each other host runs for its half (with the
    campaign's overrides of the nodes there: the plan for the generator)."""
    graph = launcher.graph.source or "GRAPH.yaml"
    lines = [
        f"aero-rig: this machine starts {', '.join(n.name for n in launcher.local_nodes)}; the "
        "start barrier waits for the other hosts' nodes, started there with:"
    ]
    hosts: dict[str, list[str]] = {}
    for spec in launcher.remote_nodes:
        hosts.setdefault(spec.host, []).append(spec.name)
    for host, names in hosts.items():
        sets = [
            f"-p {shlex.quote(f'{name}.{key}:={yaml_scalar(value)}')}"
            for name in names
            for key, value in launcher.overrides.get(name, {}).items()
            if key != "barrier_nodes"
        ]
        mode = launcher.env.get(ros_environment.PUBLICATION_MODE_ENV)
        env = f"{ros_environment.PUBLICATION_MODE_ENV}={mode} " if mode else ""
        command = f"{env}rig-launch {graph} --host {host} {' '.join(sets)}".rstrip()
        lines.append(f"  {host} ({', '.join(names)}): {command}")
    return "\n".join(lines)


def campaign_overrides(args: argparse.Namespace, run_dir: Path) -> dict[str, dict[str, Any]]:
    """The parameters the campaign sets: the plan for the generator, outputs into ``run_dir``."""
    plan = args.plan
    if plan not in ("default", "short"):
        plan = str(Path(plan).resolve())
    return {
        "generator": {
            "plan": plan,
            "seed": args.seed,
            "real_time_factor": args.real_time_factor,
            # It serves the identifier's requests only in an adaptive run (generator_node.py).
            **({"adaptive": True} if args.adaptive else {}),
        },
        "recorder": {"output": str(run_dir / "bag")},
        "identifier": {
            "output_dir": str(run_dir),
            "exit_after_final": True,
            **({"adaptive": True} if args.adaptive else {}),
        },
    }


def launch_and_monitor(launcher: Launcher, *, timeout: float, quiet: bool) -> Outcome:
    """Start the graph, follow it until it ends, fails, stalls, times out or is stopped; stop
    it.

    SIGTERM and SIGHUP stop the graph as Ctrl-C does; ``launcher.failure`` says why a run did
    not end by itself (a node's exit, the timeout, the signal); ``Outcome.stalled`` that the
    identifier made no progress within the liveness bound after the plan's end (liveness.py).
    """
    # Remote nodes that report their flow (every rig_runtime node does; a `barrier: none`
    # process may not), and the host of the stream's lead (the generator).
    remote = {n.fq_name: n.host for n in launcher.remote_nodes if n.barrier != "none"}
    local = [n.fq_name for n in launcher.local_nodes if n.barrier != "none"]
    lead_host = next((n.host for n in launcher.remote_nodes if n.barrier == "lead"), None)
    monitor = CampaignMonitor(remote, local)
    stalled: str | None = None
    flow_at_stall: dict[str, Any] | None = None
    started, started_epoch = time.monotonic(), time.time()
    # kill, a job scheduler's time limit or a closed terminal: stop the graph as Ctrl-C does
    # (the nodes are in their own process groups and would otherwise run on). Only noted: the
    # loop below sees it within one spin (an exception raised from a handler could surface
    # anywhere, also outside the try below: CI once saw the campaign die of an uncaught
    # KeyboardInterrupt, exit -2, on SIGTERM).
    stopped_by = StopSignals(signal.SIGTERM, signal.SIGHUP).install()
    launcher.start()
    reason: str | None = None
    checked, stopped = 0.0, {}
    progress = Progress(quiet=quiet)
    try:
        while reason is None and not stopped_by:
            monitor.spin(0.2)
            progress.update(monitor.k, monitor.total, monitor.state)
            reason = launcher.poll()
            now = time.monotonic()
            if now - checked >= 1.0:  # the processes' states: once a second (psutil)
                checked, stopped = now, launcher.stopped(now)
            note = monitor.liveness.silent_mid_run(now, stopped)
            if note:
                progress.write(f"aero-rig: warning: {note}")
            for event in monitor.flow.check(now):
                warning = "warning: " if event.kind in ("stuck", "partition") else ""
                progress.write(f"aero-rig: {warning}{event.text}")
            cut = {h: t for h, t in monitor.flow.partitioned().items() if h == lead_host}
            monitor.liveness.cut_off = cut_off_note(cut, now)
            if reason is None:
                stalled = monitor.liveness.check(now, stopped)
                if stalled:
                    stalled += stall_flow_note(monitor.flow, now)
                    flow_at_stall = monitor.flow.graph_state(now)
                reason = stalled
            if timeout and time.monotonic() - started > timeout:
                reason = f"timeout after {timeout:g} s"
                launcher.failure = reason
    except KeyboardInterrupt:
        reason = "interrupted"
        launcher.failure = "interrupted by the user"
    finally:
        sigint = signal.signal(signal.SIGINT, signal.SIG_IGN)
        stopped_by.ignore()  # the graph is being stopped (bounded): let that finish
        progress.close()
        monitor.close()
        codes = launcher.stop()
        stopped_by.restore()
        signal.signal(signal.SIGINT, sigint)
    if stopped_by:  # SIGTERM or SIGHUP, also one that came as the run ended by itself
        reason = "interrupted"
        launcher.failure = f"stopped by {stopped_by.received[0]}"
    return Outcome(
        reason,
        codes,
        time.monotonic() - started,
        monitor.total,
        monitor.fs,
        stalled,
        plan_ended=monitor.liveness.plan_end_at is not None,
        flow_events=[
            {
                **e.to_dict(),
                "at_s": round(e.at - started, 3),  # from the campaign's start
                "epoch_s": round(started_epoch + e.at - started, 3),
            }
            for e in monitor.flow.events
        ],
        flow_at_stall=flow_at_stall,
    )


def stall_flow_note(flow: FlowWatch, now: float) -> str:
    """What the flow reports say at a stall: the stuck readers, and the nodes not heard (a
    stopped, starved or hung process, or this machine no longer receiving); '' when every
    node reports and no reader is stuck."""
    note = ""
    if stuck := flow.stuck_readers():
        note += "; stuck reader(s): " + ", ".join(f"{topic} at {node}" for node, topic in stuck)
    if silent := flow.silent(now):
        note += "; no flow report from " + ", ".join(
            f"{node} ({'never' if ago is None else f'for {ago:.0f} s'})"
            for node, ago in silent.items()
        )
    return note


def cut_off_note(partitioned: dict[str, float], now: float) -> str:
    """``host 'rig' for 21 s`` for the hosts cut off now (rig_runtime.flow), else ''."""
    return ", ".join(f"host {h!r} for {now - since:.0f} s" for h, since in partitioned.items())


def summarise(
    run_dir: Path,
    outcome: Outcome,
    *,
    allow_excluded: bool,
    recovered: dict[str, Any] | None = None,
    publication: str = "SYNCHRONOUS",
) -> int:
    """Judge a finished run, write campaign.json, print the results; the exit code.
    ``publication``: rmw_fastrtps's publication mode of the nodes."""
    bad = {n: c for n, c in outcome.codes.items() if c not in (0, -2, 130)}
    if not (run_dir / "table1_all_levels.md").exists():
        print(
            f"aero-rig: the identifier produced no report ({outcome.reason}); "
            f"exit codes {outcome.codes}",
            file=sys.stderr,
        )
        return EXIT_FAILED
    problems = run_problems(run_dir, outcome.total)
    # seconds from the plan's own sample rate (/experiment/plan), never an assumed one
    experiment_s = None  # a plan stopped short (a stall) has no real-time factor
    if outcome.total and outcome.fs and outcome.plan_ended:
        experiment_s = outcome.total / outcome.fs
    summary = {
        "wall_s": round(outcome.wall, 1),
        "middleware": "rclpy",
        "fastdds_publication": publication,
        "experiment_s": round(experiment_s, 1) if experiment_s else None,
        "real_time_factor": round(experiment_s / outcome.wall, 1) if experiment_s else None,
        "exit_codes": outcome.codes,
        "clean": not problems,
        "problems": problems,
        "recovered_from_bag": recovered,
        # stuck readers and partitions, at seconds from the campaign's start (rig_runtime.flow)
        "flow_events": outcome.flow_events,
        # a stall: what each node last reported, per endpoint (rig_runtime.flow)
        "flow_at_stall": outcome.flow_at_stall,
    }
    (run_dir / "campaign.json").write_text(json.dumps(summary, indent=1))
    print_results(run_dir, summary, bad)
    if recovered is not None:
        print(
            f"final identification recovered from the bag ({recovered['samples_read']} samples "
            f"read from {recovered['from']}) after: {recovered['reason']}"
        )
    if problems:
        print_problems(run_dir, problems)
        if not allow_excluded:
            print(
                "aero-rig: the campaign lost or excluded data (above); exit code 3. Pass "
                "--allow-excluded to accept such a run.",
                file=sys.stderr,
            )
            return EXIT_NOT_CLEAN
    else:
        print("data clean: every plan sample arrived and was recorded once, no anomaly")
    return EXIT_OK


def print_results(run_dir: Path, summary: dict[str, Any], bad: dict[str, int]) -> None:
    """Table 1 (all levels, level 1, what the clustering changed), times, the run directory."""
    print("\nTable 1, trained on all levels (estimation: one realization per level):")
    print((run_dir / "table1_all_levels.md").read_text())
    level1 = run_dir / "table1_level1.md"
    if level1.exists():
        print("\nTable 1, trained on level 1 only (the paper's variant):")
        print(level1.read_text())
    ratios = run_dir / "table1_floor_ratios.md"
    if ratios.exists():
        print("\nTable 1 divided by each sine's noise floor (1: as good as the data allow):")
        print(ratios.read_text())
    clustering = run_dir / "clustering.md"
    if clustering.exists():
        print("\nWhat the period clustering changed (clustering.md, table1_no_clustering.md):")
        print("\n".join(x for x in clustering.read_text().splitlines() if x.startswith("|")))
    for line in experiment_lines(run_dir):
        print(line)
    if summary["experiment_s"]:
        print(
            f"\nwall time {summary['wall_s']} s for {summary['experiment_s']} s of experiment "
            f"({summary['real_time_factor']}x real time)"
        )
    else:
        print(f"\nwall time {summary['wall_s']} s; the plan did not run to its end")
    print(f"run directory: {run_dir}  (bag/, models.json, table1_*.md|csv, *.png, logs/)")
    if bad:
        print(f"aero-rig: warning: nodes stopped uncleanly: {bad}", file=sys.stderr)


def experiment_lines(run_dir: Path) -> list[str]:
    """Multisine time per level, planned against executed (models.json ``experiment``), when
    the run revised its plan (an adaptive run); nothing for a run that played it as planned."""
    try:
        account = json.loads((run_dir / "models.json").read_text()).get("experiment") or {}
    except (OSError, ValueError):
        return []
    if not account.get("revision") and not account.get("decisions"):
        return []
    lines = [
        f"\nadaptive run: multisine time {account['multisine_executed_s']:.0f} s of "
        f"{account['multisine_planned_s']:.0f} s planned "
        f"({100 * account['multisine_fraction']:.0f} %), plan revision {account['revision']}:"
    ]
    for name, level in account["levels"].items():
        lines.append(
            f"  {name}: {level['executed_s']:.0f} s of {level['planned_s']:.0f} s, measured "
            f"periods {level['executed_periods']} (planned {level['planned_periods']})"
        )
    for decision in account.get("decisions", []):
        if decision.get("event") == "refused":
            lines.append(f"  refused {decision.get('request')}: {decision.get('why')}")
        elif decision.get("change"):
            lines.append(f"  {decision['change']} ({decision.get('reason')})")
    return lines


def print_problems(run_dir: Path, problems: list[str]) -> None:
    """What the run lost or excluded, the first MAX_LISTED_PROBLEMS of it."""
    print(f"\nDATA NOT CLEAN: {len(problems)} problem(s); Table 1 uses only what was left:")
    for line in problems[:MAX_LISTED_PROBLEMS]:
        print(f"  - {line}")
    if len(problems) > MAX_LISTED_PROBLEMS:
        more = len(problems) - MAX_LISTED_PROBLEMS
        print(f"  - … {more} more in {run_dir / 'data_quality.md'}")
