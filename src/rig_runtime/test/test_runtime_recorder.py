"""The recorder writes rosbag2/MCAP that rosbags reads back, after clean stops and kill -9."""

import os
import signal
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from rig_runtime.demo_nodes import TAP_COUNT
from rig_runtime.testing import Processes, graph_env, wait_for

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


def _start(procs: Processes, bag: Path, count: int, split_s: float = 5.0) -> tuple:
    recorder = procs.start_entry(
        "rig_runtime",
        "recorder",
        "--ros-args",
        "-p",
        f"output:={bag}",
        "-p",
        "topics:=['/taps']",
        "-p",
        f"split_seconds:={split_s}",
        name="recorder",
    )
    talker = procs.start_entry(
        "rig_runtime",
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


def test_sigterm_mid_run_leaves_finalised_bag(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    with Processes(graph_env(), log_dir=tmp_path) as procs:
        recorder, _ = _start(procs, bag, 10_000_000)
        assert wait_for(lambda: (bag / "metadata.yaml").exists(), 30)
        time.sleep(2.0)
        os.kill(recorder.pid, signal.SIGTERM)
        assert wait_for(lambda: recorder.poll() is not None, 20)
        assert recorder.returncode == 0, procs.log("recorder")
    seqs, _, _ = _read(bag)
    assert len(seqs) > 100
    assert seqs == list(range(len(seqs)))  # contiguous: nothing lost before the stop
    assert not list(bag.glob("*.opening"))


def test_kill_9_leaves_readable_bag_up_to_last_split(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    with Processes(graph_env(), log_dir=tmp_path) as procs:
        recorder, _ = _start(procs, bag, 10_000_000, split_s=0.5)
        assert wait_for(lambda: (bag / "metadata.yaml").exists(), 30)
        assert wait_for(lambda: len(list(bag.glob("*.mcap"))) >= 3, 30)
        os.kill(recorder.pid, signal.SIGKILL)
        recorder.wait(timeout=10)
    seqs, _, _ = _read(bag)
    assert len(seqs) > 100
    assert seqs == list(range(len(seqs)))
