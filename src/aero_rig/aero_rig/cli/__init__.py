"""``aero-rig``: run the pitching-wing campaign, live graphs, offline fits and views.

    aero-rig campaign [--plan default|short|FILE] [--seed N] [--real-time-factor X] [--out DIR]
                      [--rerun spawn|save|serve|off] [--graph FILE] [--host NAME]
                      [--timeout S] [--quiet] [--adaptive] [--allow-excluded]
                      [-p NODE.PARAM:=VALUE ...]
    aero-rig run sim|rig [--graph FILE] [--duration S] [--out DIR] [--rerun MODE]
                         [-p NODE.PARAM:=VALUE ...]
    aero-rig fit BAG [--out DIR] [identification options: --nx, --scan, --bootstrap B, ...]
    aero-rig fit FILE|DIR --format csv|mat --input COL --output COL --period N [--fs HZ]
                 [--levels PATTERN...] [--estimation L...] [--validation L...]
                 [--drop-periods K] [--out DIR]
    aero-rig view BAG|live [--save FILE.rrd]
    aero-rig bag recover BAG

Every option: ``aero-rig VERB --help`` and docs/usage.md.

``campaign`` launches the simulated graph (generator, simulated actuator, simulated wing, lift,
identifier, recorder, optionally the Rerun view) as rclpy node processes, runs the plan to its
end, waits for the final identification, stops everything and prints Table 1 and the run
directory (bag, models, report, .rrd). A run that lost or excluded data (missing or
duplicated samples, anomalies such as a free-running actuator, excluded periods or sine records,
a bag short of samples) lists what on its last lines and exits with code 3, unless
``--allow-excluded`` is given.

One module per verb, ros2cli-style, each with its parser next to its handler
(``add_parser(subparsers)``, ``main(args)``): campaign.py, run.py, fit.py, view.py, bag.py;
common.py holds what several verbs share, monitor.py the campaign's in-process observer.
"""

import argparse
import sys

from rig_runtime.graph import GraphError

from . import bag, campaign, fit, run, view
from .common import (
    EXIT_NOT_CLEAN,
    EXIT_USAGE,
    VIEW_MODES,
    checked_ros_environment,
    config_path,
)
from .monitor import CampaignMonitor

__all__ = [
    "EXIT_NOT_CLEAN",
    "VIEW_MODES",
    "CampaignMonitor",
    "build_parser",
    "checked_ros_environment",
    "config_path",
    "main",
]

VERBS = (campaign, run, fit, view, bag)  # in the order of ``aero-rig --help``


def build_parser() -> argparse.ArgumentParser:
    """The ``aero-rig`` parser: each verb module adds its own sub-parser (``add_parser``)."""
    parser = argparse.ArgumentParser(prog="aero-rig", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    for verb in VERBS:
        verb.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except GraphError as exc:
        print(f"aero-rig: {exc}", file=sys.stderr)
        return EXIT_USAGE
