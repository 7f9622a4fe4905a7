"""Scanner driver node against the simulated scanner (PWSC frames over UDP loopback).

``python -m wing_sim.sim_scanner`` streams the WingPlant's pressures (plus fixed zero
offsets, after wind-off frames) with deliberate faults; the ``scanner`` node publishes them on
``/pressure/taps``. The test process requests a zero on ``/pressure/tare`` during the wind-off
frames and checks the pressures against the plant run here with the same seed and α.
"""

import math
import re
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from graph_support import subscribe_diagnostics

from pressure_scanner.tap_cloud import read_cloud
from rig_runtime.interface import PRESSURE_TAPS, PRESSURE_TARE
from rig_runtime.messages import stamp_to_ns
from rig_runtime.node import Node
from rig_testing.processes import Processes, graph_env, join_graph, wait_for
from wing_sim.plant import WingPlant
from wing_sim.sim_scanner import alpha_rad, zero_offsets_pa

RATE_HZ = 200.0
PERIOD_NS = 5_000_000
SEED = 7
CHANNELS = 64
OFFSET_PA = 20.0
WIND_OFF = 300  # frames 0..299 wind off
FRAMES = 450
TARE_FRAMES = 60
ALPHA_DEG, AMP_DEG, FREQ_HZ = 8.0, 2.0, 1.0
DROPPED = {350, 351, 352}
DUPLICATED = {360, 370}
SWAPPED = 380  # sent after 381: late, discarded
BAD_MAGIC = 390  # a malformed datagram before frame 390
NOISE_PA = 0.5  # wind-off reading noise (sim_scanner default)


class ScannerClient:
    def __init__(self) -> None:
        self.node = Node("scanner_test", argv=[])
        self.tare = self.node.create_publisher(PRESSURE_TARE.type, PRESSURE_TARE.name)
        self.frames: list[tuple[int, np.ndarray]] = []
        self.diagnostics: list[dict[str, str]] = []
        self.subs = [
            self.node.create_subscription(
                PRESSURE_TAPS.type, PRESSURE_TAPS.name, self._on_taps, PRESSURE_TAPS.qos
            ),
            subscribe_diagnostics(self.node, "pressure scanner", self.diagnostics),
        ]

    def _on_taps(self, msg: Any) -> None:
        _, pressures = read_cloud(msg)
        self.frames.append((stamp_to_ns(msg.header.stamp), pressures))

    def close(self) -> None:
        self.node.close()


def test_scanner_node_publishes_plant_pressures_counts_faults_and_tares(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    env = graph_env()
    join_graph(env, monkeypatch.setenv)
    client = ScannerClient()
    try:
        with Processes(env, log_dir=tmp_path) as procs:
            node = procs.start_entry(
                "pressure_scanner",
                "scanner",
                *("--ros-args", "-p", "port:=0", "-p", "bind_host:=127.0.0.1"),
                *("-p", "source_host:=127.0.0.1", "-p", f"tare_frames:={TARE_FRAMES}"),
                *("-p", "taps_qos:=stream", "-p", "diagnostics_period_s:=0.2"),
                name="scanner",
            )
            port_re = re.compile(r"scanner frames on UDP port (\d+)")
            wait_for(
                lambda: bool(port_re.search(procs.log("scanner"))) or node.poll() is not None, 30
            )
            found = port_re.search(procs.log("scanner"))
            assert found, procs.log("scanner")
            port = int(found.group(1))
            ready = client.node.spin_until(
                lambda: (
                    client.tare.subscription_count() > 0
                    and all(sub.publisher_count() > 0 for sub in client.subs)
                ),
                30,
            )
            assert ready, "scanner node not discovered"
            t_start_ns = time.time_ns()
            sim = procs.start_python(
                "-m wing_sim.sim_scanner",
                *("--port", str(port), "--rate", str(RATE_HZ), "--frames", str(FRAMES)),
                *("--alpha-deg", str(ALPHA_DEG), "--alpha-amp-deg", str(AMP_DEG)),
                *("--alpha-freq-hz", str(FREQ_HZ), "--seed", str(SEED)),
                *("--channels", str(CHANNELS), "--units", "KPA"),
                *("--zero-offset-pa", str(OFFSET_PA), "--wind-off-frames", str(WIND_OFF)),
                *("--drop", ",".join(map(str, sorted(DROPPED)))),
                *("--duplicate", ",".join(map(str, sorted(DUPLICATED)))),
                *("--swap", str(SWAPPED), "--bad-magic", str(BAD_MAGIC)),
                name="sim_scanner",
            )
            # Zero while the wind is off: a few untared frames first, to see the offsets.
            assert client.node.spin_until(lambda: len(client.frames) >= 5, 20), procs.log(
                "sim_scanner"
            )
            frames_before_tare = len(client.frames)
            client.tare.publish(client.node.new_message("std_msgs/msg/Bool", data=True))
            expected_count = FRAMES - len(DROPPED) - 1  # the swapped frame arrives late
            done = client.node.spin_until(
                lambda: len(client.frames) >= expected_count and sim.poll() is not None, 30
            )
            assert done, f"{len(client.frames)} frames\n" + procs.log("scanner")
            diag = {}
            client.node.spin_until(
                lambda: (
                    bool(client.diagnostics)
                    and client.diagnostics[-1].get("published") == str(expected_count)
                ),
                5,
            )
            diag = client.diagnostics[-1] if client.diagnostics else {}
            assert len(client.frames) == expected_count  # nothing extra
            scanner_log = procs.log("scanner")
    finally:
        client.close()

    # Stamps are the scanner's acquisition instants: t0 + k / rate, exactly, per frame counter.
    stamps = np.array([s for s, _ in client.frames], dtype=np.int64)
    assert abs(stamps[0] - t_start_ns) < 10e9
    assert np.all((stamps - stamps[0]) % PERIOD_NS == 0)
    k = (stamps - stamps[0]) // PERIOD_NS
    expected_k = sorted(set(range(FRAMES)) - DROPPED - {SWAPPED})
    np.testing.assert_array_equal(k, expected_k)  # in order, none twice, the lost ones absent
    pressures = np.array([p for _, p in client.frames])
    assert pressures.shape == (expected_count, 49)

    # Before the tare the wind-off readings are the scanner's zero offsets (+ noise).
    offsets = zero_offsets_pa(CHANNELS, OFFSET_PA, SEED)[:49]
    assert np.abs(offsets).max() > 10.0
    untared = np.all(np.abs(pressures - offsets) < 5 * NOISE_PA, axis=1)
    tared = np.all(np.abs(pressures) < 5 * NOISE_PA, axis=1)
    k_tared = int(k[np.argmax(tared)])
    assert np.all(untared[k < k_tared]), "wind-off readings before the tare are not the offsets"
    assert k_tared >= frames_before_tare - 1 + TARE_FRAMES  # the mean of TARE_FRAMES frames
    assert k_tared < WIND_OFF - 50, f"tare finished at frame {k_tared}, too close to wind on"
    assert np.all(tared[(k >= k_tared) & (k < WIND_OFF)])

    # Wind on: the plant's pressures for the same seed and α; only the tare's noise remains.
    plant = WingPlant(seed=SEED)
    expected = np.array(
        [
            plant.step(alpha_rad(j, RATE_HZ, ALPHA_DEG, AMP_DEG, FREQ_HZ))
            for j in range(FRAMES - WIND_OFF)
        ]
    )
    on = k >= WIND_OFF
    error = pressures[on] - expected[k[on] - WIND_OFF]
    tare_noise = NOISE_PA / math.sqrt(TARE_FRAMES)
    assert np.sqrt(np.mean(error**2)) < 2 * tare_noise, np.sqrt(np.mean(error**2))
    assert np.abs(error).max() < 6 * tare_noise, np.abs(error).max()
    assert np.ptp(expected[:, 0]) > 1.0  # the comparison sees a moving wing, not a constant

    # Faults are counted, not patched.
    assert diag.get("published") == str(expected_count), diag
    assert diag["frames_lost"] == str(len(DROPPED))
    assert diag["frames_duplicated"] == str(len(DUPLICATED))
    assert diag["frames_late"] == "1"
    assert diag["invalid_frames"] == "1"
    assert diag["tared"] == "True"
    assert "after_frame=349, missing=3" in diag["recent_gaps"]
    assert "tare done" in scanner_log
