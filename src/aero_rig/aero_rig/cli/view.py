"""``aero-rig view BAG|live``: a Rerun view of a recorded bag or of the running graph."""

import argparse
from pathlib import Path
from typing import Any

from rig_runtime.graph import GraphSpec, load_graph
from rig_runtime.launcher import Launcher

from .common import EXIT_OK, checked_ros_environment, config_path, with_view


def add_parser(subparsers: Any) -> None:
    p = subparsers.add_parser("view", help="Rerun view of a bag or of the live graph")
    p.add_argument(
        "source", help="BAG directory (no rclpy needed) or 'live' (the graph's view node)"
    )
    p.add_argument("--save", default=None, help="write an .rrd instead of spawning a viewer")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    if args.source == "live":
        checked_ros_environment()
        graph = with_view(
            load_graph(config_path("live_view.yaml")),
            "save" if args.save else "spawn",
            Path(args.save) if args.save else None,
        )
        graph = GraphSpec(graph.name, graph.nodes[-1:], graph.source)
        return Launcher(graph).run(None)
    from ..view import view_bag

    view_bag(args.source, rrd_path=args.save, spawn=not args.save)
    return EXIT_OK
