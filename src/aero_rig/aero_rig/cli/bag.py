"""``aero-rig bag recover BAG``: bag maintenance (footers and metadata.yaml back after a
recorder crash)."""

import argparse
import sys
from typing import Any

from .common import EXIT_OK, EXIT_USAGE


def add_parser(subparsers: Any) -> None:
    p = subparsers.add_parser("bag", help="bag maintenance (recover a bag after a recorder crash)")
    p.set_defaults(func=main)
    bag_sub = p.add_subparsers(dest="bag_command", required=True)
    p = bag_sub.add_parser(
        "recover",
        help="rewrite the MCAP files that lost their footer (kill -9, power loss) up to their "
        "last complete chunk, and metadata.yaml (like ros2 bag reindex)",
    )
    p.add_argument("bag", metavar="BAG", help="rosbag2 directory (MCAP storage)")


def recover(args: argparse.Namespace) -> int:
    """``aero-rig bag recover BAG``: footers and metadata.yaml back after a recorder crash."""
    from rig_runtime.bag_recover import describe, format_stamp, last_readable_ns, recover_bag

    try:
        reports = recover_bag(args.bag)
    except (OSError, ValueError) as exc:
        print(f"aero-rig bag recover: {exc}", file=sys.stderr)
        return EXIT_USAGE
    for line in describe(reports):
        print(line)
    damaged = [r for r in reports if not r.intact]
    print(
        f"{args.bag}: {len(damaged)} of {len(reports)} file(s) recovered; "
        f"{sum(r.stats.count for r in reports)} messages; last readable time "
        f"{format_stamp(last_readable_ns(reports))}; metadata.yaml rewritten"
    )
    return EXIT_OK


def main(args: argparse.Namespace) -> int:
    """The ``bag`` verb: runs its sub-verb."""
    return SUBVERBS[args.bag_command](args)


SUBVERBS = {"recover": recover}
