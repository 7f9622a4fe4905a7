"""The whole campaign graph as rclpy node processes, the offline fit, and faults: the short plan's
identification; the small plan (conftest.small_plan) where a run must lose nothing and give
the idle run's tables under load or after the identifier's kill."""

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from graph_support import (
    WING,
    assert_lossless_and_identical,
    campaign_paused_in_turn,
)
from rosbags.highlevel import AnyReader

from multisine_gen.plan_format import read_plan_message, segment_event_from_message
from rig_runtime.interface import (
    EXPERIMENT_ANOMALY,
    EXPERIMENT_PLAN,
    EXPERIMENT_SEGMENT,
    IDENTIFICATION_MODEL,
    IDENTIFICATION_STATUS,
    PITCH_COMMAND,
    PITCH_STATE,
    PRESSURE_TAPS,
    RECORDED_TOPICS,
    WING_COEFFICIENTS,
)
from rig_runtime.messages import stamp_to_ns
from rig_runtime.ros_environment import PARTICIPANT_LEASE_S
from rig_testing.processes import (
    BusyProcesses,
    descendants,
    finish,
    graph_env,
    node_process,
    pause,
    process_gone,
    start_session,
    wait_for,
)

CLI = (sys.executable, "-m", "aero_rig.cli")
STRING = "std_msgs/msg/String"  # what the events, plan and models were before aero_rig_interfaces
RTF5 = ("--real-time-factor", "5")
TIMEOUT_600 = ("--timeout", "600")


def _aero_rig(*args: str, env: dict[str, str], timeout: float) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "aero_rig.cli", *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


@pytest.fixture(scope="module")
def campaign(
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[Path, subprocess.CompletedProcess[str]]:
    run = tmp_path_factory.mktemp("campaign") / "run"
    proc = _aero_rig(
        "campaign",
        "--plan",
        "short",
        *WING,
        "--out",
        str(run),
        "--rerun",
        "save",
        "--quiet",
        "--timeout",
        "600",
        env=graph_env(),
        timeout=700,
    )
    return run, proc


@pytest.fixture(scope="module")
def starved_campaign(
    small_plan: Path, tmp_path_factory: pytest.TempPathFactory
) -> tuple[Path, subprocess.CompletedProcess[str]]:
    """The small campaign with two busy processes per core at the stream nodes' priority
    (sim.yaml: nice 5) for the whole run: the first wave lost its first 1,000 samples so."""
    run = tmp_path_factory.mktemp("starved") / "run"
    with BusyProcesses(2 * (os.cpu_count() or 2), nice=5, limit_s=900):
        proc = _aero_rig(
            *("campaign", "--plan", str(small_plan), *WING, "--out", str(run), "--quiet"),
            *("--timeout", "800"),
            env=graph_env(),
            timeout=900,
        )
    return run, proc


def _tables(text: str) -> dict[tuple[str, str], float]:
    """{(model, column): value} of the first Markdown table in text (a cell "0.12 ± 0.01" is
    its value 0.12; the ± is the spread over the sine's periods)."""
    lines = [line for line in text.splitlines() if line.startswith("|")]
    header = [c.strip() for c in lines[0].strip("|").split("|")]
    cells = {}
    for line in lines[2:]:
        row = [c.strip() for c in line.strip("|").split("|")]
        for col, cell in zip(header[1:], row[1:], strict=True):
            value = cell.split("±")[0].strip()
            cells[(row[0], col)] = float(value) if value not in ("–", "") else float("nan")
    return cells


def test_campaign_ends_by_itself_with_report(campaign) -> None:
    run, proc = campaign
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "run directory:" in proc.stdout
    for name in ("models.json", "table1_all_levels.md", "table1_level1.csv", "campaign.json"):
        assert (run / name).exists(), name
    assert list(run.glob("frf_*.png")) and list(run.glob("cl_alpha_*.png"))
    # As fast as the graph goes: Fast DDS publishes asynchronously (a third faster).
    summary = json.loads((run / "campaign.json").read_text())
    assert summary["fastdds_publication"] == "ASYNCHRONOUS"
    assert "publishes asynchronously" in proc.stderr
    assert "ASYNCHRONOUS publication" in (run / "logs" / "sim_wing.log").read_text()
    # Stopped with the graph, the recorder closed the bag once the publishers had left, not on
    # its drain timeout (which would mean it waited for itself or for a node that hung).
    assert "still published" not in (run / "logs" / "recorder.log").read_text()


# The fields of each recorded type (rig_runtime.interface; aero_rig_interfaces' .msg files) that
# a message decoded by mcap-ros2-support must have.
DECODED_FIELDS: dict[str, tuple[str, ...]] = {
    PITCH_COMMAND.type: ("header", "name", "position", "velocity"),
    PRESSURE_TAPS.type: ("header", "fields", "point_step", "data"),
    WING_COEFFICIENTS.type: ("header", "vector"),
    EXPERIMENT_PLAN.type: (
        "header", "plan_id", "revision", "t0_ns", "fs", "samples", "levels", "realizations",
        "offsets_deg", "adaptive", "plan_json",
    ),
    EXPERIMENT_SEGMENT.type: (
        "header", "event", "t0_ns", "index", "kind", "start_k", "length", "level", "period",
        "start_stamp_s", "end_stamp_s", "samples", "fs", "at_k", "request", "after_k", "why",
    ),
    EXPERIMENT_ANOMALY.type: ("id", "node", "kind", "first_ns", "open", "last_ns", "detail"),
    IDENTIFICATION_STATUS.type: ("header", "status"),
    IDENTIFICATION_MODEL.type: (
        "header", "refit", "complete", "selected_class", "levels", "table1", "table1_level1",
        "warnings", "model_json",
    ),
}  # fmt: skip


def _decode_every_message(bag: Path, total_samples: int) -> dict[str, int]:
    """Decode every message of every file of ``bag`` with mcap-ros2-support, check its fields
    (DECODED_FIELDS, the nested LevelSummary and TableCell too) and that the rig's readers take
    the rig's messages so decoded; the messages decoded per topic."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from aero_identification.model_message import model_from_message
    from rig_runtime.anomaly import Anomaly

    counts: dict[str, int] = {}
    for path in sorted(bag.glob("*.mcap")):
        with path.open("rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            for schema, channel, _, decoded in reader.iter_decoded_messages():
                assert schema is not None and schema.encoding == "ros2msg", channel.topic
                assert channel.message_encoding == "cdr", channel.topic
                absent = [f for f in DECODED_FIELDS[schema.name] if not hasattr(decoded, f)]
                assert not absent, (channel.topic, schema.name, absent)
                counts[channel.topic] = counts.get(channel.topic, 0) + 1
                if schema.name == EXPERIMENT_PLAN.type:
                    assert decoded.plan_id and decoded.t0_ns > 0, decoded.plan_id
                    revision, _ = read_plan_message(decoded)
                    assert revision.revision == decoded.revision
                    assert revision.total_samples == total_samples or decoded.adaptive
                elif schema.name == EXPERIMENT_SEGMENT.type:
                    assert segment_event_from_message(decoded)["event"] == decoded.event
                elif schema.name == EXPERIMENT_ANOMALY.type:
                    assert Anomaly.from_message(decoded).kind == decoded.kind
                elif schema.name == IDENTIFICATION_MODEL.type:
                    assert model_from_message(decoded)["refit"] == decoded.refit
                    for level in decoded.levels:
                        assert hasattr(level, "cluster_sizes") and hasattr(level, "role")
                    for cell in [*decoded.table1, *decoded.table1_level1]:
                        assert hasattr(cell, "error") and hasattr(cell, "spread")
    return counts


def test_bag_holds_every_topic_and_no_sample_lost(campaign) -> None:
    run, _ = campaign
    stamps: dict[str, list[int]] = {}
    with AnyReader([run / "bag"]) as reader:
        connections = list(reader.connections)
        topics = {c.topic for c in connections}
        assert {t.name for t in RECORDED_TOPICS} <= topics
        # Every topic has its interface type (rig_runtime.interface): no JSON in a String.
        assert {c.topic: c.msgtype for c in reader.connections} == {
            t.name: t.type for t in RECORDED_TOPICS if t.name in topics
        }
        assert not [c.topic for c in reader.connections if c.msgtype == STRING]
        conns = [
            c
            for c in reader.connections
            if c.topic
            in (PITCH_COMMAND.name, PITCH_STATE.name, PRESSURE_TAPS.name, WING_COEFFICIENTS.name)
        ]
        for conn, _, raw in reader.messages(connections=conns):
            msg: Any = reader.deserialize(raw, conn.msgtype)
            stamps.setdefault(conn.topic, []).append(stamp_to_ns(msg.header.stamp))
        plan_conn = [c for c in reader.connections if c.topic == EXPERIMENT_PLAN.name]
        plan_msg: Any = reader.deserialize(
            next(reader.messages(plan_conn))[2], EXPERIMENT_PLAN.type
        )
        plan, _ = read_plan_message(plan_msg)
    commands = np.array(stamps[PITCH_COMMAND.name])
    assert len(commands) == plan.total_samples
    assert len(np.unique(commands)) == len(commands)
    coefficients = set(stamps[WING_COEFFICIENTS.name])
    missing = [s for s in commands if s not in coefficients]
    assert not missing, f"{len(missing)} command samples have no coefficients sample"
    # A tool that knows only the bag (Foxglove's MCAP ROS 2 decoder) decodes every message into
    # its fields, from the definitions the recorder embeds (rig_runtime.bag); the rig's readers
    # take its messages as they take rosbags' and rclpy's.
    assert {t.type for t in RECORDED_TOPICS} <= set(DECODED_FIELDS)
    decoded_counts = _decode_every_message(run / "bag", plan.total_samples)
    assert decoded_counts == {c.topic: c.msgcount for c in connections if c.msgcount}


def test_every_view_of_the_rrd_holds_what_the_identification_sent(campaign) -> None:
    """The campaign's .rrd, read back with Rerun's reader: every entity the final blueprint lays
    out holds data, and the model entities hold what models.json says, model by model."""
    from aero_identification import model_payload as mm
    from aero_rig.view import slug
    from aero_rig.view.blueprint import cl_alpha_to_view
    from aero_rig.view.logger import finite_runs
    from aero_rig.view.readback import Rrd, entity_rows

    run, proc = campaign
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    rrd = Rrd(run / "campaign.rrd")
    model = json.loads((run / "models.json").read_text())
    rows = entity_rows(run / "campaign.rrd")
    for entity in ("/series/pitch/command", "/series/pitch/measured", "/series/cl",
                   "/cp/upper", "/cp/lower", "/cp/taps", "/cl_alpha/live", "/events/segment",
                   "/events/model", "/events/status", "/model/summary"):  # fmt: skip
        assert rows.get(entity), entity
    # Each model's prediction of each validation sine: the final model's four, and the measured.
    assert len(model[mm.PREDICTIONS]) == 4
    # Every model's series; the semi-empirical baseline only where the plan has a sweep.
    fitted = set(mm.MODELS)
    if model["models"]["beddoes_leishman"] is None:
        fitted.discard(mm.BEDDOES_LEISHMAN)
    for pred in model[mm.PREDICTIONS]:
        series = dict(mm.prediction_series(pred))
        assert set(series) == {mm.MEASURED, *fitted}, series.keys()
        alpha = np.array(pred[mm.ALPHA_DEG], float)
        for name, values in series.items():
            entity = f"/cl_alpha/predictions/{slug(pred[mm.NAME])}/{slug(name)}"
            strips = rrd.column(entity, "LineStrips2D:strips")
            assert strips, entity
            # The last drawing is this series, point by point, in view coordinates.
            expected = finite_runs(*cl_alpha_to_view(alpha, np.array(values, float)))
            lines = [np.array(strip) for strip in strips[-1]]
            assert len(lines) == len(expected) > 0, entity
            for got, want in zip(lines, expected, strict=True):
                np.testing.assert_allclose(got, want, atol=1e-4, err_msg=entity)
    # The FRF with its noise and distortion, and the cluster labels, of each level.
    for label, level in model[mm.LEVELS].items():
        for part in ("G_dB", "noise_dB", "nl_distortion_dB"):
            _, values = rrd.bars(f"/frf/level_{slug(label)}/{part}")
            assert values.size > 0, (label, part)
        labels = np.array(level[mm.CLUSTERS][mm.LABELS])
        shown = [p for p in rows if p.startswith(f"/clusters/level_{slug(label)}/")
                 and rrd.rows[p] and "BarChart:values" in rrd.rows[p][-1]]  # fmt: skip
        drawn = sum(rrd.bars(path)[1].size for path in shown)
        assert drawn == labels.size, label
    # Table 1 with its spreads, as the report has it; the data-quality line; no warnings.
    table = rrd.column("/model/table1", "TextDocument:text")[-1][0]
    assert model[mm.TABLE1][mm.TABLE1_ALL_LEVELS] in table and " ± " in table
    assert model[mm.TABLE1][mm.TABLE1_LEVEL1] in table
    quality = rrd.column("/events/data_quality", "TextLog:text")[-1][0]
    assert quality.startswith("data quality: clean (plan samples received: pitch "), quality
    (report,) = [t[0] for t in rrd.column("/events/view", "TextLog:text")]
    assert re.fullmatch(
        r"view: of \d+ plan samples missed 0 commands, 0 states, 0 C_l and \d+ tap samples; "
        r"drew \d+ of \d+ Cp frames \(\d+\.\d\d % missed\)",
        report,
    ), report
    # The C_l–α legend names each series; the last blueprint has views for every level.
    legend = rrd.static["/cl_alpha/legend"][-1]["Points2D:labels"]
    assert legend == [mm.MEASURED, *(m for m in mm.MODELS if m in fitted), "live trail"], legend
    views = rrd.blueprints[-1]
    for label in model[mm.LEVELS]:
        assert any(v.startswith(f"FRF level {label} [dB]") for v in views), views
        assert any(v.startswith(f"Clusters level {label}:") for v in views), views


def test_pnlss_beats_linear_state_space_at_highest_offset(campaign) -> None:
    run, _ = campaign
    level1 = _tables((run / "table1_level1.md").read_text())
    main = _tables((run / "table1_all_levels.md").read_text())
    high = [col for (_, col) in main if col.startswith("high")]
    assert high
    for col in high:
        # The paper's comparison: BLA SS trained on level 1 vs the PNLSS model.
        assert main[("PNLSS", col)] * 3 <= level1[("BLA SS", col)], (col, main, level1)
        # And it beats the linear model of the high level itself.
        assert main[("PNLSS", col)] < main[("BLA SS", col)], (col, main)


def test_offline_fit_gives_the_same_table(campaign, tmp_path: Path) -> None:
    run, _ = campaign
    proc = _aero_rig(
        "fit", str(run / "bag"), "--out", str(tmp_path / "fit"), env=graph_env(), timeout=600
    )
    assert proc.returncode == 0, proc.stderr
    # The fit used the parameters recorded with the run, not the defaults.
    assert "as recorded with the run" in proc.stderr and "overrides: none" in proc.stderr
    recorded = json.loads((run / "models.json").read_text())["config"]
    assert json.loads((tmp_path / "fit" / "models.json").read_text())["config"] == recorded
    online = (run / "table1_all_levels.md").read_text().strip()
    offline = (tmp_path / "fit" / "table1_all_levels.md").read_text().strip()
    assert online == offline
    assert (run / "table1_level1.md").read_text().strip() == (
        tmp_path / "fit" / "table1_level1.md"
    ).read_text().strip()


FIT_ACCOUNT_ONLY = ("--no-scan", "--no-clustering-ablation")


def test_fit_of_bag_with_a_damaged_file_warns_and_fits(campaign, tmp_path: Path) -> None:
    """A file of the bag lost its second half and footer (a disk error, a copy cut short): the
    fit reads the rest with a warning, lists the samples that are missing because of it and
    fails unless that is accepted."""
    run, _ = campaign
    bag = tmp_path / "damaged"
    shutil.copytree(run / "bag", bag)
    largest = max(bag.glob("*.mcap"), key=lambda p: p.stat().st_size)  # it holds stream data
    data = largest.read_bytes()
    largest.write_bytes(data[: len(data) // 2])
    # What is checked is the bag's account, not the models: no scan, no ablation.
    fit = ("fit", str(bag), "--out", str(tmp_path / "fit"), *FIT_ACCOUNT_ONLY)
    proc = _aero_rig(*fit, env=graph_env(), timeout=600)
    # What the damage cost is listed, and the fit fails unless that is accepted explicitly.
    assert proc.returncode == 3, proc.stderr
    assert "warning" in proc.stderr and "damaged" in proc.stderr
    assert "last readable time" in proc.stderr  # the recorder's receive time of the last chunk
    assert "DATA NOT CLEAN" in proc.stdout and "plan samples missing" in proc.stdout
    proc = _aero_rig(*fit, "--allow-excluded", env=graph_env(), timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "fit" / "table1_all_levels.md").exists()


@pytest.mark.timeout(900)  # the starved run shares two cores with four busy processes
def test_starved_campaign_is_lossless_and_gives_the_same_table(
    small_campaign, starved_campaign
) -> None:
    run, proc = starved_campaign
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "data clean" in proc.stdout
    assert_lossless_and_identical(run, small_campaign[0])


@pytest.mark.timeout(900)
def test_nodes_paused_in_turn_lose_nothing(
    small_plan: Path, small_campaign, tmp_path: Path
) -> None:
    """SIGSTOP/SIGCONT of each stream node in turn for 3 s mid-run: the credit stalls the
    stream, reliable keep-all delivery holds what is in flight, nothing is lost or changed.
    (docs/known_issues.md: what is known of pauses on rclpy)."""
    run = tmp_path / "run"
    args = ("--plan", str(small_plan), *WING, "--quiet", *TIMEOUT_600)
    code, out, err, paused = campaign_paused_in_turn(args, run, graph_env())
    assert len(paused) >= 4, f"the run ended before most pauses: {paused}"
    assert code == 0, out[-3000:] + err[-3000:]
    assert_lossless_and_identical(run, small_campaign[0])


def _campaign_with_fault(
    run: Path, log: str, text: str, node: str, fault: Any, *extra: str, plan: str = "short"
) -> tuple[int, str, str]:
    """The campaign of ``plan`` into ``run``; ``fault(process of node)`` once
    ``logs/<log>.log`` holds ``text``. Its exit code and output."""
    proc = start_session(
        [*CLI, "campaign", "--plan", plan, *extra, "--out", str(run), "--quiet", *TIMEOUT_600],
        graph_env(),
    )
    try:
        path = run / "logs" / f"{log}.log"
        assert wait_for(lambda: path.exists() and text in path.read_text(), 300)
        target = node_process(proc.pid, node)
        assert target is not None
        fault(target)
    finally:
        out, err = finish(proc, 600)
    return proc.returncode, out, err


def _assert_recovered_as_idle(run: Path, reference: Path, out: str) -> dict[str, Any]:
    """The final identification recovered from a whole bag: Table 1 byte-identical to the idle
    run's. campaign.json."""
    assert "final identification recovered from the bag" in out, out[-3000:]
    summary: dict[str, Any] = json.loads((run / "campaign.json").read_text())
    assert summary["recovered_from_bag"]["clean"] and summary["clean"]
    for name in ("table1_all_levels.md", "table1_level1.md", "table1_no_clustering.md"):
        assert (run / name).read_bytes() == (reference / name).read_bytes(), name
    return summary


@pytest.mark.timeout(900)
def test_identifier_paused_past_the_lease_is_recovered_from_the_bag(
    small_plan: Path, small_campaign, tmp_path: Path
) -> None:
    """The identifier stopped (SIGSTOP) past the DDS participant lease right after the start
    barrier: the writers drop it and what it did not take. The campaign does not wait for
    ever: the identifier stalls or finishes short of samples, the final identification is
    recovered from the bag, exit 0, Table 1 byte-identical to the idle run (issue 21).
    The small plan at twice real time (34 s) outlasts the pause (25 s), so the identifier
    runs again before the plan's end, as on the short plan."""
    run = tmp_path / "run"
    code, out, err = _campaign_with_fault(
        run,
        "generator",
        "start barrier passed",
        "identifier",
        lambda target: pause(target, PARTICIPANT_LEASE_S + 5.0),
        *WING,
        *("--real-time-factor", "2"),
        plan=str(small_plan),
    )
    assert code == 0, out[-3000:] + err[-3000:]
    _assert_recovered_as_idle(run, small_campaign[0], out)


@pytest.mark.timeout(600)
def test_a_stream_node_stopped_for_good_ends_the_run_at_the_stall_bound_naming_it(
    tmp_path: Path,
) -> None:
    """The lift stopped (SIGSTOP) mid-run and never resumed: the generator's credit stops, the
    campaign ends at its stall bound (lease + 2 status periods, not its timeout), names the
    stall and the stopped process, fits what the bag holds and exits 3; no process is left
    (the stop resumes the stopped node so that it handles its SIGINT)."""
    run = tmp_path / "run"
    stopped: list[tuple[float, list[Any]]] = []

    def stop_for_good(target: Any) -> None:
        # the campaign's processes (the node's parent is the campaign): all gone at the end
        stopped.append((time.monotonic(), descendants(target.ppid())))
        target.suspend()

    code, out, err = _campaign_with_fault(
        run, "identifier", "realization 0 complete", "lift", stop_for_good
    )
    ended_after = time.monotonic() - stopped[0][0]
    assert code == 3, out[-3000:] + err[-3000:]
    bound = PARTICIPANT_LEASE_S + 2.0
    assert "stream stalled before the plan's end" in err and "timeout after" not in err
    assert re.search(r"stopped \(SIGSTOP, job control or a debugger\): lift \(\d+ s\)", err), err
    assert bound <= ended_after, ended_after  # never before the bound (the bench times the rest)
    # the flow reports at the stall: the lift silent since it was stopped, the others heard
    assert re.search(r"no flow report from /lift \(for (\d+) s\)", err), err
    summary = json.loads((run / "campaign.json").read_text())
    assert summary["recovered_from_bag"] and not summary["clean"]
    state = summary["flow_at_stall"]
    assert state["/lift"]["heard_s_ago"] >= bound - 1.0, state
    assert all(state[n]["heard_s_ago"] < 2.0 for n in ("/generator", "/identifier")), state
    commands = state["/generator"]["endpoints"]["writer /pitch/command"]
    assert commands["count"] > 0 and commands["last"].startswith("sample "), state
    assert "the plan did not run to its end" in out
    assert all(process_gone(c) for c in stopped[0][1])


@pytest.mark.timeout(600)
def test_identifier_killed_in_its_final_identification_is_recovered_from_the_bag(
    small_plan: Path, small_campaign, tmp_path: Path
) -> None:
    """kill -9 of the identifier after the plan's end, before its final identification is
    done: the graph stops, the bag holds the whole plan, so the campaign runs the final
    identification from it: exit 0, Table 1 byte-identical to the idle run, the recovery and
    its reason said. The identifier's worker is held (SIGSTOP) in the final models' fit, which
    starts before the plan's end, so the kill comes while the final identification waits for
    it, however fast the machine."""
    run = tmp_path / "run"

    def hold_the_fit_then_kill(identifier: Any) -> None:
        (worker,) = [c for c in identifier.children() if "spawn_main" in " ".join(c.cmdline())]
        worker.suspend()
        try:
            log = run / "logs" / "identifier.log"
            assert wait_for(lambda: "final identification's data are in" in log.read_text(), 300)
            identifier.kill()
        finally:
            worker.kill()

    code, out, err = _campaign_with_fault(
        run,
        "identifier",
        "[final models]",
        "identifier",
        hold_the_fit_then_kill,
        *WING,
        plan=str(small_plan),
    )
    assert code == 0, out[-3000:] + err[-3000:]
    assert "node 'identifier' exited with code -9" in out + err
    summary = _assert_recovered_as_idle(run, small_campaign[0], out)
    assert summary["exit_codes"]["identifier"] == -9


def test_fit_of_bag_without_needed_topics_names_them(tmp_path: Path) -> None:
    from rig_runtime.bag import BagWriter
    from rig_runtime.messages import new_message, serialize

    bag = tmp_path / "partial"
    writer = BagWriter(bag)
    conn = writer.add_connection(PITCH_STATE.name, "sensor_msgs/msg/JointState")
    writer.write(conn, 1, serialize(new_message("sensor_msgs/msg/JointState", position=[0.1])))
    writer.close()
    proc = _aero_rig("fit", str(bag), env=graph_env(), timeout=120)
    assert proc.returncode == 2
    assert EXPERIMENT_PLAN.name in proc.stderr and WING_COEFFICIENTS.name in proc.stderr


def test_killing_the_identifier_stops_the_campaign_with_a_clear_error(tmp_path: Path) -> None:
    import psutil

    run = tmp_path / "run"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "aero_rig.cli",
            "campaign",
            "--plan",
            "short",
            "--out",
            str(run),
            "--quiet",
            "--real-time-factor",
            "5",
        ],
        env=graph_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:

        def identifier() -> psutil.Process | None:
            for child in descendants(proc.pid):
                try:
                    if "identifier_node" in " ".join(child.cmdline()):
                        return child
                except psutil.Error:
                    continue
            return None

        # Killed once streaming has begun: the plan is out, so the bag holds messages.
        log = run / "logs" / "generator.log"
        assert wait_for(lambda: log.exists() and "start barrier passed" in log.read_text(), 120)
        target = identifier()
        assert target is not None
        workers = target.children(recursive=True)  # its refit worker
        assert workers
        target.kill()
    finally:
        _, err = finish(proc, 120)
    assert proc.returncode != 0
    assert re.search(r"node 'identifier' exited with code -9", err), err
    # The refit worker does not outlive its node, even killed with SIGKILL.
    assert wait_for(lambda: all(process_gone(w) for w in workers), 10), workers
    with AnyReader([run / "bag"]) as reader:  # the bag up to the failure is readable
        counts = {c.topic: 0 for c in reader.connections}
        for conn, _, raw in reader.messages():
            reader.deserialize(raw, conn.msgtype)  # every message decodes
            counts[conn.topic] += 1
    # The plan, and the streaming that had begun when the identifier was killed.
    assert counts.get("/experiment/plan", 0) >= 1, counts
    assert counts.get("/pitch/command", 0) >= 1 and counts.get("/pitch/state", 0) >= 1, counts


def test_sigterm_stops_the_campaign_and_every_node_and_keeps_the_bag(tmp_path: Path) -> None:
    """A job scheduler's `kill`: the graph is stopped like on Ctrl-C, nothing is left running."""
    import psutil

    run = tmp_path / "run"
    proc = start_session(
        [*CLI, "campaign", "--plan", "short", "--out", str(run), "--quiet", *RTF5],
        graph_env(),
    )
    nodes: list[psutil.Process] = []
    try:
        # Stopped once streaming has begun: the plan is out, so the bag holds messages.
        log = run / "logs" / "generator.log"
        assert wait_for(lambda: log.exists() and "start barrier passed" in log.read_text(), 120)
        nodes = descendants(proc.pid)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        for p in [*nodes, *([psutil.Process(proc.pid)] if proc.poll() is None else [])]:
            try:
                p.kill()
            except psutil.Error:
                pass
        proc.wait(timeout=30)

    assert proc.returncode == 1
    assert "campaign failed: stopped by SIGTERM" in err, err
    assert wait_for(lambda: all(process_gone(p) for p in nodes), 30), [p.cmdline() for p in nodes]
    with AnyReader([run / "bag"]) as reader:  # finalised by the recorder on its SIGINT
        assert reader.message_count > 0


@pytest.fixture(scope="module")
def adaptive_campaign(
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[Path, subprocess.CompletedProcess[str]]:
    run = tmp_path_factory.mktemp("adaptive") / "run"
    proc = _aero_rig(
        *("campaign", "--plan", "short", "--adaptive", *WING, "--out", str(run), "--quiet"),
        *("--rerun", "save"),
        *TIMEOUT_600,
        env=graph_env(),
        timeout=700,
    )
    return run, proc


def _bag_plans_and_commands(bag: Path) -> tuple[list[Any], list[dict[str, Any]], np.ndarray]:
    """The bag's /experiment/plan revisions, its decision events and its commands [deg]."""
    plans, decisions, commands = [], [], []
    with AnyReader([bag]) as reader:
        conns = [
            c
            for c in reader.connections
            if c.topic in (EXPERIMENT_PLAN.name, EXPERIMENT_SEGMENT.name, PITCH_COMMAND.name)
        ]
        for conn, _, raw in reader.messages(connections=conns):
            msg: Any = reader.deserialize(raw, conn.msgtype)
            if conn.topic == EXPERIMENT_PLAN.name:
                plans.append(read_plan_message(msg)[0])
            elif conn.topic == EXPERIMENT_SEGMENT.name:
                event = segment_event_from_message(msg)
                if event.get("event") in ("decision", "refused"):
                    decisions.append(event)
            else:
                commands.append((stamp_to_ns(msg.header.stamp), np.degrees(msg.position[0])))
    commands.sort()
    return plans, decisions, np.array([c[1] for c in commands])


def test_adaptive_campaign_is_clean_and_its_bag_reproduces_the_executed_plan(
    adaptive_campaign, tmp_path: Path
) -> None:
    run, proc = adaptive_campaign
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "adaptive run: multisine time" in proc.stdout
    account = json.loads((run / "models.json").read_text())["experiment"]
    # The low level converges at the floor of periods (its noise is ~ -31 dB of |G|^2 after
    # two); the executed plan is shorter than the planned one.
    assert account["revision"] >= 1
    assert account["levels"]["low"]["executed_periods"] == [2, 2]
    assert account["multisine_executed_s"] < account["multisine_planned_s"]
    plans, decisions, commands = _bag_plans_and_commands(run / "bag")
    # /experiment/control is a service: the generator records each request it answered, with
    # what it did, as a decision or refused event on /experiment/segment.
    assert {d["request"] for d in decisions} >= {"go_on", "end_realization"}
    for d in decisions:  # requests of the identifier (aero_identification): none malformed
        assert isinstance(d["level"], int) and isinstance(d["after_k"], int), d
        assert isinstance(d["at_k"], int) and isinstance(d["reason"], str), d
    executed = max(plans, key=lambda p: p.revision)
    assert executed.revision == account["revision"] == plans[-1].revision
    # Every revision has its decision event, with the request's reason; every sample the
    # generator sent is the executed plan's, and the bag holds them all.
    changes = [d for d in decisions if d["event"] == "decision" and d.get("change")]
    assert [d["revision"] for d in changes] == list(range(1, executed.revision + 1))
    assert all(d["reason"] for d in changes)
    assert len(commands) == executed.total_samples
    np.testing.assert_allclose(commands, executed.command_deg(), atol=1e-9)
    # The view shows every decision, in order, on its events log.
    from aero_rig.view import describe_segment
    from aero_rig.view.readback import Rrd

    shown = [t[0] for t in Rrd(run / "campaign.rrd").column("/events/adaptive", "TextLog:text")]
    assert shown == [describe_segment(d) for d in decisions]
    assert sum(" -> revision " in line for line in shown) == executed.revision
    # The bag alone gives the campaign's report: the same tables, the same account.
    fit = _aero_rig("fit", str(run / "bag"), "--out", str(tmp_path / "fit"), env=graph_env(),
                    timeout=600)  # fmt: skip
    assert fit.returncode == 0, fit.stderr
    for name in ("table1_all_levels.md", "table1_level1.md"):
        assert (run / name).read_text().strip() == (tmp_path / "fit" / name).read_text().strip()
    offline = json.loads((tmp_path / "fit" / "models.json").read_text())["experiment"]
    assert offline == account
