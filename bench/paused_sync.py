"""Small campaigns with each node paused 3 s in turn: how many end clean (exit 0).

The steps of ``tests/test_campaign.py::test_nodes_paused_in_turn_lose_nothing`` (the small
plan, SIGSTOP/SIGCONT of generator, actuator, wing, lift, identifier and recorder in turn once
the start barrier has passed), repeated, without the test's reference campaign. It measures the
known issue of rclpy's synchronous publication (docs/known_issues.md; figures: docs/results.md):

    RMW_FASTRTPS_PUBLICATION_MODE=SYNCHRONOUS .venv/bin/python bench/paused_sync.py --runs 8

Environment variables (Fast DDS's publication mode, its profile file) pass to the
campaign as they are. Prints one line per run (exit code, wall time, the stall line if any),
then the readers the campaign named stuck (rig_runtime.flow) and the nodes' lines on samples a
reader held undelivered until its flow report took them (rig_runtime.node); last line JSON
with the counts.
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
from rig_testing.processes import graph_env


def paused_run(plan: Path, run: Path) -> tuple[int, float, list[str], str]:
    """One small campaign into ``run`` with each node paused 3 s in turn: (exit code, wall
    time, the nodes paused, the campaign's stall line or '')."""
    args = ("--plan", str(plan), "-p", "sim_wing.preset:=repeatable_stall", "--quiet")
    start = time.monotonic()
    code, _, err, paused = campaign_paused_in_turn([*args, "--timeout", "600"], run, graph_env())
    stall = next((line for line in err.splitlines() if "stream stalled" in line), "")
    (run.parent / f"{run.name}.err").write_text(err)
    return code, time.monotonic() - start, paused, stall


def stuck_and_taken(run: Path, err: str) -> tuple[list[str], list[str]]:
    """The readers the campaign named stuck (rig_runtime.flow), and the nodes' log lines of
    samples a reader held undelivered until its flow report took them (node.py)."""
    stuck = [line for line in err.splitlines() if "reader stuck:" in line]
    taken = [
        f"{log.stem}: {line.split(']: ', 1)[-1]}"
        for log in sorted((run / "logs").glob("*.log"))
        for line in log.read_text(errors="replace").splitlines()
        if "held undelivered" in line
    ]
    return stuck, taken


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
        codes, stuck_runs, taken_runs = [], 0, 0
        for i in range(ns.runs):
            run = base / f"run{i}"
            code, wall, paused, stall = paused_run(plan, run)
            stuck, taken = stuck_and_taken(run, (base / f"run{i}.err").read_text())
            codes.append(code)
            stuck_runs += bool(stuck)
            taken_runs += bool(taken)
            n = f"{len(paused)} of {len(CAMPAIGN_NODES)}"
            print(f"run {i}: exit {code}, {wall:.0f} s, paused {n} nodes {stall}", flush=True)
            for line in stuck + taken:
                print(f"    {line[:400]}", flush=True)
    failed = sum(code != 0 for code in codes)
    print(
        json.dumps(
            {
                "runs": len(codes),
                "failed": failed,
                "exit_codes": codes,
                "runs_with_a_stuck_reader": stuck_runs,
                "runs_with_undelivered_samples_taken": taken_runs,
            }
        )
    )


if __name__ == "__main__":
    main()
