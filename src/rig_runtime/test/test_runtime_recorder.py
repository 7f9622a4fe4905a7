"""The recorder writes chunk-compressed rosbag2/MCAP that rosbags and Foxglove's mcap read back,
after clean stops, with splits, and (after recovery) after kill -9."""

import os
import signal
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from rig_runtime.bag_recover import _Scan, is_intact, read_records, recover_bag
from rig_runtime.messages import deserialize
from rig_testing.demo_nodes import TAP_COUNT
from rig_testing.processes import Processes, graph_env, wait_for

pytestmark = pytest.mark.slow  # node processes talking DDS: `make test-fast` skips them


def _read(bag: Path) -> tuple[list[int], list[str], dict]:
    with AnyReader([bag]) as reader:
        seqs = []
        for conn, _t, raw in reader.messages():
            msg: Any = reader.deserialize(raw, conn.msgtype)
            points = np.frombuffer(np.asarray(msg.data, np.uint8).tobytes(), np.float32)
            points = points.reshape(TAP_COUNT, 4)
            assert msg.width == TAP_COUNT and msg.point_step == 16
            assert np.all(points[:, 3] == points[0, 3])  # every tap carries the sequence number
            seqs.append(int(points[0, 3]))
        topics = [c.topic for c in reader.connections]
        digests = {c.topic: c.digest for c in reader.connections}
    return seqs, topics, digests


def _seq(data: bytes) -> int:
    """The sequence number of a raw (CDR) tap cloud from the talker."""
    msg = deserialize(data, "sensor_msgs/msg/PointCloud2")
    return int(np.frombuffer(np.asarray(msg.data, np.uint8).tobytes(), np.float32)[3])


def _start(procs: Processes, bag: Path, count: int, *params: str, rate_hz: float = 0.0) -> tuple:
    extra = [a for p in params for a in ("-p", p)]
    recorder = procs.start_entry(
        "rig_runtime",
        "recorder",
        "--ros-args",
        "-p",
        f"output:={bag}",
        "-p",
        "topics:=['/taps']",
        *extra,
        name="recorder",
    )
    talker = procs.start_entry(
        "rig_testing",
        "talker",
        "--ros-args",
        "-p",
        "topic:=/taps",
        "-p",
        "message:=taps",
        "-p",
        f"count:={count}",
        "-p",
        "qos:=stream",
        "-p",
        f"rate_hz:={rate_hz}",
        name="talker",
    )
    return recorder, talker


def test_records_20000_pointclouds_at_high_rate_none_lost(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    with Processes(graph_env(), log_dir=tmp_path) as procs:
        recorder, talker = _start(procs, bag, 20000)
        t0 = time.monotonic()
        assert wait_for(lambda: talker.poll() is not None, 120), procs.log("talker")
        elapsed = time.monotonic() - t0
        procs.stop_all()
        assert recorder.returncode == 0, procs.log("recorder")
    seqs, topics, digests = _read(bag)
    assert topics == ["/taps"]
    assert digests["/taps"].startswith("RIHS01_")
    assert seqs == list(range(20000))
    # The talker publishes in bursts: far above 2 kHz (its total time includes start-up).
    assert 20000 / elapsed > 2000 or elapsed < 10
    assert "offered_qos_profiles" in (bag / "metadata.yaml").read_text()
    # One file, zstd chunks (the default), read by Foxglove's mcap with its ROS 2 decoder too.
    assert [p.name for p in bag.glob("*.mcap")] == ["bag_0.mcap"]
    with (bag / "bag_0.mcap").open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None
        assert {c.compression for c in summary.chunk_indexes} == {"zstd"}
        decoded = [
            int(np.frombuffer(bytes(m.data), np.float32)[3])
            for _, _, _, m in reader.iter_decoded_messages()
        ]
    assert decoded == list(range(20000))


def test_sigterm_mid_run_leaves_finalised_bag(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    with Processes(graph_env(), log_dir=tmp_path) as procs:
        recorder, _ = _start(procs, bag, 10_000_000)
        assert wait_for(lambda: (bag / "metadata.yaml").exists(), 30)
        # Mid-run: the recorder has written a chunk of the stream (MCAP writes whole chunks).
        mcap = bag / "bag_0.mcap"
        assert wait_for(lambda: mcap.exists() and mcap.stat().st_size > 200_000, 60)
        os.kill(recorder.pid, signal.SIGTERM)
        assert wait_for(lambda: recorder.poll() is not None, 20)
        assert recorder.returncode == 0, procs.log("recorder")
    seqs, _, _ = _read(bag)
    assert len(seqs) > 100
    assert seqs == list(range(len(seqs)))  # contiguous: nothing lost before the stop
    assert [p.name for p in bag.glob("*.mcap")] == ["bag_0.mcap"] and is_intact(bag / "bag_0.mcap")


def test_duration_split_files_are_those_metadata_lists(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    with Processes(graph_env(), log_dir=tmp_path) as procs:
        recorder, talker = _start(procs, bag, 3000, "max_bag_duration:=0.5", rate_hz=1000.0)
        assert wait_for(lambda: talker.poll() is not None, 120), procs.log("talker")
        procs.stop_all()
        assert recorder.returncode == 0, procs.log("recorder")
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    names = info["relative_file_paths"]
    assert len(names) >= 3, names  # about 3 s of recording in 0.5 s files
    assert sorted(names) == sorted(p.name for p in bag.glob("*.mcap"))
    assert all(is_intact(bag / n) for n in names)
    for f in info["files"][:-1]:
        assert f["duration"]["nanoseconds"] < 0.5e9
    assert sum(f["message_count"] for f in info["files"]) == info["message_count"] == 3000
    seqs, _, _ = _read(bag)
    assert seqs == list(range(3000))


def test_kill_9_loses_at_most_flush_s_and_recover_restores_the_footer(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    flush_s = 0.3
    file = bag / "bag_0.mcap"
    with Processes(graph_env(), log_dir=tmp_path) as procs:
        recorder, _ = _start(procs, bag, 10_000_000, f"flush_s:={flush_s}", rate_hz=500.0)
        # Recording has gone on for a while once a few chunks are on disk.
        assert wait_for(lambda: file.exists() and file.stat().st_size > 100_000, 60)
        kill_ns = time.time_ns()
        os.kill(recorder.pid, signal.SIGKILL)
        recorder.wait(timeout=10)
        assert recorder.returncode == -signal.SIGKILL
    assert not is_intact(file)  # no footer: the writer died
    scan = _Scan()
    messages = list(read_records(file, scan))
    assert scan.error
    assert [_seq(m.data) for m in messages] == list(range(len(messages)))
    last_ns = max(m.log_time for m in messages)
    # Everything received up to flush_s before the kill is on disk (0.5 s slack for a busy
    # machine: the flush timer shares the recorder's thread with the message callbacks).
    assert last_ns >= kill_ns - (flush_s + 0.5) * 1e9, (kill_ns - last_ns) / 1e9
    reports = recover_bag(bag)
    assert [r.name for r in reports] == ["bag_0.mcap"] and reports[0].rewritten
    assert reports[0].stats.count == len(messages) and reports[0].last_ns == last_ns
    with file.open("rb") as f:  # the indexed reader accepts the footer and summary
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert summary.statistics.message_count == len(messages)
        assert [_seq(m.data) for _, _, m in reader.iter_messages()] == list(range(len(messages)))
    seqs, _, _ = _read(bag)
    assert seqs == list(range(len(messages)))
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["message_count"] == len(messages)
