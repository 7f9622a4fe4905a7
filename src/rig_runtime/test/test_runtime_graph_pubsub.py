"""Nodes in separate processes on rclpy (Fast DDS, loopback)."""

import json
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from rig_runtime import Node
from rig_testing.demo_nodes import make_message
from rig_testing.processes import Processes, graph_env, join_graph, wait_for

pytestmark = pytest.mark.slow  # node processes talking DDS: `make test-fast` skips them


def _listener_args(result: Path, **params: object) -> list[str]:
    args = ["--ros-args", "-p", f"result_file:={result}"]
    for key, value in params.items():
        args += ["-p", f"{key}:={value}"]
    return args


def _talker_args(**params: object) -> list[str]:
    args = ["--ros-args"]
    for key, value in params.items():
        args += ["-p", f"{key}:={value}"]
    return args


def test_10000_reliable_messages_none_lost_in_order(tmp_path: Path) -> None:
    result = tmp_path / "listener.json"
    with Processes(graph_env(), log_dir=tmp_path) as procs:
        listener = procs.start_entry(
            "rig_testing", "listener", *_listener_args(result, count=10000, qos="stream")
        )
        procs.start_entry("rig_testing", "talker", *_talker_args(count=10000, qos="stream"))
        assert wait_for(lambda: listener.poll() is not None, 60), procs.log("listener")
    summary = json.loads(result.read_text())
    assert summary["received"] == 10000
    assert summary["out_of_order"] == 0
    assert summary["last"] == 9999


def test_a_writer_leaving_at_once_still_delivers_to_a_paused_reader(tmp_path: Path) -> None:
    """The listener is stopped (SIGSTOP) while the talker publishes 3,000 messages (fewer than
    the 5,000 a keep-all writer holds unacknowledged before it blocks) and exits at once
    (linger_s 0): most of the burst overflows the stopped reader's receive queue. The
    talker's writer waits for its reader's acknowledgement when its node closes
    (WRITER_LINGER_S, and Fast DDS heartbeats every 100 ms), so the listener, resumed within
    that time, still gets every message in order."""
    import psutil

    result = tmp_path / "listener.json"
    with Processes(graph_env(), log_dir=tmp_path) as procs:
        listener = procs.start_entry(
            "rig_testing", "listener", *_listener_args(result, count=3000, qos="stream")
        )
        talker = procs.start_entry(
            "rig_testing",
            "talker",
            *_talker_args(count=3000, qos="stream", linger_s=0.0, start_delay_s=0.3),
        )
        assert wait_for(lambda: "matched; publishing" in procs.log("talker"), 60), procs.log(
            "talker"
        )
        stopped = psutil.Process(listener.pid)
        stopped.suspend()
        try:
            # resumed once the talker has published all and is closing (its linger runs)
            assert wait_for(lambda: "published 3000" in procs.log("talker"), 30)
        finally:
            stopped.resume()
        assert wait_for(lambda: listener.poll() is not None, 30), procs.log("listener")
        assert wait_for(lambda: talker.poll() is not None, 30), procs.log("talker")
    summary = json.loads(result.read_text())
    assert summary["received"] == 3000, summary
    assert summary["out_of_order"] == 0 and summary["last"] == 2999, summary


def test_latched_topic_reaches_late_subscriber(tmp_path: Path) -> None:
    result = tmp_path / "late.json"
    with Processes(graph_env(), log_dir=tmp_path) as procs:
        talker = procs.start_entry(
            "rig_testing",
            "talker",
            *_talker_args(count=1, qos="latched", wait_for_subscribers=0, linger_s=30.0),
        )
        # The sample is published before the subscriber exists: a late join, nothing else.
        assert wait_for(lambda: "published 1 messages" in procs.log("talker"), 30), procs.log(
            "talker"
        )
        assert talker.poll() is None, procs.log("talker")  # still there to serve the late join
        listener = procs.start_entry(
            "rig_testing", "listener", *_listener_args(result, count=1, qos="latched")
        )
        assert wait_for(lambda: listener.poll() is not None, 30), procs.log("listener")
    assert json.loads(result.read_text())["received"] == 1


def test_sensor_qos_pubsub(tmp_path: Path) -> None:
    result = tmp_path / "sensor.json"
    with Processes(graph_env(), log_dir=tmp_path) as procs:
        listener = procs.start_entry(
            "rig_testing", "listener", *_listener_args(result, qos="sensor", message="taps")
        )
        talker = procs.start_entry(
            "rig_testing",
            "talker",
            *_talker_args(count=400, rate_hz=200.0, qos="sensor", message="taps", linger_s=0.5),
        )
        assert wait_for(lambda: talker.poll() is not None, 30), procs.log("talker")
        procs.stop_all()
        assert listener.returncode == 0
    summary = json.loads(result.read_text())
    # Best effort may drop under load; on loopback at 200 Hz nearly everything arrives.
    assert summary["received"] >= 380
    assert summary["out_of_order"] == 0


def _publish_then_idle(
    tmp_path: Path, monkeypatch: Any, publish: Callable[[Any, Any], None]
) -> None:
    """A listener process must receive 5 samples this process writes and then never spins for."""
    result = tmp_path / "listener.json"
    env = graph_env()
    join_graph(env, monkeypatch.setenv)
    with Processes(env, log_dir=tmp_path) as procs:
        listener = procs.start_entry(
            "rig_testing", "listener", *_listener_args(result, count=5, qos="stream")
        )
        node = Node("batch_talker", [], [])
        try:
            pub = node.create_publisher(
                "sensor_msgs/msg/JointState", "/chatter", qos_profile="stream"
            )
            assert node.spin_until(lambda: pub.subscription_count() > 0, 30)
            publish(node, lambda seq: pub.publish(make_message(node, "joint_state", seq)))
            # No spinning from here on: whatever was not flushed would never leave.
            assert wait_for(lambda: listener.poll() is not None, 20), procs.log("listener")
        finally:
            node.close()
    assert json.loads(result.read_text())["received"] == 5


def test_batched_writes_in_a_turn_leave_when_the_turn_ends(
    tmp_path: Path, monkeypatch: Any
) -> None:
    def in_one_turn(node: Any, send: Callable[[int], None]) -> None:
        def send_all() -> None:
            for i in range(5):
                send(i)

        timer = node.create_timer(0.001, send_all)
        node.spin_once(1.0)  # the timer fires once inside this turn
        timer.cancel()

    _publish_then_idle(tmp_path, monkeypatch, in_one_turn)


def test_writes_outside_a_turn_leave_at_once(tmp_path: Path, monkeypatch: Any) -> None:
    def from_a_thread(node: Any, send: Callable[[int], None]) -> None:
        def send_all() -> None:
            for i in range(5):
                send(i)

        worker = threading.Thread(target=send_all)
        worker.start()
        worker.join(10)

    _publish_then_idle(tmp_path, monkeypatch, from_a_thread)
