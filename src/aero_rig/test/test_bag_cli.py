"""``aero-rig bag recover``: a bag whose recorder died gets its footer and metadata back."""

from pathlib import Path

import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from aero_rig.cli import main
from rig_runtime.bag import BagWriter
from rig_runtime.bag_recover import is_intact
from rig_runtime.interface import PITCH_STATE
from rig_runtime.messages import new_message, serialize

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
