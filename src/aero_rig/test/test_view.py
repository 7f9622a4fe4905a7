"""The Rerun view: logger on plain messages, bag replay to .rrd, and the node over DDS.

Recordings are written to files only (never a viewer) and read back with
``rerun.chunk.RrdReader`` (rerun 0.41; ``rerun.dataframe`` is gone), so the assertions are on
what a viewer would load: entity paths, timeline stamps, values and the blueprint's views.
"""

import json
import math
import os
import re
import signal
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from aero_identification import model_payload as mm
from aero_rig import view as rig_view
from aero_rig.view.readback import Rrd
from multisine_gen.plan_format import segment_event_fields
from pressure_scanner.tap_cloud import fill_cloud
from pressure_scanner.taps import load_taps
from pressure_scanner.wing_geometry import RigGeometry
from rig_runtime.interface import (
    EXPERIMENT_SEGMENT,
    IDENTIFICATION_MODEL,
    IDENTIFICATION_STATUS,
    PITCH_COMMAND,
    PITCH_JOINT,
    PITCH_STATE,
    PRESSURE_TAPS,
    WING_COEFFICIENTS,
)
from rig_runtime.messages import new_message, serialize, set_stamp, typestore
from rig_runtime.node import Node
from rig_testing.processes import Processes, graph_env, join_graph, wait_for

T0 = 1_700_000_000_000_000_000  # ns
NEW_MODEL = "a model added later"
FS = 200.0
N = 200  # samples (1 s)
NAN_CL_K = 57  # this coefficients sample is invalid (NaN)
NAN_TAP_K = 20  # this taps sample has a missing tap (a logged one: 20 % 10 == 0)
Q = RigGeometry().dynamic_pressure_pa
CHORD = RigGeometry().chord_m
TAPS = load_taps(None)
STRING = "std_msgs/msg/String"  # the events' and models' type in bags recorded before


def stamp(k: int) -> int:
    return T0 + round(k * 1e9 / FS)


def alpha_deg(k: int) -> float:
    return 6.6 + 2.4 * math.sin(2 * math.pi * 1.0 * k / FS)


def cp_true() -> np.ndarray:
    """A made-up Cp per tap, distinct on each surface: upper −2(1−x/c), lower 0.5(1−x/c)."""
    x = TAPS.x_c
    return np.where(TAPS.side > 0, -2.0 * (1 - x), np.where(TAPS.side < 0, 0.5 * (1 - x), 1.0))


def model_json(refit: int, predictions: list[str], k: int) -> str:
    freq = [0.02, 0.06, 0.10, 0.14]
    labels = [[0, 0], [1, 0], [0, 0]] if k == 2 else [[0, 0], [0, 0], [0, 0]]
    g = np.array([6.0, 5.0 - 1j, 4.0 - 2j, 3.0 - 2j])
    levels: dict[str, Any] = {
        "0": {
            "offset_deg": 6.6,
            "bla": {
                "freq_hz": freq,
                "G_re": g.real.tolist(),
                "G_im": g.imag.tolist(),
                "var_noise": [1e-4, 1e-4, 2e-4, 1e-3],
                "var_total": [1e-3] * 4,
                "var_nl": [1e-3, 1e-2, -1e-4, None],  # not positive / missing: no bar
            },
            "clusters": {"labels": labels, "k": k, "dominant": 0},
        },
        "2": {"offset_deg": 19.9, "bla": {"freq_hz": freq[:2], "G_re": [1, 1], "G_im": [0, 0]}},
    }
    # The pipeline's keys (model_payload); BLA SS has a gap (a non-finite value), and a model
    # the view has no colour for is drawn as well.
    preds = [
        {
            mm.NAME: name,
            mm.ALPHA_DEG: [5.0, 6.0, 7.0, 8.0],
            mm.series_key(mm.MEASURED): [0.5, 0.6, 0.7, 0.8],
            mm.series_key(mm.BLA_SS_OWN): [0.5, 0.61, None, 0.8],
            mm.series_key(mm.PNLSS_ALL): [0.5, 0.6, 0.71, 0.8],
            mm.series_key(NEW_MODEL): [0.4, 0.5, 0.6, 0.7],
        }
        for name in predictions
    ]
    model = {
        "refit": refit,
        "stamp_ns": stamp(100 * refit),
        "levels": levels,
        "predictions": preds,
        "table1": {"markdown": f"| model | 1 Hz |\n|---|---|\n| PNLSS | 0.0{refit} |"},
    }
    return json.dumps(model)


def status_msg(k: int, message: str) -> Any:
    msg = new_message("diagnostic_msgs/msg/DiagnosticArray")
    set_stamp(msg.header.stamp, stamp(k))
    msg.status = [
        new_message(
            "diagnostic_msgs/msg/DiagnosticStatus",
            level=1,
            name="identifier",
            message=message,
            values=[new_message("diagnostic_msgs/msg/KeyValue", key="periods", value="3")],
        )
    ]
    return msg


def segment_msg(event: dict[str, Any], t_ns: int, legacy: bool = False) -> Any:
    """The /experiment/segment message of an event payload: a SegmentEvent stamped ``t_ns``,
    or (``legacy``) the std_msgs/String JSON of a bag recorded before SegmentEvent existed."""
    if legacy:
        return new_message(STRING, data=json.dumps(event))
    msg = new_message(EXPERIMENT_SEGMENT.type, **segment_event_fields(event))
    set_stamp(msg.header.stamp, t_ns)
    return msg


def model_msg(text: str, legacy: bool = False) -> Any:
    """The /identification/model message of a model record's JSON: an IdentificationModel with
    it in ``model_json`` (its refit beside it when there is one), or (``legacy``) a String."""
    if legacy:
        return new_message(STRING, data=text)
    try:
        refit = json.loads(text).get("refit", 0)
    except (ValueError, AttributeError):
        refit = 0  # a broken record: only its JSON matters to the view
    return new_message(IDENTIFICATION_MODEL.type, refit=int(refit), model_json=text)


def messages(legacy: bool = False) -> list[tuple[int, str, Any]]:
    """(receive time ns, topic, message) of a 1 s run with events, two models and status;
    ``legacy``: events and models as the std_msgs/String JSON of a bag recorded before the rig
    had its own messages."""
    out: list[tuple[int, str, Any]] = []
    xyz = TAPS.xyz_m(CHORD, 0.54)
    for k in range(N):
        t = stamp(k)
        rad = math.radians(alpha_deg(k))
        for topic in (PITCH_COMMAND.name, PITCH_STATE.name):
            msg = new_message("sensor_msgs/msg/JointState", name=[PITCH_JOINT], position=[rad])
            set_stamp(msg.header.stamp, t)
            out.append((t, topic, msg))
        pressures = Q * cp_true()
        if k == NAN_TAP_K:
            pressures[5] = np.nan
        cloud = fill_cloud(new_message("sensor_msgs/msg/PointCloud2"), new_message, xyz, pressures)
        set_stamp(cloud.header.stamp, t)
        out.append((t + 1, PRESSURE_TAPS.name, cloud))
        coeff = new_message("geometry_msgs/msg/Vector3Stamped")
        coeff.vector.x = math.nan if k == NAN_CL_K else 0.104 * alpha_deg(k)
        set_stamp(coeff.header.stamp, t)
        out.append((t + 2, WING_COEFFICIENTS.name, coeff))
    for k, event in (
        (0, {"event": "start", "kind": "multisine", "level": 0, "realization": 1, "period": 2}),
        (N - 1, {"event": "end", "kind": "multisine", "level": 0, "realization": 1, "period": 2}),
        (N - 1, {"event": "plan_end", "samples": N, "t0_ns": T0, "fs": FS}),
    ):
        edge = {"start": "start_stamp_s", "end": "end_stamp_s"}
        if event["event"] in edge:
            event[edge[event["event"]]] = stamp(k) / 1e9
        out.append((stamp(k), EXPERIMENT_SEGMENT.name, segment_msg(event, stamp(k), legacy)))
    first = model_json(1, ["sine level 0 1.0 Hz", "sine level 0 0.4 Hz"], 2)
    second = model_json(2, ["sine level 0 1.0 Hz"], 1)  # one prediction, one cluster fewer
    out.append((stamp(100), IDENTIFICATION_MODEL.name, model_msg(first, legacy)))
    out.append((stamp(199), IDENTIFICATION_MODEL.name, model_msg(second, legacy)))
    for k, text in ((50, "buffering"), (60, "buffering"), (70, "refit 1 done")):
        out.append((stamp(k), IDENTIFICATION_STATUS.name, status_msg(k, text)))
    out.sort(key=lambda item: item[0])
    return out


def write_bag(path: Path, storage: StoragePlugin, legacy: bool = False) -> None:
    with Writer(path, version=9, storage_plugin=storage) as writer:
        connections: dict[str, Any] = {}
        for t, topic, msg in messages(legacy):
            if topic not in connections:
                connections[topic] = writer.add_connection(
                    topic, msg.__msgtype__, typestore=typestore()
                )
            writer.write(connections[topic], t, serialize(msg))


# -- reading a recording back ----------------------------------------------------------------


EXPECTED_ENTITIES = {
    "/series/pitch/command",
    "/series/pitch/measured",
    "/series/cl",
    "/cp/upper",
    "/cp/lower",
    "/cp/taps",
    "/cl_alpha/live",
    "/frf/level_0/G_dB",
    "/frf/level_0/noise_dB",
    "/frf/level_0/nl_distortion_dB",
    "/frf/level_2/G_dB",
    "/clusters/level_0/cluster_0",
    "/clusters/level_0/cluster_1",
    "/cl_alpha/predictions/sine_level_0_1_0_hz/measured",
    "/cl_alpha/predictions/sine_level_0_1_0_hz/bla_ss_own_level",
    "/cl_alpha/predictions/sine_level_0_1_0_hz/pnlss_all_levels",
    "/cl_alpha/predictions/sine_level_0_1_0_hz/a_model_added_later",
    "/cl_alpha/predictions/sine_level_0_0_4_hz/pnlss_all_levels",
    "/model/table1",
    "/model/summary",
    "/events/segment",
    "/events/model",
    "/events/status",
    "/events/view",
}


@pytest.mark.parametrize(
    ("storage", "legacy"),
    [(StoragePlugin.MCAP, False), (StoragePlugin.SQLITE3, False), (StoragePlugin.MCAP, True)],
    ids=["mcap", "sqlite3", "mcap-string"],
)
def test_view_bag_writes_every_view_of_the_run(
    tmp_path: Path, storage: StoragePlugin, legacy: bool
) -> None:
    """Every view of a bag of the rig's messages; ``legacy``: of a bag recorded before them,
    its segment events and models std_msgs/String JSON, drawn the same."""
    bag = tmp_path / "run"
    write_bag(bag, storage, legacy)
    out = rig_view.view_bag(bag)
    assert out == tmp_path / "run.rrd" and out.stat().st_size > 0
    rrd = Rrd(out)
    assert EXPECTED_ENTITIES <= set(rrd.rows), EXPECTED_ENTITIES - set(rrd.rows)
    assert {"/cp/axes", "/cl_alpha/axes"} <= set(rrd.static)

    # Pitch in degrees at the message stamps, every sample.
    stamps = np.array([stamp(k) for k in range(N)])
    degs = np.array([alpha_deg(k) for k in range(N)])
    for entity in ("/series/pitch/command", "/series/pitch/measured"):
        times, values = rrd.scalars(entity)
        np.testing.assert_array_equal(times, stamps)
        np.testing.assert_allclose(values, degs, rtol=0, atol=1e-9)
    # The NaN C_l sample is a gap, not a value.
    times, values = rrd.scalars("/series/cl")
    np.testing.assert_array_equal(times, np.delete(stamps, NAN_CL_K))
    np.testing.assert_allclose(values, 0.104 * np.delete(degs, NAN_CL_K), atol=1e-12)

    # Cp every 10th sample: x = 4·x/c, y = Cp (−Cp up), each surface from the leading edge.
    strips = rrd.column("/cp/upper", "LineStrips2D:strips")
    assert len(strips) == N // 10
    cp = cp_true()
    upper = np.flatnonzero(TAPS.side >= 0)
    upper = upper[np.argsort(TAPS.x_c[upper])]
    first = np.array(strips[0][0])
    assert len(strips[0]) == 1 and first.shape == (25, 2)
    np.testing.assert_allclose(first[:, 0], rig_view.CP_X_SCALE * TAPS.x_c[upper], atol=1e-5)
    np.testing.assert_allclose(first[:, 1], cp[upper], atol=1e-5)
    lower = np.array(rrd.column("/cp/lower", "LineStrips2D:strips")[0][0])
    assert lower.shape == (25, 2) and np.all(lower[1:, 1] > 0)  # lower surface: Cp > 0 here
    # The sample with a missing tap: its point is left out, not drawn at a made-up value.
    taps_rows = rrd.rows["/cp/taps"]
    counts = {r[rig_view.TIMELINE]: len(r["Points2D:positions"]) for r in taps_rows}
    assert counts[stamp(NAN_TAP_K)] == 48 and counts[stamp(0)] == 49

    # FRF of the latest model: |G| dB at the lines, variances in dB beside them.
    f, gdb = rrd.bars("/frf/level_0/G_dB")
    g = np.array([6.0, 5.0 - 1j, 4.0 - 2j, 3.0 - 2j])
    np.testing.assert_allclose(f, [0.02, 0.06, 0.10, 0.14])
    np.testing.assert_allclose(gdb, 20 * np.log10(np.abs(g)))
    f, ndb = rrd.bars("/frf/level_0/noise_dB")
    np.testing.assert_allclose(f, np.array([0.02, 0.06, 0.10, 0.14]) - 0.01)
    np.testing.assert_allclose(ndb, 10 * np.log10([1e-4, 1e-4, 2e-4, 1e-3]))
    f, nldb = rrd.bars("/frf/level_0/nl_distortion_dB")
    np.testing.assert_allclose(f, [0.03, 0.07])
    np.testing.assert_allclose(nldb, [-30.0, -20.0])
    # Clusters: periods in time order (realization 0: 1..3, realization 1: 4..6).
    first_model = stamp(100)
    x0, h0 = rrd.bars("/clusters/level_0/cluster_0", 0)
    x1, h1 = rrd.bars("/clusters/level_0/cluster_1", 0)
    np.testing.assert_array_equal(x0, [1, 3, 4, 5, 6])
    np.testing.assert_array_equal(x1, [2])
    assert np.all(h0 == 1.0) and np.all(h1 == 0.6)  # dominant cluster is taller
    # The models' C_l–α predictions: (α, −10·C_l), the missing BLA value breaks the line.
    pred = "/cl_alpha/predictions/sine_level_0_1_0_hz"
    measured = np.array(rrd.column(f"{pred}/measured", "LineStrips2D:strips")[0][0])
    np.testing.assert_allclose(measured, [[5, -5], [6, -6], [7, -7], [8, -8]], atol=1e-5)
    assert len(rrd.column(f"{pred}/bla_ss_own_level", "LineStrips2D:strips")[0]) == 1  # 2 kept
    # Each model in its colour, named in the C_l–α view's legend; the new model in a spare one.
    for model, color in (*rig_view.PREDICTION_COLORS[:2], (NEW_MODEL, rig_view.SPARE_COLORS[0])):
        colors = rrd.column(f"{pred}/{rig_view.slug(model)}", "LineStrips2D:colors")
        assert colors[0] == [int.from_bytes(bytes([*color, 255]), "big")], model
    (legend,) = rrd.static["/cl_alpha/legend"][-1:]
    names = [mm.MEASURED, mm.BLA_SS_OWN, mm.PNLSS_ALL, NEW_MODEL, "live trail"]
    assert legend["Points2D:labels"] == names
    colors = [*dict(rig_view.PREDICTION_COLORS).values()]
    expected = [colors[0], colors[1], colors[3], rig_view.SPARE_COLORS[0], (44, 160, 44)]
    assert legend["Points2D:colors"] == [int.from_bytes(bytes([*c, 255]), "big") for c in expected]
    # Each gap is named once on the view's log, with its field, though both models carried the
    # 1 Hz one.
    warnings = [t[0] for t in rrd.column("/events/view", "TextLog:text")]
    gaps = [w for w in warnings if mm.series_key(mm.BLA_SS_OWN) in w]
    assert gaps == [
        f"/identification/model: predictions[sine level 0 {f} Hz]."
        f"{mm.series_key(mm.BLA_SS_OWN)}: 1 of 4 values not finite"
        for f in ("1.0", "0.4")
    ]
    # The second model dropped a prediction and a cluster: both are cleared at its stamp.
    second_model = stamp(200)
    for entity in (
        "/cl_alpha/predictions/sine_level_0_0_4_hz/pnlss_all_levels",
        "/clusters/level_0/cluster_1",
    ):
        cleared = [r for r in rrd.rows[entity] if r.get("Clear:is_recursive") is not None]
        assert [r[rig_view.TIMELINE] for r in cleared] == [second_model], entity
    assert rrd.rows["/frf/level_0/G_dB"][0][rig_view.TIMELINE] == first_model
    table = rrd.column("/model/table1", "TextDocument:text")
    assert [t[0] for t in table] == [
        "## Table 1, models of all levels\n\n| model | 1 Hz |\n|---|---|\n| PNLSS | 0.01 |",
        "## Table 1, models of all levels\n\n| model | 1 Hz |\n|---|---|\n| PNLSS | 0.02 |",
    ]

    # Events: segment edges at their own stamps, status only when it changes.
    segs = rrd.rows["/events/segment"]
    texts = [r["TextLog:text"][0] for r in segs]
    assert texts[0] == "start multisine level 0 realization 1 period 2"
    assert texts[1].startswith("end multisine") and texts[2].startswith("plan_end")
    assert segs[0][rig_view.TIMELINE] == stamp(0)
    status = [r["TextLog:text"][0] for r in rrd.rows["/events/status"]]
    assert status == [
        "identifier: buffering (periods=3)",
        "identifier: refit 1 done (periods=3)",
    ]
    assert rrd.column("/events/status", "TextLog:level")[0] == ["WARN"]

    # The blueprint got one FRF and one cluster tab per level once the model named them.
    assert "C_l" in rrd.view_names
    for head in ("Pitch [deg]", "FRF level 0 [dB]", "FRF level 2 [dB]", "Clusters level 0:"):
        assert any(v.startswith(head) for v in rrd.view_names), (head, rrd.view_names)
    # Opened with no clicks, every blueprint's time cursor follows the newest data (so a
    # finished recording shows its end state; PlayState 3 is "following", PanelState 2
    # "collapsed": the play bar without the streams tree).
    following = {"timeline": rig_view.TIMELINE, "play_state": 3, "state": 2}
    assert rrd.time_panels and all(panel == following for panel in rrd.time_panels)
    # What the view received against the plan_end event's samples: nothing missed.
    (report,) = [w[0] for w in rrd.column("/events/view", "TextLog:text") if "plan" in w[0]]
    assert report == (
        f"view: of {N} plan samples missed 0 commands, 0 states, 0 C_l and 0 tap samples; "
        f"drew {N // 10} of {N // 10} Cp frames (0.00 % missed)"
    )


def test_logger_tolerates_early_models_and_rejects_garbage(tmp_path: Path) -> None:
    rec, where = rig_view.open_recording("test_view", "save", tmp_path / "early.rrd")
    assert "early.rrd" in where
    logger = rig_view.RigViewLogger(rec)
    logger.on_model(model_msg(json.dumps({"refit": 0})))
    logger.on_model(model_msg(json.dumps({"refit": 1, "levels": {"1": {}}})))
    # A model the view cannot wholly read: what is whole is drawn, the rest named once.
    broken = json.loads(model_json(2, ["sine level 0 1.0 Hz"], 2))
    del broken["stamp_ns"]  # at the time of the models before it
    broken["levels"]["0"]["bla"]["G_im"] = [0.0]  # 1 value for 4 frequencies
    broken["predictions"][0][mm.series_key(mm.PNLSS_ALL)] = [0.5, 0.6]  # 2 values for 4 angles
    broken["levels"]["3"] = {"offset_deg": "high", "bla": [1, 2], "clusters": "k = 2"}
    broken["data_quality"] = {"samples": ["pitch"]}
    for legacy in (False, True):  # the same record as an older bag's String: named once
        logger.on_model(model_msg(json.dumps(broken), legacy))
    for bad in ("not json", "[1, 2]"):
        for legacy in (False, True):
            with pytest.raises(ValueError, match="identification/model"):
                logger.on_model(model_msg(bad, legacy))
    with pytest.raises(ValueError, match="/experiment/segment: unknown event 'bogus'"):
        logger.on_segment(new_message(EXPERIMENT_SEGMENT.type, event="bogus"))
    with pytest.raises(ValueError, match="/experiment/segment is not valid JSON"):
        logger.on_segment(new_message(STRING, data="{"))
    rig_view.close_recording(rec)
    rrd = Rrd(tmp_path / "early.rrd")
    summaries = [t[0] for t in rrd.column("/model/summary", "TextDocument:text")]
    assert summaries[0].startswith("# Model refit 0") and "- level 1" in summaries[1]
    assert "/frf/level_1/G_dB" not in rrd.rows
    assert any(v.startswith("FRF level 1 [dB]") for v in rrd.view_names)
    model = "/identification/model"
    assert [t[0] for t in rrd.column("/events/view", "TextLog:text")] == [
        f"{model}: levels: missing",
        f"{model}: predictions: missing",
        f"{model}: table1: missing",
        f"{model}: levels.0.bla.G_im: 1 values for 4 frequencies",
        f"{model}: levels.3.offset_deg: not a number",
        f"{model}: levels.3.bla.freq_hz: missing or not numbers",
        f"{model}: levels.3.clusters.labels: not a periods x realizations table",
        f"{model}: predictions[sine level 0 1.0 Hz].{mm.series_key(mm.BLA_SS_OWN)}: "
        "1 of 4 values not finite",
        f"{model}: predictions[sine level 0 1.0 Hz].{mm.series_key(mm.PNLSS_ALL)}: "
        "2 values for 4 angles",
        f"{model}: data_quality: not an account of samples",
        f"{model}: levels.3: not drawn ('list' object has no attribute 'get')",
    ]
    assert "/frf/level_0/G_dB" not in rrd.rows and "/frf/level_2/G_dB" in rrd.rows
    assert "/cl_alpha/predictions/sine_level_0_1_0_hz/pnlss_all_levels" not in rrd.rows
    assert "/cl_alpha/predictions/sine_level_0_1_0_hz/measured" in rrd.rows


def test_series_go_in_batches_at_their_stamps_and_none_is_held_back(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Pitch and C_l samples wait in a buffer and go as one column per batch (send_columns):
    a full batch goes at once, send_series sends the rest, every sample once at its stamp."""
    rec, _ = rig_view.open_recording("test_view", "save", tmp_path / "batches.rrd")
    logger = rig_view.RigViewLogger(rec, series_batch=3)
    sent: list[tuple[str, int]] = []
    send_columns = rec.send_columns

    def spy(entity: str, indexes: Any, columns: Any) -> None:
        sent.append((entity, len(next(iter(indexes)).as_arrow_array())))
        send_columns(entity, indexes=indexes, columns=columns)

    monkeypatch.setattr(rec, "send_columns", spy)
    commands = [m for _, t, m in messages() if t == PITCH_COMMAND.name][:7]
    for msg in commands:
        logger.on_command(msg)
    assert sent == [("/series/pitch/command", 3), ("/series/pitch/command", 3)]
    logger.send_series()  # the node's timer: the seventh sample does not wait for a batch
    assert sent[2:] == [("/series/pitch/command", 1)]
    logger.send_series()  # nothing left: nothing sent twice
    assert len(sent) == 3
    with pytest.raises(ValueError, match="series_batch"):
        rig_view.RigViewLogger(rec, series_batch=0)
    rig_view.close_recording(rec)
    times, values = Rrd(tmp_path / "batches.rrd").scalars("/series/pitch/command")
    np.testing.assert_array_equal(times, [stamp(k) for k in range(7)])
    np.testing.assert_allclose(values, [alpha_deg(k) for k in range(7)], atol=1e-9)


def test_tap_samples_are_deserialized_only_when_logged(tmp_path: Path) -> None:
    """The view reads /pressure/taps serialized (a raw subscription, the bag's bytes) and
    deserializes only the samples it logs, every taps_decimation-th: bytes in between are
    counted, never read; a logged sample that is not a PointCloud2 is a ValueError naming the
    topic, and counted."""
    rec, _ = rig_view.open_recording("test_view", "save", tmp_path / "taps.rrd")
    logger = rig_view.RigViewLogger(rec, taps_decimation=10)
    clouds = [serialize(m) for _, t, m in messages() if t == PRESSURE_TAPS.name][:20]
    for k, cdr in enumerate(clouds):
        logger.on_taps_cdr(cdr if k % 10 == 0 else b"never read")
    assert logger.counts["taps"] == 20
    with pytest.raises(ValueError, match="/pressure/taps: not a sensor_msgs/msg/PointCloud2"):
        logger.on_taps_cdr(b"\x00\x01")  # the 21st sample is a logged one
    assert logger.counts["taps"] == 21
    rig_view.close_recording(rec)
    rows = Rrd(tmp_path / "taps.rrd").rows["/cp/taps"]
    assert [r[rig_view.TIMELINE] for r in rows] == [stamp(0), stamp(10)]
    assert all(len(r["Points2D:positions"]) == 49 for r in rows)


def test_view_reports_what_it_missed_inside_the_plan(tmp_path: Path) -> None:
    """The report counts, per stream, the plan's samples the view never got: samples outside
    the plan (the rig at rest before it) do not make up for lost ones."""
    rec, _ = rig_view.open_recording("test_view", "save", tmp_path / "missed.rrd")
    logger = rig_view.RigViewLogger(rec)
    before = new_message("sensor_msgs/msg/JointState", name=[PITCH_JOINT], position=[0.0])
    for k in range(-3, 0):  # three states before the plan's first sample
        set_stamp(before.header.stamp, stamp(k))
        logger.on_state(before)
    lost = {(PITCH_COMMAND.name, 5), (PITCH_COMMAND.name, 6), (PITCH_STATE.name, 7)}
    lost |= {(PRESSURE_TAPS.name, k) for k in range(30, 45)}  # it draws every 10th it gets
    handlers = {topic: getattr(logger, handler) for topic, (_, handler) in rig_view.TOPICS.items()}
    seen: dict[str, int] = defaultdict(int)
    for _, topic, msg in messages():
        k = seen[topic]
        seen[topic] += 1
        if (topic, k) in lost:
            continue
        handlers[topic](serialize(msg) if topic == PRESSURE_TAPS.name else msg)
    assert logger.report() == (
        f"view: of {N} plan samples missed 2 commands, 1 states, 0 C_l and 15 tap samples; "
        f"drew {N // 10 - 1} of {N // 10} Cp frames (5.00 % missed)"
    )
    rig_view.close_recording(rec)


def test_node_rejects_save_without_path_and_a_bad_mode(monkeypatch: pytest.MonkeyPatch) -> None:
    join_graph(graph_env(), monkeypatch.setenv)
    from aero_rig.view.node import main as view_main

    assert view_main(["--ros-args", "-p", "mode:=save"]) == 2
    assert view_main(["--ros-args", "-p", "mode:=movie"]) == 2


def test_view_node_records_what_it_receives_over_dds(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    env = graph_env()
    join_graph(env, monkeypatch.setenv)
    rrd_path = tmp_path / "live" / "view.rrd"
    topics = {
        PITCH_COMMAND.name: ("sensor_msgs/msg/JointState", "stream"),
        PITCH_STATE.name: ("sensor_msgs/msg/JointState", "stream"),
        PRESSURE_TAPS.name: ("sensor_msgs/msg/PointCloud2", "stream"),
        WING_COEFFICIENTS.name: ("geometry_msgs/msg/Vector3Stamped", "stream"),
        EXPERIMENT_SEGMENT.name: (EXPERIMENT_SEGMENT.type, "events"),
        IDENTIFICATION_MODEL.name: (IDENTIFICATION_MODEL.type, "latched"),
        IDENTIFICATION_STATUS.name: ("diagnostic_msgs/msg/DiagnosticArray", "latched"),
    }
    node = Node("test_view_publisher", argv=[])
    try:
        pubs = {t: node.create_publisher(ty, t, qos) for t, (ty, qos) in topics.items()}
        # Published before the view exists: the latched model must still reach it.
        model = next(m for _, t, m in messages() if t == IDENTIFICATION_MODEL.name)
        pubs[IDENTIFICATION_MODEL.name].publish(model)
        with Processes(env, log_dir=tmp_path) as procs:
            view = procs.start_python(
                "-m aero_rig.view",
                "--ros-args",
                "-p",
                "mode:=save",
                "-p",
                f"rrd_path:={rrd_path}",
                "-p",
                "stats_period_s:=0.2",
                name="view",
            )
            matched = node.spin_until(
                lambda: all(p.subscription_count() > 0 for p in pubs.values()), 20
            )
            assert matched, procs.log("view")
            # And the other way round: the view's best-effort readers drop what a writer sends
            # before they have matched it (seen under load: the first 16 samples of each stream).
            readers = f"matched={len(topics)}/{len(topics)}"
            assert wait_for(lambda: readers in procs.log("view"), 20), procs.log("view")
            streamed = [(t, m) for _, t, m in messages() if t not in (IDENTIFICATION_MODEL.name,)]
            for i, (topic, msg) in enumerate(streamed):
                pubs[topic].publish(msg)
                if i % 8 == 7:
                    # Pace the burst (about 1 kHz per topic, 5x the rig's rate): the view reads
                    # best effort with a shallow history, and Fast DDS drops what a reader has
                    # not taken when a burst outruns it.
                    node.spin_once(0.002)

            # Status is latched (keep-last 1 on the writer): only the latest is guaranteed.
            expected = f"command={N} state={N} taps={N} coefficients={N} segment=3 model=1"

            def counted() -> bool:
                lines = re.findall(r"received (.*) errors=0", procs.log("view"))
                return (
                    bool(lines) and lines[-1].startswith(expected) and "status=0" not in lines[-1]
                )

            assert wait_for(counted, 15), procs.log("view")
            os.kill(view.pid, signal.SIGINT)
            assert view.wait(timeout=15) == 0, procs.log("view")
    finally:
        node.close()

    rrd = Rrd(rrd_path)
    assert EXPECTED_ENTITIES <= set(rrd.rows), EXPECTED_ENTITIES - set(rrd.rows)
    times, values = rrd.scalars("/series/pitch/measured")
    np.testing.assert_array_equal(times, [stamp(k) for k in range(N)])
    np.testing.assert_allclose(values, [alpha_deg(k) for k in range(N)], atol=1e-9)
    assert len(rrd.column("/cp/upper", "LineStrips2D:strips")) == N // 10
    f, _ = rrd.bars("/frf/level_0/G_dB")
    np.testing.assert_allclose(f, [0.02, 0.06, 0.10, 0.14])
    status = rrd.column("/events/status", "TextLog:text")
    assert status[-1] == ["identifier: refit 1 done (periods=3)"]
    assert any(v.startswith("FRF level 2 [dB]") for v in rrd.view_names)
