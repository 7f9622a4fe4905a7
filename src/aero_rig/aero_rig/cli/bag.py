"""``aero-rig bag recover BAG``: bag maintenance (footers and metadata.yaml back after a
recorder crash; every intact chunk of a file damaged in the middle kept, each gap named)."""

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
        "last complete chunk, or hold damaged chunks (skipped, every intact one kept; each gap "
        "printed with its time span and the messages lost per topic), and metadata.yaml (like "
        "ros2 bag reindex)",
    )
    p.add_argument("bag", metavar="BAG", help="rosbag2 directory (MCAP storage)")


def recover(args: argparse.Namespace) -> int:
    """``aero-rig bag recover BAG``: footers and metadata.yaml back after a recorder crash,
    and every intact chunk of a damaged file kept (each gap printed)."""
    from rig_runtime.bag_recover import describe, format_stamp, last_readable_ns, recover_bag

    try:
        reports = recover_bag(args.bag)
    except (OSError, ValueError) as exc:
        print(f"aero-rig bag recover: {exc}", file=sys.stderr)
        return EXIT_USAGE
    for line in describe(reports):
        print(line)
    damaged = [r for r in reports if not r.intact]
    gaps = [g for r in reports for g in r.gaps]
    lost = [g.lost_count for g in gaps]
    skipped = ""
    if gaps:
        unknown = f"; {lost.count(None)} stretch(es) of unknown count" if None in lost else ""
        skipped = (
            f"{len(gaps)} unreadable stretch(es) skipped ({sum(n or 0 for n in lost)} messages "
            f"lost in them{unknown}); "
        )
    print(
        f"{args.bag}: {len(damaged)} of {len(reports)} file(s) recovered; {skipped}"
        f"{sum(r.stats.count for r in reports)} messages; last readable time "
        f"{format_stamp(last_readable_ns(reports))}; metadata.yaml rewritten"
    )
    return EXIT_OK


def main(args: argparse.Namespace) -> int:
    """The ``bag`` verb: runs its sub-verb."""
    return SUBVERBS[args.bag_command](args)


SUBVERBS = {"recover": recover}
