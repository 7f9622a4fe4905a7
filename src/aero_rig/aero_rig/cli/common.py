"""What several ``aero-rig`` verbs share: exit codes, the backend check, config paths, the live
view node, run directories, parameter overrides and the ``-p`` / ``--node-backend`` options."""

import argparse
import os
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


def backend_label(backend: str) -> str:
    return "rclpy (Fast DDS)" if backend == "rclpy" else "the Cyclone DDS backend"


def checked_backend() -> str:
    """The runtime backend of the graph to start, or SystemExit(2) with one clear line."""
    try:
        backend = ros_environment.check()
    except ros_environment.RosEnvironmentError as exc:
        print(f"aero-rig: {exc}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE) from None
    if backend == "dds" and not os.environ.get(ros_environment.BACKEND_ENV):
        print(
            "aero-rig: rclpy does not import here; the graph runs on the Cyclone DDS backend "
            f"(for rclpy: {ros_environment.INSTALL_RCLPY})",
            file=sys.stderr,
        )
    return backend


def add_override_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "-p",
        dest="overrides",
        action="append",
        default=[],
        metavar="NODE.PARAM:=VALUE",
        help="set a node parameter, as rig-launch -p (e.g. -p sim_wing.seed:=3); repeatable",
    )


def add_backend_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--node-backend",
        action="append",
        default=[],
        metavar="NODE=BACKEND",
        help="run NODE on rclpy or dds, the others on RIG_RUNTIME_BACKEND's (default: rclpy "
        "where it imports): a mixed graph, as a lab with ROS PCs and a venv laptop; repeatable",
    )


def parse_node_backends(items: list[str]) -> dict[str, str]:
    """``["lift=dds", ...]`` -> ``{"lift": "dds"}``; SystemExit(2) on a malformed item."""
    out = {}
    for item in items:
        name, sep, backend = item.partition("=")
        if not sep or backend not in ("rclpy", "dds") or not name:
            print(f"aero-rig: --node-backend {item!r}: expected NODE=rclpy|dds", file=sys.stderr)
            raise SystemExit(EXIT_USAGE)
        if backend == "rclpy" and not ros_environment.rclpy_available():
            print(
                f"aero-rig: --node-backend {item}: rclpy does not import here; install it with "
                f"`{ros_environment.INSTALL_RCLPY}`",
                file=sys.stderr,
            )
            raise SystemExit(EXIT_USAGE)
        out[name] = backend
    return out
