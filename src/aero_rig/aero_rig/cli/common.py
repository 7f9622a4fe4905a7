"""What several ``aero-rig`` verbs share: exit codes, the ROS environment check, config paths,
the live view node, run directories, parameter overrides and the ``-p`` option."""

import argparse
import sys
from dataclasses import replace
from datetime import datetime
from pathlib import Path
from typing import Any

from rig_runtime import ros_environment
from rig_runtime.graph import GraphSpec, load_graph, package_share

EXIT_OK = 0
EXIT_FAILED = 1  # the graph or the fit failed
EXIT_USAGE = 2  # bad arguments, graph or input (one line on stderr says which)
EXIT_NOT_CLEAN = 3  # the campaign finished but lost or excluded data
VIEW_MODES = ("spawn", "save", "serve", "off")  # "off": no view node (the node calls it "none")


def config_path(name: str) -> Path:
    """A file of the installed aero_rig ``config/`` directory (graphs, parameter files)."""
    return package_share("aero_rig") / "config" / name


def with_view(graph: GraphSpec, mode: str, rrd: Path | None) -> GraphSpec:
    """``graph`` with the Rerun view node of config/live_view.yaml in ``mode`` (off: as is)."""
    if mode == "off":
        return graph
    view = load_graph(config_path("live_view.yaml")).nodes[0]
    overrides = {"mode": mode}
    if rrd is not None:
        overrides["rrd_path"] = str(rrd)
    view = replace(
        view, parameter_overrides={**view.parameter_overrides, **overrides}, stops_graph=False
    )
    return GraphSpec(graph.name, (*graph.nodes, view), graph.source)


def new_run_dir(out: str | None) -> Path:
    """``out`` or runs/<date-time>, created; SystemExit if it exists and is not empty."""
    if out:
        path = Path(out)
    else:
        path = Path("runs") / datetime.now().strftime("%Y%m%d-%H%M%S")
    if path.exists() and any(path.iterdir()):
        raise SystemExit(f"aero-rig: run directory {path} exists and is not empty; use --out NEW")
    path.mkdir(parents=True, exist_ok=True)
    return path.resolve()


def merge_overrides(
    base: dict[str, dict[str, Any]], extra: dict[str, dict[str, Any]]
) -> dict[str, dict[str, Any]]:
    """Per-node parameter overrides, ``extra`` (the user's -p) winning."""
    out = {name: dict(values) for name, values in base.items()}
    for name, values in extra.items():
        out.setdefault(name, {}).update(values)
    return out


def checked_ros_environment() -> None:
    """rclpy imports and the ROS environment is valid, or SystemExit(2) with one clear line."""
    try:
        ros_environment.require_rclpy()
        ros_environment.check()
    except ros_environment.RosEnvironmentError as exc:
        print(f"aero-rig: {exc}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE) from None


def add_override_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "-p",
        dest="overrides",
        action="append",
        default=[],
        metavar="NODE.PARAM:=VALUE",
        help="set a node parameter, as rig-launch -p (e.g. -p sim_wing.seed:=3); repeatable",
    )
