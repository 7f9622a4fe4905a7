"""``aero-rig``: run the pitching-wing campaign, live graphs, offline fits and views.

    aero-rig campaign [--plan default|short|FILE] [--real-time-factor X] [--out DIR]
                      [--rerun spawn|save|serve|off] [--seed N] [--allow-excluded]
    aero-rig run sim|rig [--graph FILE] [--duration S]
    aero-rig fit BAG [--out DIR]
    aero-rig view BAG|live [--save FILE.rrd]

``campaign`` launches the simulated graph (generator, simulated actuator, simulated wing, lift,
identifier, recorder, optionally the Rerun view) as processes on the Cyclone DDS backend, runs
the plan to its end, waits for the final identification, stops everything and prints Table 1
and the run directory (bag, models, report, .rrd). A run that lost or excluded data (missing or
duplicated samples, anomalies such as a free-running actuator, excluded periods or sine records,
a bag short of samples) lists what on its last lines and exits with code 3, unless
``--allow-excluded`` is given.
"""

import argparse
import json
import os
import signal
import sys
import time
from dataclasses import replace
from datetime import datetime
from pathlib import Path
from typing import Any

from aero_identification.quality import data_quality_lines
from rig_runtime.graph import GraphError, GraphSpec, load_graph, package_share
from rig_runtime.interface import EXPERIMENT_PLAN, EXPERIMENT_SEGMENT, IDENTIFICATION_STATUS
from rig_runtime.launcher import Launcher, parse_overrides

from .verdict import run_problems

EXIT_NOT_CLEAN = 3  # the campaign finished but lost or excluded data
VIEW_MODES = ("spawn", "save", "serve", "off")  # "off": no view node (the node calls it "none")


def _config(name: str) -> Path:
    return package_share("aero_rig") / "config" / name


def _with_view(graph: GraphSpec, mode: str, rrd: Path | None) -> GraphSpec:
    if mode == "off":
        return graph
    view = load_graph(_config("live_view.yaml")).nodes[0]
    overrides = {"mode": mode}
    if rrd is not None:
        overrides["rrd_path"] = str(rrd)
    view = replace(
        view, parameter_overrides={**view.parameter_overrides, **overrides}, stops_graph=False
    )
    return GraphSpec(graph.name, (*graph.nodes, view), graph.source)


def _run_dir(out: str | None) -> Path:
    if out:
        path = Path(out)
    else:
        path = Path("runs") / datetime.now().strftime("%Y%m%d-%H%M%S")
    if path.exists() and any(path.iterdir()):
        raise SystemExit(f"aero-rig: run directory {path} exists and is not empty; use --out NEW")
    path.mkdir(parents=True, exist_ok=True)
    return path.resolve()


class CampaignMonitor:
    """In-process observer: progress from segment events, end from the identifier's status."""

    def __init__(self) -> None:
        from rig_runtime.node import Node

        self.node = Node("aero_rig_campaign", argv=[], backend="dds")
        self.total = 0
        self.k = 0
        self.state = ""
        self.model: dict[str, Any] | None = None
        self.node.create_subscription(
            EXPERIMENT_PLAN.type, EXPERIMENT_PLAN.name, self._plan, EXPERIMENT_PLAN.qos
        )
        self.node.create_subscription(
            EXPERIMENT_SEGMENT.type, EXPERIMENT_SEGMENT.name, self._segment, EXPERIMENT_SEGMENT.qos
        )
        self.node.create_subscription(
            IDENTIFICATION_STATUS.type,
            IDENTIFICATION_STATUS.name,
            self._status,
            IDENTIFICATION_STATUS.qos,
        )

    def _plan(self, msg: Any) -> None:
        self.total = int(json.loads(msg.data)["total_samples"])

    def _segment(self, msg: Any) -> None:
        event = json.loads(msg.data)
        if event.get("event") == "end":
            self.k = int(event["start_k"]) + int(event["length"])
        elif event.get("event") == "plan_end":
            self.k = self.total

    def _status(self, msg: Any) -> None:
        for status in msg.status:
            for kv in status.values:
                if kv.key == "state":
                    self.state = kv.value

    def spin(self, seconds: float) -> None:
        self.node.spin_until(lambda: False, seconds)

    def close(self) -> None:
        self.node.close()


def cmd_campaign(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    user_overrides = parse_overrides(args.overrides)
    graph = load_graph(Path(args.graph) if args.graph else _config("sim.yaml"))
    run_dir = _run_dir(args.out)
    rrd = run_dir / "campaign.rrd" if args.rerun == "save" else None
    graph = _with_view(graph, args.rerun, rrd)
    plan = args.plan
    if plan not in ("default", "short"):
        plan = str(Path(plan).resolve())
    overrides = _merge(
        {
            "generator": {
                "plan": plan,
                "seed": args.seed,
                "real_time_factor": args.real_time_factor,
            },
            "recorder": {"output": str(run_dir / "bag")},
            "identifier": {"output_dir": str(run_dir), "exit_after_final": True},
        },
        user_overrides,
    )
    env = {"RIG_RUNTIME_BACKEND": "dds"}
    os.environ.update(env)
    print(f"aero-rig: campaign '{args.plan}' -> {run_dir}", file=sys.stderr)
    launcher = Launcher(graph, env=env, overrides=overrides, log_dir=run_dir / "logs")
    monitor = CampaignMonitor()
    started = time.monotonic()
    stopped_by: list[str] = []

    def _on_signal(signum: int, _frame: Any) -> None:
        # kill, a job scheduler's time limit or a closed terminal: stop the graph as Ctrl-C does
        # (the nodes are in their own process groups and would otherwise run on).
        stopped_by.append(signal.Signals(signum).name)
        raise KeyboardInterrupt

    previous = {s: signal.signal(s, _on_signal) for s in (signal.SIGTERM, signal.SIGHUP)}
    launcher.start()
    reason: str | None = None
    progress = tqdm(total=1, unit="sample", unit_scale=True, desc="experiment", disable=args.quiet)
    try:
        while reason is None:
            monitor.spin(0.2)
            if monitor.total and progress.total != monitor.total:
                progress.total = monitor.total
            progress.n = monitor.k
            progress.set_postfix_str(monitor.state or "starting")
            progress.refresh()
            reason = launcher.poll()
            if args.timeout and time.monotonic() - started > args.timeout:
                reason = f"timeout after {args.timeout:g} s"
                launcher.failure = reason
    except KeyboardInterrupt:
        reason = "interrupted"
        launcher.failure = (
            f"stopped by {stopped_by[0]}" if stopped_by else "interrupted by the user"
        )
    finally:
        previous[signal.SIGINT] = signal.getsignal(signal.SIGINT)
        for sig in previous:  # the graph is being stopped (bounded): let that finish
            signal.signal(sig, signal.SIG_IGN)
        progress.close()
        monitor.close()
        codes = launcher.stop()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    wall = time.monotonic() - started
    if launcher.failure:
        print(f"aero-rig: campaign failed: {launcher.failure}", file=sys.stderr)
        print(
            f"aero-rig: node logs in {run_dir / 'logs'}; the bag so far: {run_dir / 'bag'}",
            file=sys.stderr,
        )
        return 1
    bad = {n: c for n, c in codes.items() if c not in (0, -2, 130)}
    table = run_dir / "table1_all_levels.md"
    if not table.exists():
        print(
            f"aero-rig: the identifier produced no report ({reason}); exit codes {codes}",
            file=sys.stderr,
        )
        return 1
    problems = run_problems(run_dir, monitor.total)
    summary = {
        "wall_s": round(wall, 1),
        "experiment_s": round(monitor.total / 200.0, 1) if monitor.total else None,
        "real_time_factor": round(monitor.total / 200.0 / wall, 1) if monitor.total else None,
        "exit_codes": codes,
        "clean": not problems,
        "problems": problems,
    }
    (run_dir / "campaign.json").write_text(json.dumps(summary, indent=1))
    print("\nTable 1, trained on all levels (estimation: one realization per level):")
    print(table.read_text())
    level1 = run_dir / "table1_level1.md"
    if level1.exists():
        print("\nTable 1, trained on level 1 only (the paper's variant):")
        print(level1.read_text())
    print(
        f"\nwall time {summary['wall_s']} s for {summary['experiment_s']} s of experiment "
        f"({summary['real_time_factor']}x real time)"
    )
    print(f"run directory: {run_dir}  (bag/, models.json, table1_*.md|csv, *.png, logs/)")
    if bad:
        print(f"aero-rig: warning: nodes stopped uncleanly: {bad}", file=sys.stderr)
    if problems:
        print(f"\nDATA NOT CLEAN: {len(problems)} problem(s); Table 1 uses only what was left:")
        for line in problems[:40]:
            print(f"  - {line}")
        if len(problems) > 40:
            print(f"  - … {len(problems) - 40} more in {run_dir / 'data_quality.md'}")
        if not args.allow_excluded:
            print(
                "aero-rig: the campaign lost or excluded data (above); exit code 3. Pass "
                "--allow-excluded to accept such a run.",
                file=sys.stderr,
            )
            return EXIT_NOT_CLEAN
    else:
        print("data clean: every plan sample arrived and was recorded once, no anomaly")
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    graph = load_graph(Path(args.graph) if args.graph else _config(f"{args.which}.yaml"))
    graph = _with_view(graph, args.rerun, None)
    overrides: dict[str, dict[str, Any]] = {}
    if any(n.name == "recorder" for n in graph.nodes):
        out = _run_dir(args.out)
        overrides["recorder"] = {"output": str(out / "bag")}
        overrides["identifier"] = {"output_dir": str(out)}
        print(f"aero-rig: recording to {out / 'bag'}", file=sys.stderr)
    overrides = _merge(overrides, parse_overrides(args.overrides))
    return Launcher(graph, overrides=overrides).run(args.duration)


def _merge(
    base: dict[str, dict[str, Any]], extra: dict[str, dict[str, Any]]
) -> dict[str, dict[str, Any]]:
    """Per-node parameter overrides, ``extra`` (the user's -p) winning."""
    out = {name: dict(values) for name, values in base.items()}
    for name, values in extra.items():
        out.setdefault(name, {}).update(values)
    return out


def cmd_fit(args: argparse.Namespace) -> int:
    from .offline import BagError, fit_bag

    out = Path(args.out) if args.out else Path(args.bag).resolve().parent / "offline_fit"
    try:
        result, data = fit_bag(args.bag, out)
    except BagError as exc:
        print(f"aero-rig fit: {exc}", file=sys.stderr)
        return 2
    for warning in result.warnings:
        print(f"aero-rig fit: warning: {warning}", file=sys.stderr)
    tables = result.tables()
    print(f"{data.messages} samples read from {args.bag}")
    print("realizations in the bag (valid periods / periods):")
    for (level, m), block in sorted(data.assembler.blocks.items()):
        valid = int(block.period_valid().sum())
        state = "complete" if valid == block.P else ("incomplete" if valid else "none")
        print(f"  level {level} realization {m}: {valid}/{block.P} ({state})")
    print("\nTable 1, trained on all levels:")
    print(tables["all_levels"][0])
    print("\nTable 1, trained on level 1 only:")
    print(tables["level1"][0])
    print(f"\nreport: {out.resolve()}")
    problems = data_quality_lines(result.data_quality)
    if problems:
        print(f"\nDATA NOT CLEAN: {len(problems)} problem(s); Table 1 uses only what was left:")
        for line in problems[:40]:
            print(f"  - {line}")
        if not args.allow_excluded:
            print(
                "aero-rig fit: the bag lost or excluded data (above); exit code 3. Pass "
                "--allow-excluded to accept it.",
                file=sys.stderr,
            )
            return EXIT_NOT_CLEAN
    return 0


def cmd_view(args: argparse.Namespace) -> int:
    if args.source == "live":
        graph = _with_view(
            load_graph(_config("live_view.yaml")),
            "save" if args.save else "spawn",
            Path(args.save) if args.save else None,
        )
        graph = GraphSpec(graph.name, graph.nodes[-1:], graph.source)
        return Launcher(graph).run(None)
    from .view import view_bag

    view_bag(args.source, rrd_path=args.save, spawn=not args.save)
    return 0


def _add_override_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "-p",
        dest="overrides",
        action="append",
        default=[],
        metavar="NODE.PARAM:=VALUE",
        help="set a node parameter, as rig-launch -p (e.g. -p sim_wing.seed:=3); repeatable",
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="aero-rig", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("campaign", help="run the simulated campaign end to end")
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
    p.add_argument("--timeout", type=float, default=0.0, help="give up after S wall seconds")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument(
        "--allow-excluded",
        action="store_true",
        help="exit 0 even if data were lost or excluded (they are still listed)",
    )
    _add_override_option(p)
    p.set_defaults(func=cmd_campaign)

    p = sub.add_parser("run", help="run the sim or rig graph until Ctrl-C")
    p.add_argument("which", choices=("sim", "rig"))
    p.add_argument("--graph", default=None, help="graph YAML instead of config/<which>.yaml")
    p.add_argument("--duration", type=float, default=None, help="stop after S seconds")
    p.add_argument("--out", default=None, help="run directory for the bag and the report")
    p.add_argument("--rerun", choices=VIEW_MODES, default="off", help="live Rerun view")
    _add_override_option(p)
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("fit", help="offline fit of a recorded bag (MCAP or sqlite3)")
    p.add_argument("bag", help="rosbag2 directory")
    p.add_argument("--out", default=None, help="report directory (default <bag>/../offline_fit)")
    p.add_argument(
        "--allow-excluded",
        action="store_true",
        help="exit 0 even if data were lost or excluded (they are still listed)",
    )
    p.set_defaults(func=cmd_fit)

    p = sub.add_parser("view", help="Rerun view of a bag or of the live graph")
    p.add_argument("source", help="BAG directory or 'live'")
    p.add_argument("--save", default=None, help="write an .rrd instead of spawning a viewer")
    p.set_defaults(func=cmd_view)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except GraphError as exc:
        print(f"aero-rig: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
