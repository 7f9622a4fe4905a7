"""Transport benchmark: two rclpy node processes, 49-tap PointCloud2 messages.

Each configuration runs the same two phases: the nodes' serialized path (the runtime's
messages as CDR bytes through rclpy's serialized publish and ``raw=True`` subscriptions) with
rclpy's EventsExecutor (``cdr_events``, what every node uses) and with its
SingleThreadedExecutor (``cdr_single``), and rclpy's own message classes (``native_events``:
rclpy converts each message between Python and C on publish and on take), so the figures say
what the serialized path saves.

Round trip: this process publishes a tap cloud at 200 Hz on /bench/ping; an echo process
republishes it on /bench/pong; the round-trip time is measured per message.
Throughput: this process publishes ``--flood`` messages as fast as the reliable transport
takes on /bench/flood (QoS "stream": reliable, keep-all, back-pressure); the echo process counts
them and reports the count and its first/last receive times (one-way sustained rate).

    .venv/bin/python bench/transport.py [--seconds 10] [--flood 20000] [--configs cdr_events,...]

Last line: JSON {configuration: {sent, received, lost, throughput_msg_s, rtt_p50_ms,
rtt_p99_ms, ...}}.
"""

import argparse
import json
import os
import subprocess
import sys
import time
from typing import Any

import numpy as np

from rig_runtime.messages import serialize
from rig_runtime.node import Node, message_class
from rig_runtime.qos import PROFILES, to_rclpy_qos
from rig_testing.demo_nodes import make_message
from rig_testing.processes import graph_env, join_graph, unique_domain_id

CLOUD = "sensor_msgs/msg/PointCloud2"
RESULT = "std_msgs/msg/String"
MESSAGES_ENV = "BENCH_MESSAGES"  # "cdr" (the runtime's path) or "native" (rclpy's classes)


def _native() -> bool:
    return os.environ.get(MESSAGES_ENV, "cdr") == "native"


def _cloud_type() -> Any:
    """The tap cloud's type as the configuration's endpoints take it."""
    return message_class(CLOUD) if _native() else CLOUD


def _stream() -> Any:
    return to_rclpy_qos(PROFILES["stream"]) if _native() else "stream"


def _matched(publisher: Any) -> int:
    """Matched readers of a CdrPublisher or of an rclpy publisher."""
    count = getattr(publisher, "subscription_count", None) or publisher.get_subscription_count
    return int(count())


def _cloud(node: Node, seq: int) -> Any:
    """A tap cloud; in native mode as rclpy's message (converted before any timing)."""
    msg = make_message(node, "taps", seq)
    if not _native():
        return msg
    from rclpy.serialization import deserialize_message

    return deserialize_message(serialize(msg), message_class(CLOUD))


def echo_main() -> int:
    node = Node("bench_echo", argv=[])
    pong = node.create_publisher(_cloud_type(), "/bench/pong", _stream())
    result = node.create_publisher(RESULT, "/bench/result", qos_profile="latched")
    state = {"count": 0, "first": 0, "last": 0}

    def on_ping(msg: object) -> None:
        pong.publish(msg)

    def on_flood(_msg: object) -> None:
        now = time.monotonic_ns()
        state["first"] = state["first"] or now
        state["last"] = now
        state["count"] += 1

    def report() -> None:
        result.publish(node.new_message(RESULT, data=json.dumps(state)))

    node.create_subscription(_cloud_type(), "/bench/ping", on_ping, _stream())
    node.create_subscription(_cloud_type(), "/bench/flood", on_flood, _stream())
    node.create_timer(0.2, report)
    try:
        node.spin()
    except KeyboardInterrupt:
        pass
    finally:
        node.close()
    return 0


CONFIGS = {
    "cdr_events": {MESSAGES_ENV: "cdr", "RIG_RCLPY_EXECUTOR": "events"},
    "cdr_single": {MESSAGES_ENV: "cdr", "RIG_RCLPY_EXECUTOR": "single"},
    "native_events": {MESSAGES_ENV: "native", "RIG_RCLPY_EXECUTOR": "events"},
}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="round-trip phase length")
    parser.add_argument("--flood", type=int, default=20000, help="messages in throughput phase")
    parser.add_argument(
        "--configs", default=",".join(CONFIGS), help=f"comma-separated, of {list(CONFIGS)}"
    )
    parser.add_argument("--echo", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.echo:
        return echo_main()
    results: dict[str, dict[str, Any]] = {}
    ok = True
    for name in args.configs.split(","):
        print(f"== {name}")
        figures = measure(args, CONFIGS[name])
        ok = ok and figures["lost"] == 0
        results[name] = figures
    print(json.dumps(results))
    return 0 if ok else 1


def measure(args: argparse.Namespace, config: dict[str, str]) -> dict[str, Any]:
    env = graph_env(unique_domain_id(), **config)
    join_graph(env)
    os.environ.update(config)
    echo = subprocess.Popen([sys.executable, __file__, "--echo"], env=env)
    try:
        node = Node("bench_ping", argv=[])
        ping = node.create_publisher(_cloud_type(), "/bench/ping", _stream())
        flood = node.create_publisher(_cloud_type(), "/bench/flood", _stream())
        sent_at: dict[int, int] = {}
        rtts: list[float] = []
        latest: dict[str, Any] = {}

        def on_pong(msg: object) -> None:
            seq = int(np.frombuffer(np.asarray(msg.data, np.uint8).tobytes(), np.float32)[3])  # type: ignore[attr-defined]
            t0 = sent_at.pop(seq, None)
            if t0 is not None:
                rtts.append((time.perf_counter_ns() - t0) / 1e6)

        def on_result(msg: object) -> None:
            latest.update(json.loads(msg.data))  # type: ignore[attr-defined]

        node.create_subscription(_cloud_type(), "/bench/pong", on_pong, _stream())
        node.create_subscription(RESULT, "/bench/result", on_result, qos_profile="latched")
        if not node.spin_until(lambda: bool(_matched(ping) and _matched(flood) and latest), 30):
            raise RuntimeError("echo process did not appear on the DDS domain within 30 s")

        # Phase 1: round trip at 200 Hz.
        n_ping = int(args.seconds * 200)
        period = 1 / 200
        start = time.perf_counter()
        for k in range(n_ping):
            target = start + k * period

            def due(target: float = target) -> bool:
                return time.perf_counter() >= target

            node.spin_until(due, 1.0)
            msg = _cloud(node, k)
            sent_at[k] = time.perf_counter_ns()
            ping.publish(msg)
        node.spin_until(lambda: not sent_at, 5.0)
        pings_lost = len(sent_at)

        # Phase 2: sustained reliable throughput, one way.
        msgs = [_cloud(node, k) for k in range(min(args.flood, 1000))]
        t_start = time.perf_counter()
        for k in range(args.flood):
            flood.publish(msgs[k % len(msgs)])
            if k % 200 == 0:
                node.spin_once(0)
        node.spin_until(lambda: latest.get("count", 0) >= args.flood, 60)
        node.spin_until(lambda: False, 0.5)  # let the last report arrive
        t_send = time.perf_counter() - t_start
        received = int(latest.get("count", 0))
        span_s = (int(latest["last"]) - int(latest["first"])) / 1e9 if received > 1 else t_send
        node.close()
    finally:
        echo.send_signal(2)
        try:
            echo.wait(timeout=10)
        except subprocess.TimeoutExpired:
            echo.kill()
            echo.wait()

    rtt = np.array(rtts) if rtts else np.array([np.nan])
    figures = {
        "sent": args.flood,
        "received": received,
        "lost": args.flood - received,
        "throughput_msg_s": round(received / span_s, 1),
        "rtt_p50_ms": round(float(np.percentile(rtt, 50)), 3),
        "rtt_p99_ms": round(float(np.percentile(rtt, 99)), 3),
        "rtt_samples": len(rtts),
        "rtt_lost": pings_lost,
        "rtt_p90_ms": round(float(np.percentile(rtt, 90)), 3),
        "rtt_max_ms": round(float(np.max(rtt)), 3),
        "message_bytes": len(bytes(np.asarray(msgs[0].data))) + 100,
    }
    print(
        f"round trip at 200 Hz: {len(rtts)} samples, p50 {figures['rtt_p50_ms']} ms, "
        f"p99 {figures['rtt_p99_ms']} ms, lost {pings_lost}"
    )
    print(
        f"reliable throughput: {received}/{args.flood} received, "
        f"{figures['throughput_msg_s']} msg/s sustained"
    )
    return figures


if __name__ == "__main__":
    sys.exit(main())
