"""The bag writer: chunk-compressed MCAP that rosbags and Foxglove's mcap (ROS 2 decoder) read,
splits that metadata.yaml lists, files without footer that are read and recovered."""

from pathlib import Path
from typing import Any

import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from rig_runtime.bag import BagWriter
from rig_runtime.bag_recover import _Scan, is_intact, read_records, recover_bag
from rig_runtime.interface import PITCH_STATE
from rig_runtime.messages import new_message, serialize

T0 = 1_700_000_000 * 10**9


def _state(k: int) -> bytes:
    return serialize(new_message("sensor_msgs/msg/JointState", name=["pitch"], position=[k * 0.1]))


def _record(bag: Path, n: int, period_ns: int = 5_000_000, **options: Any) -> BagWriter:
    writer = BagWriter(bag, **options)
    cid = writer.add_connection(PITCH_STATE.name, "sensor_msgs/msg/JointState")
    writer.add_connection("/never", "std_msgs/msg/String")  # a topic without messages
    for k in range(n):
        writer.write(cid, T0 + k * period_ns, _state(k))
    return writer


def _meta(bag: Path) -> dict[str, Any]:
    return yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]


def _rosbags_positions(bag: Path) -> list[float]:
    with AnyReader([bag]) as reader:
        out = []
        for conn, _, raw in reader.messages():
            msg: Any = reader.deserialize(raw, conn.msgtype)
            out.append(float(msg.position[0]))
    return out


def _mcap_positions(file: Path) -> list[float]:
    with file.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [float(m.position[0]) for _, _, _, m in reader.iter_decoded_messages()]


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_one_compressed_file_read_by_rosbags_and_mcap(tmp_path: Path, compression: str) -> None:
    bag = tmp_path / "bag"
    _record(bag, 3000, compression=compression).close()
    files = sorted(bag.glob("*.mcap"))
    assert [f.name for f in files] == ["bag_0.mcap"]  # no split unless asked for
    expected = [k * 0.1 for k in range(3000)]
    assert _rosbags_positions(bag) == pytest.approx(expected)
    assert _mcap_positions(files[0]) == pytest.approx(expected)
    with files[0].open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.chunk_indexes
    assert {c.compression for c in summary.chunk_indexes} == {
        {"none": ""}.get(compression, compression)
    }
    meta = _meta(bag)
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
    assert (meta["compression_format"], meta["compression_mode"]) == ("", "")
    assert meta["message_count"] == 3000 and meta["files"][0]["message_count"] == 3000
    assert meta["duration"]["nanoseconds"] == 2999 * 5_000_000
    counts = {
        t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]
    }
    assert counts == {PITCH_STATE.name: 3000, "/never": 0}


def test_default_compression_is_zstd_and_smaller(tmp_path: Path) -> None:
    _record(tmp_path / "z", 5000).close()
    _record(tmp_path / "n", 5000, compression="none").close()
    with (tmp_path / "z" / "z_0.mcap").open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    assert {c.compression for c in summary.chunk_indexes} == {"zstd"}
    size = (tmp_path / "z" / "z_0.mcap").stat().st_size
    assert size < (tmp_path / "n" / "n_0.mcap").stat().st_size / 2


def _assert_files_as_listed(bag: Path, total: int) -> dict[str, Any]:
    meta = _meta(bag)
    on_disk = sorted((p.name for p in bag.glob("*.mcap")), key=lambda n: int(n[4:-5]))
    assert meta["relative_file_paths"] == on_disk == [f["path"] for f in meta["files"]]
    per_file = []
    for name in on_disk:
        assert is_intact(bag / name)
        per_file.append(len(_mcap_positions(bag / name)))
    assert per_file == [f["message_count"] for f in meta["files"]]
    assert sum(per_file) == meta["message_count"] == total
    assert len(_rosbags_positions(bag)) == total
    return meta


def test_size_split_gives_the_files_metadata_lists(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    writer = _record(bag, 20000, compression="none", max_bag_size=200_000)
    writer.close()
    meta = _assert_files_as_listed(bag, 20000)
    assert len(meta["files"]) >= 3
    for name in meta["relative_file_paths"][:-1]:  # at most one chunk (a quarter) past it
        assert 200_000 <= (bag / name).stat().st_size <= 200_000 * 1.25 + 10_000


def test_duration_split_gives_the_files_metadata_lists(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    _record(bag, 2000, period_ns=5_000_000, max_bag_duration_ns=2 * 10**9).close()  # 10 s
    meta = _assert_files_as_listed(bag, 2000)
    assert [f["message_count"] for f in meta["files"]] == [400] * 5
    for f in meta["files"]:
        assert f["duration"]["nanoseconds"] == 399 * 5_000_000


def test_flushed_file_without_footer_is_read_and_recovered(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    writer = BagWriter(bag)
    cid = writer.add_connection(PITCH_STATE.name, "sensor_msgs/msg/JointState")
    writer.add_connection("/never", "std_msgs/msg/String")
    for k in range(4000):
        writer.write(cid, T0 + k * 5_000_000, _state(k))
        if k % 1000 == 999:
            writer.flush()  # what the recorder does every flush_s; then the process dies
    file = bag / "bag_0.mcap"
    assert not is_intact(file)
    assert _meta(bag)["relative_file_paths"] == ["bag_0.mcap"]
    scan = _Scan()
    assert len(list(read_records(file, scan))) == 4000 and scan.error
    # A disk error or a copy cut short: the tail of the last chunk is lost too.
    data = file.read_bytes()
    file.write_bytes(data[: len(data) // 2])
    reports = recover_bag(bag)
    assert len(reports) == 1 and not reports[0].intact and reports[0].rewritten
    assert is_intact(file)
    recovered = _mcap_positions(file)
    assert len(recovered) in (1000, 2000, 3000)  # whole chunks
    assert recovered == pytest.approx([k * 0.1 for k in range(len(recovered))])
    assert reports[0].last_ns == T0 + (len(recovered) - 1) * 5_000_000
    assert _rosbags_positions(bag) == pytest.approx(recovered)
    meta = _meta(bag)
    assert meta["message_count"] == len(recovered)
    topics = {t["topic_metadata"]["name"]: t for t in meta["topics_with_message_count"]}
    assert topics[PITCH_STATE.name]["topic_metadata"]["type_description_hash"].startswith("RIHS01")
    assert topics[PITCH_STATE.name]["topic_metadata"]["offered_qos_profiles"]
    assert "/never" in topics
    assert not list(bag.glob("*.recovering"))
    # A whole bag is left as it is.
    before = file.read_bytes()
    assert recover_bag(bag)[0].intact and file.read_bytes() == before


def test_bad_writer_options_are_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="compression 'gzip' unknown"):
        BagWriter(tmp_path / "a", compression="gzip")
    with pytest.raises(ValueError, match="max_bag_size"):
        BagWriter(tmp_path / "b", max_bag_size=-1)
    BagWriter(tmp_path / "c").close()
    with pytest.raises(FileExistsError):
        BagWriter(tmp_path / "c")


@pytest.mark.parametrize(
    ("override", "expected"),
    [
        ("compression:=gzip", "compression"),
        ("max_bag_size:=-5", "max_bag_size"),
        ("max_bag_duration:=-1.0", "max_bag_duration"),
        ("flush_s:=0.0", "flush_s"),
        ("split_seconds:=5.0", "split_seconds"),  # removed: max_bag_duration / flush_s
    ],
)
def test_bad_recorder_parameters_give_clear_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], override: str, expected: str
) -> None:
    from rig_runtime.recorder import main

    code = main(["--ros-args", "-p", f"output:={tmp_path / 'bag'}", "-p", override])
    assert code == 2
    err = capsys.readouterr().err
    assert "[FATAL]" in err and expected in err
    assert not (tmp_path / "bag").exists()
