"""Lift node faults through DDS: missing taps, uncovered surfaces, taps ahead of their pitch.

The test process plays the actuator and the scanner: it publishes ``/pitch/state`` and
``/pressure/taps`` (the WingPlant's pressures at a fixed α) and reads ``/wing/coefficients``,
``/wing/coefficients/progress`` and ``/diagnostics`` of the ``lift`` node running as a process.
"""

import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from graph_support import PeerReaders, subscribe_diagnostics, wait_diagnostics

from pressure_scanner.integration import PressureIntegrator
from pressure_scanner.tap_cloud import fill_cloud
from pressure_scanner.taps import load_taps
from rig_runtime.interface import (
    PITCH_JOINT,
    PITCH_STATE,
    PRESSURE_TAPS,
    WING_COEFFICIENTS,
    WING_PROGRESS,
)
from rig_runtime.messages import set_stamp, stamp_to_ns
from rig_runtime.node import Node
from rig_testing.processes import Processes, graph_env, join_graph
from wing_sim.plant import WingPlant
from wing_sim.wing_params import WingParams

PERIOD_NS = 5_000_000
ALPHA_DEG = 8.0


class LiftClient:
    def __init__(self) -> None:
        self.node = Node("lift_test", argv=[])
        self.state_pub = self.node.create_publisher(
            PITCH_STATE.type, PITCH_STATE.name, PITCH_STATE.qos
        )
        self.taps_pub = self.node.create_publisher(
            PRESSURE_TAPS.type, PRESSURE_TAPS.name, PRESSURE_TAPS.qos
        )
        self.out: list[tuple[int, np.ndarray]] = []
        self.progress: list[int] = []  # the stamps /wing/coefficients/progress carried
        self.diagnostics: list[dict[str, str]] = []
        self.peers = PeerReaders(self.node)
        self.subs = [
            self.node.create_subscription(
                WING_COEFFICIENTS.type, WING_COEFFICIENTS.name, self._on_out, WING_COEFFICIENTS.qos
            ),
            self.node.create_subscription(
                WING_PROGRESS.type,
                WING_PROGRESS.name,
                lambda msg: self.progress.append(stamp_to_ns(msg.stamp)),
                WING_PROGRESS.qos,
            ),
            subscribe_diagnostics(self.node, "pressure integration", self.diagnostics),
        ]
        taps = load_taps()
        wing = WingParams()
        self.tap_xyz = taps.xyz_m(wing.chord_m, wing.span_m)
        self.t0_ns = time.time_ns() // PERIOD_NS * PERIOD_NS

    def _on_out(self, msg: Any) -> None:
        v = msg.vector
        self.out.append((stamp_to_ns(msg.header.stamp), np.array([v.x, v.y, v.z])))

    def wait_ready(self, timeout_s: float = 30.0) -> bool:
        return self.node.spin_until(
            lambda: (
                self.state_pub.subscription_count() > 0
                and self.taps_pub.subscription_count() > 0
                and all(sub.publisher_count() > 0 for sub in self.subs)
                and self.peers.matched([PITCH_STATE.name, PRESSURE_TAPS.name])
            ),
            timeout_s,
        )

    def stamp(self, k: int) -> int:
        return self.t0_ns + k * PERIOD_NS

    def publish_state(self, k: int, alpha_rad: float) -> None:
        msg = self.node.new_message(
            "sensor_msgs/msg/JointState", name=[PITCH_JOINT], position=[alpha_rad], velocity=[0.0]
        )
        set_stamp(msg.header.stamp, self.stamp(k))
        self.state_pub.publish(msg)

    def publish_taps(self, k: int, pressures_pa: np.ndarray) -> None:
        cloud = self.node.new_message("sensor_msgs/msg/PointCloud2")
        set_stamp(cloud.header.stamp, self.stamp(k))
        cloud.header.frame_id = "wing"
        fill_cloud(cloud, self.node.new_message, self.tap_xyz, pressures_pa)
        self.taps_pub.publish(cloud)

    def wait_outputs(self, n: int, timeout_s: float = 10.0) -> bool:
        return self.node.spin_until(lambda: len(self.out) >= n, timeout_s)

    def wait_progress(self, stamp: int, timeout_s: float = 10.0) -> bool:
        return self.node.spin_until(lambda: stamp in self.progress, timeout_s)

    def wait_diagnostics(self, predicate: Any, timeout_s: float = 10.0) -> dict[str, str]:
        return wait_diagnostics(self.node, self.diagnostics, predicate, timeout_s)

    def close(self) -> None:
        self.node.close()


@pytest.fixture
def lift(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Any:
    env = graph_env()
    join_graph(env, monkeypatch.setenv)
    client = LiftClient()
    with Processes(env, log_dir=tmp_path) as procs:
        try:
            procs.start_entry(
                "pressure_scanner",
                "lift",
                *("--ros-args", "-p", "diagnostics_period_s:=0.1"),
                name="lift",
            )
            assert client.wait_ready(30), "lift not discovered\n" + procs.log("lift")
            yield client, procs
        finally:
            client.close()


@pytest.fixture(scope="module")
def wing_pressures() -> np.ndarray:
    """Tap pressures of the simulated wing settled at ALPHA_DEG (Pa, tap order)."""
    plant = WingPlant(seed=2)
    alpha = math.radians(ALPHA_DEG)
    for _ in range(300):
        pressures = plant.step(alpha)
    return np.asarray(pressures, dtype=np.float64)


def test_missing_taps_are_excluded_or_invalidate_the_sample(
    lift: Any, wing_pressures: np.ndarray
) -> None:
    client, procs = lift
    taps = load_taps()
    alpha = math.radians(ALPHA_DEG)
    three = [int(taps.upper[8]), int(taps.upper[16]), int(taps.lower[12])]  # U09, U17, L13
    assert [taps.names[i] for i in three] == ["U09", "U17", "L13"]

    # k = 0: all taps; k = 1: three isolated taps NaN.
    for k, nan_taps in enumerate(([], three)):
        p = wing_pressures.copy()
        p[nan_taps] = np.nan
        client.publish_state(k, alpha)
        client.publish_taps(k, p)
    assert client.wait_outputs(2), procs.log("lift")
    (s0, ref), (s1, partial) = client.out[:2]
    assert (s0, s1) == (client.stamp(0), client.stamp(1))
    # The node integrates what went over the wire (float32 pressures) at the state's α.
    expected = PressureIntegrator(taps).integrate(
        wing_pressures.astype(np.float32), alpha, WingParams().dynamic_pressure_pa
    )
    np.testing.assert_allclose(ref, [expected.cl[0], expected.cd[0], expected.cm[0]], rtol=1e-9)
    assert 0.5 < ref[0] < 1.2  # lift of the wing at 8°
    assert np.all(np.isfinite(partial))
    assert abs(partial[0] / ref[0] - 1) < 0.03, (partial, ref)
    assert abs(partial[1] / ref[1] - 1) < 0.03, (partial, ref)
    # C_m is a small number (about −0.015 here): an absolute bound instead of a relative one.
    assert abs(partial[2] - ref[2]) < 0.003, (partial, ref)
    diag = client.wait_diagnostics(lambda d: d.get("published") == "2")
    assert diag["excluded_taps"] == "U09: 1, U17: 1, L13: 1"
    assert diag["invalid"] == "0"

    # k = 2, 3: the front half, then the rear half of the upper surface NaN -> no number.
    for k, half in ((2, taps.upper[:12]), (3, taps.upper[12:])):
        p = wing_pressures.copy()
        p[half] = np.nan
        client.publish_state(k, alpha)
        client.publish_taps(k, p)
    assert client.wait_outputs(4), procs.log("lift")
    for stamp, coefficients in client.out[2:4]:
        assert stamp in (client.stamp(2), client.stamp(3))
        assert np.all(np.isnan(coefficients)), coefficients
    diag = client.wait_diagnostics(lambda d: d.get("published") == "4")
    assert diag["invalid"] == "2"
    excluded = dict(item.split(": ") for item in diag["excluded_taps"].split(", "))
    assert excluded["U09"] == "2" and excluded["U17"] == "2" and excluded["L13"] == "1"
    assert all(excluded[taps.names[i]] in ("1", "2") for i in taps.upper)
    assert len(client.out) == 4


def test_taps_ahead_of_their_pitch_wait_for_it(lift: Any, wing_pressures: np.ndarray) -> None:
    client, procs = lift
    alpha = math.radians(ALPHA_DEG)
    client.publish_state(0, alpha)
    client.publish_taps(0, wing_pressures)
    assert client.wait_outputs(1), procs.log("lift")
    ref = client.out[0][1]
    # Taps 1..5 arrive before any pitch sample with their stamps: no output yet.
    for k in range(1, 6):
        client.publish_taps(k, wing_pressures)
    client.node.spin_until(lambda: len(client.out) > 1, 0.5)
    assert len(client.out) == 1, "taps were processed without their pitch"
    diag = client.wait_diagnostics(lambda d: d.get("pending") == "5")
    assert diag["alpha_missing"] == "0"
    # The states arrive: exactly one output per taps sample, with the taps' stamps, in order.
    for k in range(1, 6):
        client.publish_state(k, alpha)
    assert client.wait_outputs(6), procs.log("lift")
    client.node.spin_until(lambda: len(client.out) > 6, 0.5)  # anything extra would show now
    stamps = [s for s, _ in client.out]
    assert stamps == [client.stamp(k) for k in range(6)]
    for _, coefficients in client.out[1:]:
        np.testing.assert_array_equal(coefficients, ref)  # same pressures, same α
    diag = client.wait_diagnostics(lambda d: d.get("published") == "6")
    assert diag["pending"] == "0"
    assert diag["alpha_missing"] == "0"
    assert diag["invalid"] == "0"


def test_the_progress_carries_the_latest_published_stamp(
    lift: Any, wing_pressures: np.ndarray
) -> None:
    """The generator's credit (multisine_gen.pacing): the stamp of the last coefficients sample
    published, never of taps still waiting for their pitch."""
    client, procs = lift
    alpha = math.radians(ALPHA_DEG)
    client.publish_state(0, alpha)
    client.publish_taps(0, wing_pressures)
    assert client.wait_progress(client.stamp(0)), procs.log("lift")
    for k in range(1, 4):
        client.publish_taps(k, wing_pressures)
    client.wait_diagnostics(lambda d: d.get("pending") == "3")
    client.node.spin_until(lambda: len(client.progress) > 1, 0.5)  # a report would show now
    assert client.progress == [client.stamp(0)], "progress past what was published"
    for k in range(1, 4):
        client.publish_state(k, alpha)
    assert client.wait_progress(client.stamp(3)), procs.log("lift")
    assert client.wait_outputs(4)
    published = {s for s, _ in client.out}
    assert set(client.progress) <= published
    assert client.progress == sorted(set(client.progress)), "a stamp again, or out of order"


def test_taps_whose_state_is_still_in_the_reader_at_shutdown_get_their_pitch(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The graph stops with a taps sample waiting for its pitch and that state received but
    not yet delivered: the lift takes it before it releases the taps (one valid sample, none
    without pitch)."""
    from pressure_scanner.lift_node import LiftNode

    join_graph(graph_env(), monkeypatch.setenv)
    lift = LiftNode([])
    client = LiftClient()
    try:
        assert client.node.spin_until(
            lambda: (
                client.state_pub.subscription_count() > 0
                and client.taps_pub.subscription_count() > 0
            ),
            30.0,
        )
        plant = WingPlant(WingParams(), load_taps(), seed=0)
        client.publish_taps(0, plant.step(math.radians(ALPHA_DEG)))
        assert lift.spin_until(lambda: lift.alignment.pending_count == 1, 10.0)
        client.publish_state(0, math.radians(ALPHA_DEG))
        # In the lift's reader (acknowledged), not delivered: the lift has not spun since.
        from rclpy.duration import Duration

        assert client.state_pub.handle.wait_for_all_acked(Duration(seconds=10))
    finally:
        lift.close()
        client.close()
    assert lift.counts == {"published": 1, "invalid": 0, "alpha_missing": 0}
