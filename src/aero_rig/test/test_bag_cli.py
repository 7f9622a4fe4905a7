"""``aero-rig bag recover``: a bag whose recorder died gets its footer and metadata back; a
damaged chunk costs only its own messages, in the recovery and in ``aero-rig fit``'s reader."""

import json
import tempfile
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from aero_identification.hyperparameters import IdentificationConfig
from aero_rig.cli import main
from aero_rig.offline import read_campaign_bag
from multisine_gen.campaigns import short_plan
from multisine_gen.plan_format import plan_message, segment_event_fields
from rig_runtime.anomaly import Anomaly
from rig_runtime.bag import BagWriter
from rig_runtime.bag_recover import is_intact
from rig_runtime.interface import (
    EXPERIMENT_ANOMALY,
    EXPERIMENT_PLAN,
    EXPERIMENT_SEGMENT,
    IDENTIFICATION_MODEL,
    PITCH_JOINT,
    PITCH_STATE,
    WING_COEFFICIENTS,
)
from rig_runtime.messages import new_message, serialize, set_stamp

T0 = 1_700_000_000 * 10**9


def test_bag_recover_rewrites_the_footer_and_prints_what_it_kept(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "bag"
    writer = BagWriter(bag)
    cid = writer.add_connection(PITCH_STATE.name, "sensor_msgs/msg/JointState")
    for k in range(500):
        data = serialize(new_message("sensor_msgs/msg/JointState", position=[k * 1.0]))
        writer.write(cid, T0 + k * 5_000_000, data)
    writer.flush()  # then the recorder is killed: no footer, no summary
    file = bag / "bag_0.mcap"
    assert not is_intact(file)
    assert main(["bag", "recover", str(bag)]) == 0
    out = capsys.readouterr().out
    assert "bag_0.mcap: damaged" in out and f"{PITCH_STATE.name}: 500" in out
    assert "last readable time 2023-11-14T22:13:22.495000Z" in out
    with file.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == 500
    with AnyReader([bag]) as reader:
        assert reader.message_count == 500
    assert main(["bag", "recover", str(bag)]) == 0  # a whole bag is left as it is
    assert "whole" in capsys.readouterr().out


def test_bag_recover_of_a_missing_bag_fails_clearly(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["bag", "recover", str(tmp_path / "nope")]) == 2
    assert "not a directory" in capsys.readouterr().err


STRING = "std_msgs/msg/String"  # the plan's, events' and models' type before aero_rig_interfaces
# An adaptive run's answer to a request (the generator's /experiment/segment payload).
DECISION = {
    "t0_ns": T0, "at_k": 900, "request": "go_on", "level": 0, "after_k": 899,
    "reason": "the periods agree", "event": "decision", "change": "",
}  # fmt: skip
ANOMALY = Anomaly("lift/frame_loss/1", "lift", "frame_loss", T0 + 10**9, T0 + 2 * 10**9, "lost")


def _campaign_bag(
    bag: Path, samples: int, per_chunk: int, legacy: bool | None = None
) -> tuple[int, Any]:
    """The short plan's message and its first ``samples`` plan samples of pitch and C_l, one
    chunk per ``per_chunk`` samples (the recorder's flush); the plan's t0 and the chunk index.

    ``legacy`` given: also DECISION on /experiment/segment, an /identification/model holding
    IdentificationConfig() and ANOMALY; True writes the plan, the event, the model and the
    anomaly as a bag recorded before aero_rig_interfaces did, std_msgs/String JSON."""
    plan = short_plan()
    t0 = T0
    writer = BagWriter(bag)
    plan_fields = plan_message(plan, t0, plan_id="short")
    if legacy:
        plan_id = writer.add_connection(EXPERIMENT_PLAN.name, STRING)
        plan_msg = new_message(STRING, data=plan_fields["plan_json"])
    else:
        plan_id = writer.add_connection(EXPERIMENT_PLAN.name, EXPERIMENT_PLAN.type)
        plan_msg = new_message(EXPERIMENT_PLAN.type, **plan_fields)
        set_stamp(plan_msg.header.stamp, t0)
    writer.write(plan_id, t0 - 10**9, serialize(plan_msg))
    if legacy is not None:
        model = json.dumps({"refit": 1, "config": IdentificationConfig().to_dict()})
        if legacy:
            event = new_message(STRING, data=json.dumps(DECISION))
            model_msg = new_message(STRING, data=model)
            anomaly = new_message(STRING, data=ANOMALY.to_json())
        else:
            event = new_message(EXPERIMENT_SEGMENT.type, **segment_event_fields(DECISION))
            model_msg = new_message(IDENTIFICATION_MODEL.type, refit=1, model_json=model)
            anomaly = new_message(EXPERIMENT_ANOMALY.type, **ANOMALY.to_fields())
        for topic, msg in (
            (EXPERIMENT_SEGMENT, event),
            (IDENTIFICATION_MODEL, model_msg),
            (EXPERIMENT_ANOMALY, anomaly),
        ):
            cid = writer.add_connection(topic.name, STRING if legacy else topic.type)
            writer.write(cid, t0, serialize(msg))
    pitch = writer.add_connection(PITCH_STATE.name, PITCH_STATE.type)
    wing = writer.add_connection(WING_COEFFICIENTS.name, WING_COEFFICIENTS.type)
    for k in range(samples):
        t = t0 + round(k * 1e9 / plan.fs)
        state = new_message(PITCH_STATE.type, name=[PITCH_JOINT], position=[k * 1e-4])
        coeff = new_message(WING_COEFFICIENTS.type)
        set_stamp(state.header.stamp, t)
        set_stamp(coeff.header.stamp, t)
        coeff.vector.x = k * 1e-3
        writer.write(pitch, t, serialize(state))
        writer.write(wing, t, serialize(coeff))
        if k % per_chunk == per_chunk - 1:
            writer.flush()
    writer.close()
    with (bag / "bag_0.mcap").open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return t0, sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)


def _damage_chunk(file: Path, chunk: Any) -> None:
    data = bytearray(file.read_bytes())
    mid = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[mid : mid + 64] = bytes(b ^ 0xFF for b in data[mid : mid + 64])
    file.write_bytes(bytes(data))


def test_bag_recover_keeps_every_intact_chunk_and_prints_each_gap(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "bag"
    _, chunks = _campaign_bag(bag, 2000, 400)
    assert len(chunks) == 5
    _damage_chunk(bag / "bag_0.mcap", chunks[2])
    assert main(["bag", "recover", str(bag)]) == 0
    out = capsys.readouterr().out
    gap = [line for line in out.splitlines() if line.startswith("  gap: ")]
    assert len(gap) == 1, out
    assert f"{PITCH_STATE.name} 400, {WING_COEFFICIENTS.name} 400" in gap[0]
    assert "2023-11-14T22:13:24.000000Z" in gap[0] and "2023-11-14T22:13:25.995000Z" in gap[0]
    assert "1 unreadable stretch(es) skipped (800 messages lost in them)" in out
    assert f"{PITCH_STATE.name}: 1600" in out
    with AnyReader([bag]) as reader:
        assert reader.message_count == 1 + 2 * 1600


def test_fit_reads_around_a_damaged_middle_chunk(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """aero-rig fit's reader: a damaged chunk in the middle of a bag with its summary costs only
    that chunk's samples (missing from their periods, so the data-quality account names them),
    with a warning that names the gap."""
    bag = tmp_path / "bag"
    t0, chunks = _campaign_bag(bag, 3000, 500)
    whole = read_campaign_bag(bag)
    assert whole.warnings == [] and whole.messages == 6000
    _damage_chunk(bag / "bag_0.mcap", chunks[3])  # samples 1500..1999
    views = tmp_path / "tmp"
    views.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(views))  # where the salvaged view goes
    damaged = read_campaign_bag(bag)
    assert not list(views.iterdir())  # the view is removed
    assert damaged.messages == 5000
    assert len(damaged.warnings) == 1, damaged.warnings
    assert f"{PITCH_STATE.name} 500, {WING_COEFFICIENTS.name} 500" in damaged.warnings[0]
    assert "aero-rig bag recover" in damaged.warnings[0]
    for channel in ("u", "y"):
        expected = whole.assembler.coverage[channel].copy()
        assert expected[:3000].all()
        expected[1500:2000] = 0
        assert (damaged.assembler.coverage[channel] == expected).all()
    assert damaged.assembler.t0_ns == t0
    assert is_intact(bag / "bag_0.mcap")  # the bag is left as it was (its summary is intact)


@pytest.mark.parametrize("legacy", [False, True], ids=["typed", "string"])
def test_fit_reads_a_bag_of_either_message_generation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], legacy: bool
) -> None:
    """The plan (ExperimentPlan with plan_json), the decision event, the recorded parameters
    and the anomaly of a bag are read and fitted, and so are those of a bag recorded before
    aero_rig_interfaces (the same JSON in std_msgs/String): the same account either way."""
    bag = tmp_path / "bag"
    t0, _ = _campaign_bag(bag, 3000, 1000, legacy)
    with AnyReader([bag]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
    assert types[EXPERIMENT_PLAN.name] == (STRING if legacy else EXPERIMENT_PLAN.type)
    data = read_campaign_bag(bag)
    assert data.warnings == [] and data.messages == 6000
    assert data.plan.total_samples == short_plan().total_samples and data.assembler.t0_ns == t0
    assert data.assembler.decisions == [DECISION]
    assert data.recorded_config == IdentificationConfig().to_dict()
    assert list(data.assembler.anomalies) == [ANOMALY.id]
    # The fit of the first 3000 samples: what is missing is listed, accepted here.
    out = tmp_path / "fit"
    args = ["fit", str(bag), "--out", str(out), "--no-scan", "--no-clustering-ablation"]
    assert main([*args, "--allow-excluded"]) == 0
    assert "as recorded with the run" in capsys.readouterr().err
    models = json.loads((out / "models.json").read_text())
    assert models["experiment"]["decisions"] == [DECISION]
    assert models["data_quality"]["anomalies"] == ["samples 200..400: lift frame_loss: lost"]


def test_fit_of_a_bag_whose_plan_is_not_a_plan_stops_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "bag"
    writer = BagWriter(bag)
    for topic in (PITCH_STATE, WING_COEFFICIENTS):
        writer.add_connection(topic.name, topic.type)
    cid = writer.add_connection(EXPERIMENT_PLAN.name, STRING)
    writer.write(cid, T0, serialize(new_message(STRING, data='{"format": "a shopping list"}')))
    writer.close()
    assert main(["fit", str(bag)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"aero-rig fit: bag {bag}: /experiment/plan holds no plan with an integer t0_ns"]
