"""How reliably the real ``ros2`` tools see a running simulated graph.

The sim graph (`aero-rig run sim`'s, real time, LOCALHOST discovery as simulated campaigns use
it) runs; against it, ``ros2 node list`` (Jazzy's ros2cli, rclpy on Fast DDS)
is run ``--tries`` times in each of these ways:

- ``daemon``: as a user types it, through the ROS 2 daemon of the domain (started once);
- ``direct_localhost``: ``--no-daemon`` (its default 0.5 s spin), ROS_AUTOMATIC_DISCOVERY_RANGE
  LOCALHOST, the graph's range;
- ``direct_default_env``: ``--no-daemon`` with the variable unset: a stock ROS 2 shell
  (SUBNET).

A try counts if it lists all six nodes.

    .venv/bin/python bench/ros2_discovery.py [--tries 10]

Last line: JSON {"rclpy": {way: complete tries}, "tries": N}.
"""

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from aero_rig.cli.common import config_path
from rig_runtime.graph import load_graph
from rig_runtime.launcher import Launcher
from rig_testing.processes import graph_env, unique_domain_id

ROS2 = Path(sys.executable).parent / "ros2"
NODES = ["/generator", "/identifier", "/lift", "/recorder", "/sim_actuator", "/sim_wing"]


def node_list(env: dict[str, str], *extra: str) -> list[str]:
    proc = subprocess.run(
        [str(ROS2), "node", "list", *extra], env=env, capture_output=True, text=True, timeout=60
    )
    return sorted(proc.stdout.split())


def measure(tries: int, run_dir: Path) -> dict[str, Any]:
    env = graph_env(unique_domain_id())
    graph = load_graph(config_path("sim.yaml"))
    overrides: dict[str, dict[str, Any]] = {
        "generator": {"plan": "default", "real_time_factor": 1.0},
        "identifier": {"output_dir": str(run_dir), "use_worker": False, "scan": False},
        "recorder": {"output": str(run_dir / "bag")},
    }
    launcher = Launcher(graph, env=env, overrides=overrides, log_dir=run_dir / "logs")
    launcher.start()
    stock = {k: v for k, v in env.items() if k != "ROS_AUTOMATIC_DISCOVERY_RANGE"}
    try:
        # The graph is up once the daemon (started by the first call) lists every node.
        deadline = time.monotonic() + 120.0
        while node_list(env) != NODES:
            if time.monotonic() > deadline or launcher.poll() is not None:
                raise RuntimeError("the graph never showed its six nodes")
        counts = {
            "daemon": sum(node_list(env) == NODES for _ in range(tries)),
            "direct_localhost": sum(node_list(env, "--no-daemon") == NODES for _ in range(tries)),
            "direct_default_env": sum(
                node_list(stock, "--no-daemon") == NODES for _ in range(tries)
            ),
        }
        counts["direct_localhost_spin_3s"] = sum(
            node_list(env, "--no-daemon", "--spin-time", "3") == NODES for _ in range(tries)
        )
    finally:
        subprocess.run([str(ROS2), "daemon", "stop"], env=env, capture_output=True, timeout=60)
        launcher.stop()
    return counts


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tries", type=int, default=10)
    args = parser.parse_args()
    if not ROS2.exists():
        print("the ros2 tools are not in the venv: ../shared/ros2-python/install.sh .venv")
        return 2
    results: dict[str, Any] = {"tries": args.tries}
    with tempfile.TemporaryDirectory(prefix="bench_ros2_") as tmp:
        results["rclpy"] = measure(args.tries, Path(tmp))
    print(f"complete listings of {args.tries}: {results['rclpy']}")
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
