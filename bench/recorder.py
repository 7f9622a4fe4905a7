"""Recorder benchmark: the default campaign's four sample streams into a bag.

A publisher in this process sends /pitch/command and /pitch/state (JointState),
/wing/coefficients (Vector3Stamped) and /pressure/taps (PointCloud2, 49 taps from the simulated
wing plant, so the pressures are as compressible as the campaign's) for ``--seconds`` of
experiment time (samples stamped at the plan's 200 Hz), published at ``--rate-hz`` samples per
second per topic (stream QoS: reliable, keep-all); the recorder runs as its own process
(an rclpy node, loopback). Printed: MB written, the compression ratio
(CDR payload bytes / bag bytes), the recorder's CPU seconds (user + system of the process, from
its rusage once reaped), messages lost (published - recorded), and the same figures scaled to
the default campaign's experiment length (``--experiment-s``, 2,442 s at 200 Hz).

    .venv/bin/python bench/recorder.py [--seconds 60] [--rate-hz 200] [-p NAME:=VALUE ...]

``--rate-hz 200`` is the rig's pace (the campaign at real time); the simulated campaign at
``real_time_factor`` 0 delivers about 5,500 samples/s per topic (``--rate-hz 5000``). ``-p``
passes recorder parameters (e.g. ``-p compression:=lz4``). To measure another checkout's recorder,
put its package first: ``PYTHONPATH=/tmp/rec_base/src/rig_runtime .venv/bin/python
bench/recorder.py``. Last line: JSON.
"""

import argparse
import json
import math
import resource
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import psutil

from rig_runtime.interface import PITCH_COMMAND, PITCH_STATE, PRESSURE_TAPS, WING_COEFFICIENTS
from rig_runtime.messages import new_message, serialize
from rig_testing.processes import Processes, graph_env, join_graph, wait_for

TOPICS = (PITCH_COMMAND, PITCH_STATE, WING_COEFFICIENTS, PRESSURE_TAPS)
CAMPAIGN_EXPERIMENT_S = 2442.0  # the default plan: 488,449 samples at 200 Hz
FS = 200.0  # the plan's sample rate [Hz]


def _payloads(count: int, fs: float) -> dict[str, list[bytes]]:
    """``count`` serialized samples per topic, stamped as a run starting now would stamp them."""
    from pressure_scanner.tap_cloud import fill_cloud, point_fields
    from pressure_scanner.taps import load_taps
    from wing_sim.plant import WingPlant
    from wing_sim.wing_params import WingParams

    plant = WingPlant(WingParams(), load_taps(None), seed=0)
    fields = point_fields(new_message)
    rng = np.random.default_rng(0)
    t0 = time.time_ns()
    out: dict[str, list[bytes]] = {t.name: [] for t in TOPICS}
    for k in range(count):
        stamp_ns = t0 + round(k * 1e9 / fs)
        stamp = new_message(
            "builtin_interfaces/msg/Time", sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9
        )
        t = k / fs
        command = math.radians(4.0 + 3.0 * math.sin(2 * math.pi * 0.7 * t) + rng.normal(0, 0.5))
        measured = command + rng.normal(0, 2e-4)
        header = new_message("std_msgs/msg/Header", stamp=stamp)
        out[PITCH_COMMAND.name].append(
            serialize(
                new_message(PITCH_COMMAND.type, header=header, name=["pitch"], position=[command])
            )
        )
        out[PITCH_STATE.name].append(
            serialize(
                new_message(
                    PITCH_STATE.type,
                    header=header,
                    name=["pitch", "alpha_true"],
                    position=[measured, command],
                )
            )
        )
        pressures = plant.step(measured)
        cloud = new_message(PRESSURE_TAPS.type)
        cloud.header.stamp = stamp
        cloud.header.frame_id = "wing"
        fill_cloud(cloud, new_message, plant.tap_xyz, pressures, fields)
        out[PRESSURE_TAPS.name].append(serialize(cloud))
        cl = float(np.mean(pressures)) / -plant.dynamic_pressure_pa
        vector = new_message("geometry_msgs/msg/Vector3", x=cl, y=0.0, z=0.0)
        out[WING_COEFFICIENTS.name].append(
            serialize(new_message(WING_COEFFICIENTS.type, header=header, vector=vector))
        )
    return out


def _count_bag(bag: Path) -> dict[str, int]:
    from rosbags.highlevel import AnyReader

    counts: dict[str, int] = {}
    with AnyReader([bag]) as reader:
        for conn, _, _ in reader.messages():
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
    return counts


def run(seconds: float, rate_hz: float, params: list[str], workdir: Path) -> dict[str, Any]:
    from rig_runtime.node import Node

    count = round(seconds * FS)
    print(f"serializing {count} samples x {len(TOPICS)} topics ...", file=sys.stderr)
    payloads = _payloads(count, FS)
    payload_bytes = sum(len(p) for msgs in payloads.values() for p in msgs)
    env = graph_env()
    join_graph(env)
    bag = workdir / "bag"
    topics = "[" + ",".join(f"'{t.name}'" for t in TOPICS) + "]"
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    node = Node("bench_recorder_feed", argv=[])
    try:
        pubs: dict[str, Any] = {
            t.name: node.create_publisher(t.type, t.name, t.qos) for t in TOPICS
        }
        with Processes(env, log_dir=workdir / "logs") as procs:
            args = ["--ros-args", "-p", f"output:={bag}", "-p", f"topics:={topics}"]
            for p in params:
                args += ["-p", p]
            recorder = procs.start_entry("rig_runtime", "recorder", *args, name="recorder")
            if not wait_for(lambda: all(p.subscription_count() for p in pubs.values()), 60):
                raise RuntimeError(
                    "recorder did not subscribe within 60 s: " + procs.log("recorder")
                )
            startup = psutil.Process(recorder.pid).cpu_times()
            startup_s = startup.user + startup.system  # imports, DDS, discovery
            t0 = time.monotonic()
            sent = 0
            while sent < count:
                due = min(count, int((time.monotonic() - t0) * rate_hz) + 1)
                for k in range(sent, due):
                    for topic, pub in pubs.items():
                        pub.publish_raw(payloads[topic][k])
                sent = due
                time.sleep(0.002)
            publish_s = time.monotonic() - t0
            procs.stop_all(grace_s=30.0)  # SIGINT: the recorder drains, then closes the bag
            if recorder.returncode != 0:
                raise RuntimeError(f"recorder exit {recorder.returncode}: {procs.log('recorder')}")
    finally:
        node.close()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu_s = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    files = sorted(bag.glob("*.mcap"))
    size = sum(f.stat().st_size for f in files)
    counts = _count_bag(bag)
    lost = sum(max(0, count - counts.get(t.name, 0)) for t in TOPICS)
    scale = CAMPAIGN_EXPERIMENT_S / seconds
    return {
        "seconds": seconds,
        "rate_hz": rate_hz,
        "publish_wall_s": round(publish_s, 2),
        "messages_published": count * len(TOPICS),
        "messages_lost": lost,
        "files": len(files),
        "mb_written": round(size / 1e6, 2),
        "payload_mb": round(payload_bytes / 1e6, 2),
        "compression_ratio": round(payload_bytes / size, 2),
        "recorder_cpu_s": round(cpu_s, 2),
        "kb_per_experiment_s": round(size / 1e3 / seconds, 1),
        "campaign_mb_scaled": round(size / 1e6 * scale, 1),
        "recorder_startup_cpu_s": round(startup_s, 2),
        # Start-up once, the rest in proportion to the experiment's length.
        "campaign_recorder_cpu_s_scaled": round(startup_s + (cpu_s - startup_s) * scale, 1),
        "recorder_params": params,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="experiment seconds to record")
    parser.add_argument("--rate-hz", type=float, default=200.0, help="samples/s per topic")
    parser.add_argument("-p", dest="params", action="append", default=[], help="NAME:=VALUE")
    parser.add_argument("--keep", default=None, help="record into this directory and keep it")
    args = parser.parse_args()
    if args.keep:
        workdir = Path(args.keep)
        workdir.mkdir(parents=True, exist_ok=False)
        result = run(args.seconds, args.rate_hz, args.params, workdir)
    else:
        with tempfile.TemporaryDirectory(prefix="bench_recorder_") as tmp:
            result = run(args.seconds, args.rate_hz, args.params, Path(tmp))
    print(
        f"{result['seconds']:.0f} experiment s published at {result['rate_hz']:.0f} Hz: "
        f"{result['mb_written']} MB in "
        f"{result['files']} file(s) ({result['kb_per_experiment_s']} kB per experiment s), "
        f"compression ratio {result['compression_ratio']}, recorder CPU "
        f"{result['recorder_cpu_s']} s ({result['recorder_startup_cpu_s']} s of it start-up), "
        f"{result['messages_lost']} of "
        f"{result['messages_published']} messages lost"
    )
    print(
        f"scaled to the default campaign ({CAMPAIGN_EXPERIMENT_S:.0f} s): "
        f"{result['campaign_mb_scaled']} MB, "
        f"recorder CPU {result['campaign_recorder_cpu_s_scaled']} s"
    )
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
