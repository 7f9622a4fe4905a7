"""Small campaigns with each node paused 3 s in turn: how many end clean (exit 0).

The steps of ``tests/test_campaign.py::test_nodes_paused_in_turn_lose_nothing`` (the small
plan, SIGSTOP/SIGCONT of generator, actuator, wing, lift, identifier and recorder in turn once
the start barrier has passed), repeated, without the test's reference campaign. It measures the
README's known limit on rclpy's synchronous publication (README, "Known limits"):

    RMW_FASTRTPS_PUBLICATION_MODE=SYNCHRONOUS .venv/bin/python bench/paused_sync.py --runs 8

Environment variables (Fast DDS's publication mode, its profile file) pass to the
campaign as they are. Prints one line per run (exit code, wall time, the stall line if any);
last line JSON.
"""

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from graph_support import CAMPAIGN_NODES, campaign_paused_in_turn, small_plan_design

from multisine_gen.plan_format import plan_to_json
from rig_runtime.testing import graph_env


def paused_run(plan: Path, run: Path) -> tuple[int, float, list[str], str]:
    """One small campaign into ``run`` with each node paused 3 s in turn: (exit code, wall
    time, the nodes paused, the campaign's stall line or '')."""
    args = ("--plan", str(plan), "-p", "sim_wing.preset:=repeatable_stall", "--quiet")
    start = time.monotonic()
    code, _, err, paused = campaign_paused_in_turn([*args, "--timeout", "600"], run, graph_env())
    stall = next((line for line in err.splitlines() if "stream stalled" in line), "")
    return code, time.monotonic() - start, paused, stall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=8, help="campaigns to run (default 8)")
    parser.add_argument("--out", type=Path, help="where the runs go (default: a temporary dir)")
    ns = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        base = ns.out or Path(tmp)
        base.mkdir(parents=True, exist_ok=True)
        plan = base / "small.json"
        plan.write_text(plan_to_json(small_plan_design()))
        codes = []
        for i in range(ns.runs):
            code, wall, paused, stall = paused_run(plan, base / f"run{i}")
            codes.append(code)
            n = f"{len(paused)} of {len(CAMPAIGN_NODES)}"
            print(f"run {i}: exit {code}, {wall:.0f} s, paused {n} nodes {stall}")
    failed = sum(code != 0 for code in codes)
    print(json.dumps({"runs": len(codes), "failed": failed, "exit_codes": codes}))


if __name__ == "__main__":
    main()
