"""`aero-rig campaign --host`: which machine may run the campaign, and the other half's command
line (aero_rig/cli/campaign.py); no node is started."""

import shlex
from dataclasses import replace
from typing import Any

import pytest

from aero_rig.cli.campaign import check_campaign_host, other_hosts_note
from aero_rig.cli.common import config_path, with_view
from rig_runtime.graph import GraphError, load_graph
from rig_runtime.launcher import Launcher


def test_the_campaign_runs_where_the_identifier_recorder_and_view_run() -> None:
    graph = load_graph(config_path("sim.yaml"))
    check_campaign_host(Launcher(graph, hosts=["workstation"]))
    check_campaign_host(Launcher(graph))  # one machine: every node here
    with pytest.raises(
        GraphError, match=r"identifier, recorder: run it on their host \(--host workstation\)"
    ):
        check_campaign_host(Launcher(graph, hosts=["rig"]))
    viewed = with_view(graph, "save", None)
    check_campaign_host(Launcher(viewed, hosts=["workstation"]))
    elsewhere = replace(viewed, nodes=(*viewed.nodes[:-1], replace(viewed.nodes[-1], host="rig")))
    with pytest.raises(GraphError, match="outputs of view"):
        check_campaign_host(Launcher(elsewhere, hosts=["workstation"]))


def test_the_other_half_gets_a_command_line_with_the_campaigns_overrides() -> None:
    graph = load_graph(config_path("sim.yaml"))
    plan = "/data/plans/my plan.json"  # a space: the line must still be one argument
    overrides: dict[str, dict[str, Any]] = {
        "generator": {"plan": plan, "seed": 3},
        "sim_wing": {"preset": "repeatable_stall"},
    }
    launcher = Launcher(graph, overrides=overrides, hosts=["workstation"])
    launcher.env["RMW_FASTRTPS_PUBLICATION_MODE"] = "ASYNCHRONOUS"
    note = other_hosts_note(launcher)
    assert note.startswith("aero-rig: this machine starts identifier, recorder;")
    (line,) = [x for x in note.splitlines() if x.startswith("  rig (")]
    assert line.startswith("  rig (generator, sim_actuator, sim_wing, lift): ")
    argv = shlex.split(line.split(": ", 1)[1])
    assert argv[0] == "RMW_FASTRTPS_PUBLICATION_MODE=ASYNCHRONOUS"
    assert argv[1:5] == ["rig-launch", str(graph.source), "--host", "rig"]
    sets = [argv[i + 1] for i, a in enumerate(argv) if a == "-p"]
    assert f"generator.plan:={plan}" in sets and "generator.seed:=3" in sets
    assert "sim_wing.preset:=repeatable_stall" in sets
    assert not any(s.startswith("generator.barrier_nodes") for s in sets)
