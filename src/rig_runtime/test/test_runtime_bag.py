"""The split bag writer: MCAP records identical to rosbags', metadata listing closed files."""

from pathlib import Path
from typing import Any

from rosbags.highlevel import AnyReader
from rosbags.rosbag2.enums import CompressionMode
from rosbags.rosbag2.storage_mcap import McapWriter

from rig_runtime.bag import SplitBagWriter, _McapFile
from rig_runtime.interface import PITCH_STATE
from rig_runtime.messages import new_message, serialize


def test_fast_message_records_equal_rosbags_records(tmp_path: Path) -> None:
    bag = SplitBagWriter(tmp_path / "bag")
    cid = bag.add_connection(PITCH_STATE.name, "sensor_msgs/msg/JointState")
    conn = bag.connections[cid - 1]
    ours = _McapFile(tmp_path / "ours.mcap")
    (tmp_path / "ref").mkdir()
    reference = McapWriter(tmp_path / "ref", CompressionMode.NONE)
    for writer in (ours, reference):
        writer.add_msgtype(conn)
        writer.add_connection(conn, "")
        for k in range(50):
            data = serialize(new_message("sensor_msgs/msg/JointState", position=[k * 0.1]))
            writer.write(conn, 1_000 + k, data)
    assert ours.chunk.bio.getvalue() == reference.chunk.bio.getvalue()
    assert dict(ours.chunk.msgs) == dict(reference.chunk.msgs)


def test_metadata_lists_only_closed_files(tmp_path: Path) -> None:
    bag = SplitBagWriter(tmp_path / "bag", split_seconds=3600)
    cid = bag.add_connection("/x", "std_msgs/msg/String")
    for k in range(10):
        bag.write(cid, k + 1, serialize(new_message("std_msgs/msg/String", data=str(k))))
    bag.split()
    bag.write(cid, 100, serialize(new_message("std_msgs/msg/String", data="open")))
    with AnyReader([tmp_path / "bag"]) as reader:  # the open file is not listed yet
        msgs: list[Any] = [reader.deserialize(r, c.msgtype) for c, _, r in reader.messages()]
        assert [m.data for m in msgs] == [str(k) for k in range(10)]
    bag.close()
    with AnyReader([tmp_path / "bag"]) as reader:
        assert reader.message_count == 11
