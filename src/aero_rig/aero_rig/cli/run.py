"""``aero-rig run sim|rig``: a graph until Ctrl-C (or ``--duration``), recording if it has a
recorder."""

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from rig_runtime import ros_environment
from rig_runtime.graph import GraphError, load_graph
from rig_runtime.launcher import Launcher, parse_overrides

from .common import (
    EXIT_USAGE,
    VIEW_MODES,
    add_override_option,
    checked_ros_environment,
    config_path,
    merge_overrides,
    new_run_dir,
    with_view,
)


def add_parser(subparsers: Any) -> None:
    p = subparsers.add_parser("run", help="run the sim or rig graph until Ctrl-C")
    p.add_argument("which", choices=("sim", "rig"))
    p.add_argument("--graph", default=None, help="graph YAML instead of config/<which>.yaml")
    p.add_argument("--duration", type=float, default=None, help="stop after S seconds")
    p.add_argument("--out", default=None, help="run directory for the bag and the report")
    p.add_argument("--rerun", choices=VIEW_MODES, default="off", help="live Rerun view")
    add_override_option(p)
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    checked_ros_environment()
    if args.which == "sim":
        ros_environment.localhost_by_default(os.environ)
    print(f"aero-rig: {args.which} graph", file=sys.stderr)
    graph = load_graph(Path(args.graph) if args.graph else config_path(f"{args.which}.yaml"))
    graph = with_view(graph, args.rerun, None)
    overrides: dict[str, dict[str, Any]] = {}
    if any(n.name == "recorder" for n in graph.nodes):
        out = new_run_dir(args.out)
        overrides["recorder"] = {"output": str(out / "bag")}
        overrides["identifier"] = {"output_dir": str(out)}
        print(f"aero-rig: recording to {out / 'bag'}", file=sys.stderr)
    overrides = merge_overrides(overrides, parse_overrides(args.overrides))
    try:
        launcher = Launcher(graph, overrides=overrides)
        launcher.check()  # every parameter, before any node starts
    except (KeyError, GraphError) as exc:
        print(f"aero-rig: {exc}", file=sys.stderr)
        return EXIT_USAGE
    return launcher.run(args.duration)
