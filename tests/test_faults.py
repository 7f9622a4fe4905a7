"""Fault injection on the campaign graph (issue: trust under load and faults).

Each case runs the real process graph on rclpy with a small plan (one level, two
realizations of 2 periods, one sine: 69 s of experiment; conftest.small_plan) and checks the
outcome a user must see. The starved and paused runs, which must give the idle run's
Table 1 byte for byte, are in test_campaign.py; bench/faults.py runs every case on the short
plan with figures.
"""

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from rosbags.highlevel import AnyReader

from multisine_gen.plan_format import segment_event_from_message
from rig_runtime import Node
from rig_runtime.graph import load_graph, package_share
from rig_runtime.interface import (
    EXPERIMENT_PLAN,
    EXPERIMENT_SEGMENT,
    PITCH_COMMAND,
    PITCH_STATE,
    PRESSURE_TAPS,
    WING_COEFFICIENTS,
)
from rig_runtime.launcher import Launcher, node_command
from rig_testing.processes import (
    finish,
    graph_env,
    join_graph,
    node_process,
    pause,
    start_session,
    wait_for,
)

SIM_GRAPH = package_share("aero_rig") / "config" / "sim.yaml"


def _campaign(*args: str, env: dict[str, str]) -> subprocess.Popen[str]:
    return start_session([sys.executable, "-m", "aero_rig.cli", "campaign", "--quiet", *args], env)


def _log_has(path: Path, text: str) -> bool:
    return path.exists() and text in path.read_text(errors="replace")


def _topic_counts(bag: Path) -> dict[str, int]:
    with AnyReader([bag]) as reader:
        counts = dict.fromkeys({c.topic for c in reader.connections}, 0)
        for conn, _, _ in reader.messages():
            counts[conn.topic] += 1
    return counts


def test_a_node_that_never_becomes_ready_stops_the_start_and_nothing_moves(
    tmp_path: Path,
) -> None:
    """The barrier waits for the identifier, which never reports: the generator gives up
    naming it, the campaign fails with that line, and not one command was sent."""
    graph = yaml.safe_load(SIM_GRAPH.read_text())
    graph["nodes"] = [n for n in graph["nodes"] if n["name"] != "identifier"]
    graph_file = tmp_path / "no_identifier.yaml"
    graph_file.write_text(yaml.safe_dump(graph))
    run = tmp_path / "run"
    started = time.monotonic()
    proc = _campaign(
        *("--plan", "short", "--out", str(run), "--graph", str(graph_file)),
        *("-p", "generator.start_timeout_s:=4"),
        *("-p", "generator.barrier_nodes:=[sim_actuator, sim_wing, lift, identifier, recorder]"),
        env=graph_env(),
    )
    _, err = finish(proc, 120)
    assert proc.returncode == 1, err
    assert time.monotonic() - started < 60
    # The campaign prints the generator's own error line, which names the missing node.
    assert "node 'generator' exited with code 1: [ERROR]" in err, err
    assert "start barrier: not ready after 4 s" in err and "/identifier: no readiness" in err
    counts = _topic_counts(run / "bag")
    assert counts.get(PITCH_COMMAND.name, 0) == 0 and counts.get(PITCH_STATE.name, 0) == 0
    assert EXPERIMENT_PLAN.name not in counts or counts[EXPERIMENT_PLAN.name] == 0


def test_a_recorder_started_late_is_waited_for_and_records_everything(
    small_plan: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    env = graph_env()
    join_graph(env, monkeypatch.setenv)
    full = load_graph(SIM_GRAPH)
    members = [n.name for n in full.nodes if n.barrier == "member"]
    graph = type(full)(full.name, tuple(n for n in full.nodes if n.name != "recorder"))
    run = tmp_path / "run"
    run.mkdir()
    overrides = {
        "generator": {"plan": str(small_plan), "real_time_factor": 0.0, "barrier_nodes": members},
        "identifier": {"output_dir": str(run), "exit_after_final": True},
    }
    launcher = Launcher(graph, env=env, overrides=overrides, log_dir=run / "logs")
    recorder_spec = full.node("recorder")
    recorder = None
    try:
        launcher.start()
        # The rest of the graph is up and waiting; the recorder comes 5 s later.
        assert wait_for(lambda: _log_has(run / "logs" / "generator.log", "plan "), 60)
        time.sleep(5.0)
        assert not _log_has(run / "logs" / "generator.log", "start barrier passed")
        with (run / "logs" / "recorder.log").open("wb") as log:
            recorder = subprocess.Popen(
                node_command(recorder_spec, {"output": str(run / "bag")}),
                env=env,
                stdout=log,
                stderr=subprocess.STDOUT,
            )
        assert wait_for(lambda: launcher.poll() is not None, 300), "the identifier did not finish"
    finally:
        codes = launcher.stop()
        if recorder is not None:
            recorder.send_signal(signal.SIGINT)
            recorder.wait(timeout=30)
    assert codes["identifier"] == 0, codes
    text = (run / "logs" / "generator.log").read_text()
    assert "start barrier passed after" in text
    waited = float(text.split("start barrier passed after ")[1].split(" s")[0])
    assert waited >= 5.0
    plan = json.loads(small_plan.read_text())
    counts = _topic_counts(run / "bag")
    total = sum(s["length"] for s in plan["segments"])
    for topic in (PITCH_COMMAND.name, PITCH_STATE.name, PRESSURE_TAPS.name, WING_COEFFICIENTS.name):
        assert counts.get(topic, 0) >= total, (topic, counts.get(topic), total)
    assert counts[PITCH_COMMAND.name] == total
    assert json.loads((run / "models.json").read_text())["data_quality"]["clean"]


def test_killing_the_lift_node_stops_the_campaign_and_the_bag_fits(
    small_plan: Path, tmp_path: Path
) -> None:
    run = tmp_path / "run"
    proc = _campaign(
        *("--plan", str(small_plan), "--out", str(run), "--real-time-factor", "5"),
        env=graph_env(),
    )
    try:
        identifier_log = run / "logs" / "identifier.log"
        # Killed once realization 0 is complete (its refit started), mid realization 1.
        assert wait_for(lambda: _log_has(identifier_log, "realization 0 complete"), 120)
        lift = node_process(proc.pid, "lift")
        assert lift is not None
        lift.kill()
        killed = time.monotonic()
    finally:
        _, err = finish(proc, 120)
    stopped_after = time.monotonic() - killed
    assert proc.returncode == 1
    assert "node 'lift' exited with code -9" in err, err
    assert stopped_after < 20, stopped_after
    fit = subprocess.run(
        [
            sys.executable,
            "-m",
            "aero_rig.cli",
            "fit",
            str(run / "bag"),
            "--out",
            str(tmp_path / "f"),
        ],
        env=graph_env(),
        capture_output=True,
        text=True,
        timeout=300,
    )
    # The bag is readable; the fit names what is complete and says the data are not.
    assert fit.returncode == 3, fit.stdout + fit.stderr
    assert "level 0 realization 0: 2/2 (complete)" in fit.stdout, fit.stdout
    assert "level 0 realization 1: " in fit.stdout and "DATA NOT CLEAN" in fit.stdout
    assert "plan samples missing" in fit.stdout


def test_a_free_running_actuator_is_reported_excluded_and_fails_the_campaign(
    small_plan: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The generator frozen longer than the actuator's stream timeout: the actuator runs on in
    real time (the first wave's corruption). The run must say so and exit non-zero."""
    env = graph_env()
    join_graph(env, monkeypatch.setenv)
    watcher = Node("fault_watcher", argv=[])
    events: list[dict[str, object]] = []
    watcher.create_subscription(
        EXPERIMENT_SEGMENT.type,
        EXPERIMENT_SEGMENT.name,
        lambda m: events.append(segment_event_from_message(m)),
        "events",
    )
    run = tmp_path / "run"
    proc = _campaign(
        *("--plan", str(small_plan), "--out", str(run), "--real-time-factor", "5"),
        *("-p", "sim_actuator.stream_timeout_s:=1.0"),
        env=env,
    )
    try:
        # Frozen as the first measured period of realization 1 starts.
        assert watcher.spin_until(
            lambda: any(
                (e.get("event"), e.get("kind"), e.get("realization"), e.get("period"))
                == ("start", "multisine", 1, 0)
                for e in events
            ),
            120,
        )
        generator = node_process(proc.pid, "generator")
        assert generator is not None
        pause(generator, 3.0)
    finally:
        watcher.close()
        out, err = finish(proc, 300)
    assert proc.returncode == 3, out[-3000:] + err[-3000:]
    assert "DATA NOT CLEAN" in out and "sim_actuator free_run" in out, out
    quality = json.loads((run / "models.json").read_text())["data_quality"]
    assert not quality["clean"]
    assert any("free_run" in a for a in quality["anomalies"])
    assert any("free_run" in p for p in quality["excluded_periods"] + quality["excluded_sines"])
    assert (run / "table1_all_levels.md").read_text().startswith("> **Data not clean**")
    assert "free_run" in (run / "data_quality.md").read_text()


def test_a_node_failing_at_start_is_named_with_its_own_error(tmp_path: Path) -> None:
    """What only the node finds at its start (a tap layout file that is not there; the
    declarations and the plan are checked before: test_refused_before_start.py)."""
    missing = tmp_path / "no_taps.yaml"
    proc = _campaign("-p", f"lift.taps_file:={missing}", "--out", str(tmp_path / "run"),
                     env=graph_env())  # fmt: skip
    _, err = finish(proc, 120)
    assert proc.returncode == 1
    assert (
        "campaign failed: node 'lift' exited with code 2: [FATAL] [/lift]: "
        f"cannot read tap layout {missing}"
    ) in err, err
