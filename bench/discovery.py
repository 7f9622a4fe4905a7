"""How long a graph's endpoints take to match when its processes start a few tenths apart.

``--nodes`` processes, each one rclpy node of the runtime (`rig_runtime.node.Node`, so the
participant profile of `rig_runtime.participant_profile`, LOCALHOST discovery on a domain of
its own), start ``--gap`` seconds apart, as a launcher starts a graph. Each makes a reliable
writer and a reader of one topic and spins until both are matched with every process's, then
stays up until all are. Per round the bench prints how long after the last process made its
endpoints the last pair matched: what the start barrier waits beyond the processes' own start.

    .venv/bin/python bench/discovery.py [--nodes 6] [--gap 0.15] [--rounds 5] [--before TREE]

``--before TREE`` first runs the same rounds with the code of another checkout (its ``src/*``
on PYTHONPATH, this venv), so before and after are measured in one run.

Last line: JSON {"after": {"match_after_last_s": [...], "median_s": ..., "max_s": ...},
"before": {...}} (before only with ``--before``).
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from rig_testing.processes import graph_env, unique_domain_id

TOPIC = "/bench_discovery"
MATCH_TIMEOUT_S = 30.0

CHILD = """
import json, sys, time
from rig_runtime.interface import EXPERIMENT_ANOMALY as T
from rig_runtime.node import Node

name, topic, peers, timeout = sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4])
node = Node(name, argv=[])
pub = node.create_publisher(T.type, topic, T.qos)
sub = node.create_subscription(T.type, topic, lambda _msg: None, T.qos)
made = time.time()
matched = node.spin_until(
    lambda: pub.subscription_count() >= peers and sub.publisher_count() >= peers, timeout
)
print(json.dumps({"made": made, "matched": time.time() if matched else None}), flush=True)
sys.stdin.read()  # stay matched until the bench closes stdin
node.close()
"""


def one_round(nodes: int, gap: float, env: dict[str, str]) -> float:
    """Seconds from the last process's endpoints made to the last pair matched."""
    procs = []
    try:
        for i in range(nodes):
            procs.append(
                subprocess.Popen(
                    [
                        sys.executable,
                        "-c",
                        CHILD,
                        f"bench_discovery_{i}",
                        TOPIC,
                        str(nodes),
                        str(MATCH_TIMEOUT_S),
                    ],
                    env=env,
                    stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE,
                    text=True,
                )
            )
            time.sleep(gap)  # the launch's spacing is what is measured, not a readiness wait
        reports = []
        for proc in procs:
            assert proc.stdout is not None
            line = proc.stdout.readline()
            if not line:
                raise RuntimeError(f"a bench node exited ({proc.wait(10)}) before reporting")
            reports.append(json.loads(line))
    finally:
        for proc in procs:
            if proc.stdin is not None:
                proc.stdin.close()
        for proc in procs:
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    if any(r["matched"] is None for r in reports):
        raise RuntimeError(f"not every pair matched within {MATCH_TIMEOUT_S:g} s")
    return max(r["matched"] for r in reports) - max(r["made"] for r in reports)


def run(args: argparse.Namespace, tree: Path | None) -> dict[str, Any]:
    env = graph_env(unique_domain_id())
    if tree is not None:
        env["PYTHONPATH"] = os.pathsep.join(str(p) for p in sorted((tree / "src").glob("*")))
    spans = [round(one_round(args.nodes, args.gap, env), 3) for _ in range(args.rounds)]
    return {
        "match_after_last_s": spans,
        "median_s": round(statistics.median(spans), 3),
        "max_s": round(max(spans), 3),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--nodes", type=int, default=6, help="node processes (the sim graph: 6)")
    parser.add_argument("--gap", type=float, default=0.15, help="seconds between process starts")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--before", default=None, help="a checkout to compare with")
    args = parser.parse_args()
    results: dict[str, Any] = {}
    if args.before:
        results["before"] = run(args, Path(args.before).resolve())
        print(f"before ({args.before}): {json.dumps(results['before'])}")
    results["after"] = run(args, None)
    print(f"after (this checkout): {json.dumps(results['after'])}")
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
