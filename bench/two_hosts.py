"""The campaign on two hosts against one machine, and each link fault's time to its diagnosis.

Builds a lab of hosts inside this machine (rig_testing.netlab: network namespaces on one
switch; needs root) and runs the simulated campaign of one plan and seed per case:

- ``one_host``: `aero-rig campaign` with every node on this machine (the reference);
- ``two_hosts``: the rig half (generator, actuator, wing, lift) by `rig-launch sim.yaml --host
  rig` on the lab's rig, the identifier and recorder by `aero-rig campaign --host workstation`
  on its workstation, ROS's default discovery (SUBNET, multicast);
- ``static_peers``: the same with LOCALHOST and ROS_STATIC_PEERS naming the other host;
- ``pulled_3s``: ``two_hosts`` with the rig's cable pulled for 3 s once the identifier holds
  the first realization (inside the DDS participant lease);
- ``pulled_past_lease``: the cable pulled for the lease + 5 s.

Per case: exit code, wall time, real-time factor (campaign.json), whether Table 1 (all levels)
is byte for byte one machine's, and for the faults the seconds from the fault to the campaign's
naming of the partition and to its exit.

    sudo .venv/bin/python bench/two_hosts.py [--plan small|short|FILE] [--cases a,b,...]

Last line: JSON {case: {...}}.
"""

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from graph_support import (
    LAB_HOSTS,
    WING,
    TwoHostRun,
    pull_cable,
    small_plan_design,
    two_host_campaign,
)

from multisine_gen.plan_format import plan_to_json
from rig_runtime.ros_environment import PARTICIPANT_LEASE_S
from rig_testing import netlab
from rig_testing.processes import graph_env

CASES = ("one_host", "two_hosts", "static_peers", "pulled_3s", "pulled_past_lease")


def one_host(plan: str, run: Path) -> dict[str, Any]:
    start = time.time()
    cli = [sys.executable, "-m", "aero_rig.cli", "campaign", "--plan", plan, *WING]
    done = subprocess.run(
        [*cli, "--out", str(run), "--quiet", "--timeout", "900"],
        env=graph_env(),
        capture_output=True,
        text=True,
    )
    return {"exit": done.returncode, "wall_s": round(time.time() - start, 1)}


def two_hosts(
    lab: netlab.NetLab, plan: str, run: Path, static_peers: bool, pull_s: float | None
) -> dict[str, Any]:
    ran = two_host_campaign(
        lab,
        Path(plan),
        run,
        graph_env(),
        static_peers=static_peers,
        during=pull_cable(lab, pull_s) if pull_s else None,
        timeout_s=900,
    )
    figures: dict[str, Any] = {"exit": ran.code, "wall_s": round(ran.wall_s, 1)}
    if ran.fault_at is not None:
        events = (
            TwoHostRun.summary_of(run)["flow_events"] if (run / "campaign.json").exists() else []
        )
        named = [e for e in events if e["event"] == "partition"]
        figures["fault_to_partition_named_s"] = (
            round(named[0]["epoch_s"] - ran.fault_at, 2) if named else None
        )
        figures["fault_to_exit_s"] = round(ran.started + ran.wall_s - ran.fault_at, 1)
        figures["stall_line"] = next(
            (line for line in ran.err.splitlines() if "stream stalled" in line), ""
        )[:300]
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--plan", default="small", help="small (default) | short | plan file")
    parser.add_argument("--cases", default=",".join(CASES), help="comma-separated cases")
    parser.add_argument("--out", type=Path, help="where the runs go (default: a temporary dir)")
    ns = parser.parse_args()
    why = netlab.unavailable()
    if why:
        sys.exit(f"bench/two_hosts.py: no lab of hosts here: {why}")
    cases = [c for c in ns.cases.split(",") if c]
    unknown = sorted(set(cases) - set(CASES))
    if unknown:
        sys.exit(f"unknown cases {unknown}; known: {', '.join(CASES)}")
    with tempfile.TemporaryDirectory() as tmp:
        base = ns.out or Path(tmp)
        base.mkdir(parents=True, exist_ok=True)
        plan = ns.plan
        if plan == "small":
            plan = str(base / "small.json")
            Path(plan).write_text(plan_to_json(small_plan_design()))
        results: dict[str, dict[str, Any]] = {}
        with netlab.NetLab(LAB_HOSTS) as lab:
            for case in cases:
                run = base / case
                if case == "one_host":
                    figures = one_host(plan, run)
                else:
                    pulls = {"pulled_3s": 3.0, "pulled_past_lease": PARTICIPANT_LEASE_S + 5.0}
                    figures = two_hosts(lab, plan, run, case == "static_peers", pulls.get(case))
                summary = run / "campaign.json"
                if summary.exists():
                    figures["real_time_factor"] = json.loads(summary.read_text())[
                        "real_time_factor"
                    ]
                reference = base / "one_host" / "table1_all_levels.md"
                mine = run / "table1_all_levels.md"
                if reference.exists() and mine.exists():
                    figures["table1_identical"] = mine.read_bytes() == reference.read_bytes()
                results[case] = figures
                print(f"{case}: {figures}", flush=True)
    print(json.dumps(results))


if __name__ == "__main__":
    main()
