"""Hardware actuator node against the simulated controller over UDP loopback (PWAC).

Three processes' worth of graph: this test process publishes ``/pitch/command`` in real time
(the hw node's safety layer runs on the wall clock), ``hw_actuator`` forwards setpoints to
``python -m pitch_actuator.sim_controller`` and publishes its feedback on ``/pitch/state`` with
the controller's stamps. The controller's audit file shows what it actually applied.
"""

import json
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from graph_support import PeerReaders, subscribe_diagnostics, wait_diagnostics

from multisine_gen.plan_format import segment_event_fields
from rig_runtime.interface import (
    EXPERIMENT_SEGMENT,
    PITCH_COMMAND,
    PITCH_JOINT,
    PITCH_STATE,
    joint_position,
)
from rig_runtime.messages import set_stamp, stamp_to_ns
from rig_runtime.node import Node
from rig_testing.processes import Processes, graph_env, join_graph, wait_for

RATE_HZ = 200.0  # controller rate
COMMAND_HZ = 100.0  # commands from this test, paced by the wall clock
HOLD_S = 0.3
RAMP_DEG_S = 20.0
# The host's watchdog (its safety governor) in the limits test. The commands come from this
# process and pass two others, which a loaded 2-core machine can deschedule for longer than the
# governor's 0.25 s; a trip would ramp the pitch away from the limit under test. The test is
# about the limits and the hold and ramp once commands stop; the trip itself is the governor's
# unit tests' (test_safety_governor.py).
WATCHDOG_S = 1.0
# The controller's watchdog in the graph tests. The link feeds it every 50 ms; in polling
# mode a descheduled hw_actuator process stops feeding it, as intended (controller_link.py),
# and a loaded 2-core machine can deschedule it past the controller's default 0.25 s. These
# tests are about forwarding and the host's limits, so they allow 1 s, and
# test_controller_udp_link.py tests the 0.25 s trip itself.
FORWARDING_WATCHDOG_S = 1.0
SAFE_DEG = 2.0


class HwClient:
    """In-process DDS node: publishes commands in real time, collects states and diagnostics."""

    def __init__(self) -> None:
        self.node = Node("hw_test", argv=[])
        self.cmd = self.node.create_publisher(
            PITCH_COMMAND.type, PITCH_COMMAND.name, PITCH_COMMAND.qos
        )
        self.segment_pub = self.node.create_publisher(
            EXPERIMENT_SEGMENT.type, EXPERIMENT_SEGMENT.name, EXPERIMENT_SEGMENT.qos
        )
        self.states: list[tuple[int, float]] = []  # controller stamp [ns], pitch [deg]
        self.diagnostics: list[tuple[str, dict[str, str]]] = []  # hardware_id, values
        self.sent: list[tuple[int, float]] = []  # wall ns, command [rad]
        self.peers = PeerReaders(self.node)
        self.subs = [
            self.node.create_subscription(
                PITCH_STATE.type, PITCH_STATE.name, self._on_state, PITCH_STATE.qos
            ),
            subscribe_diagnostics(
                self.node, "pitch actuator safety", self.diagnostics, hardware_id=True
            ),
        ]

    def _on_state(self, msg: Any) -> None:
        pitch_rad = joint_position(msg, PITCH_JOINT)
        assert pitch_rad is not None, msg
        pitch = math.degrees(pitch_rad)
        self.states.append((stamp_to_ns(msg.header.stamp), pitch))

    def wait_ready(self, timeout_s: float = 30.0) -> bool:
        # States flow as soon as the node has fed the controller a heartbeat.
        return self.node.spin_until(
            lambda: (
                self.cmd.subscription_count() > 0
                and self.segment_pub.subscription_count() > 0
                and all(sub.publisher_count() > 0 for sub in self.subs)
                and self.peers.matched([PITCH_COMMAND.name, EXPERIMENT_SEGMENT.name])
                and len(self.states) > 10
            ),
            timeout_s,
        )

    def command(self, value_rad: float) -> None:
        msg = self.node.new_message(
            "sensor_msgs/msg/JointState", name=[PITCH_JOINT], position=[value_rad]
        )
        now = time.time_ns()
        set_stamp(msg.header.stamp, now)
        self.cmd.publish(msg)
        self.sent.append((now, value_rad))

    def stream(self, value_deg: Callable[[float], float], duration_s: float) -> int:
        """Command value_deg(seconds since start) at COMMAND_HZ for duration_s of wall time;
        returns the wall-clock ns at the start."""
        t0_ns = time.time_ns()
        start = time.monotonic()
        k = 0
        while True:
            elapsed = time.monotonic() - start
            if elapsed >= duration_s:
                return t0_ns
            self.command(math.radians(value_deg((time.time_ns() - t0_ns) / 1e9)))
            k += 1
            next_tick = start + k / COMMAND_HZ
            while (remaining := next_tick - time.monotonic()) > 0:
                self.node.spin_once(remaining)

    def end_plan(self) -> None:
        """The generator's plan_end event (multisine_gen.generator_node)."""
        event = {"event": "plan_end", "samples": len(self.sent), "fs": COMMAND_HZ}
        msg = self.node.new_message(EXPERIMENT_SEGMENT.type, **segment_event_fields(event))
        if self.sent:
            set_stamp(msg.header.stamp, self.sent[-1][0])  # the last command's stamp
        self.segment_pub.publish(msg)

    def series(self) -> tuple[np.ndarray, np.ndarray]:
        stamps = np.array([s for s, _ in self.states], dtype=np.int64)
        return stamps, np.array([p for _, p in self.states])

    def wait_diagnostics(
        self, predicate: Callable[[dict[str, str]], bool], timeout_s: float = 10.0
    ) -> tuple[str, dict[str, str]]:
        return wait_diagnostics(
            self.node, self.diagnostics, predicate, timeout_s, values=lambda e: e[1]
        )

    def close(self) -> None:
        self.node.close()


def _audit(path: Path) -> list[dict[str, Any]]:
    if not path.exists():
        return []
    lines = path.read_text().splitlines()
    return [json.loads(line) for line in lines if line.strip()]


@pytest.fixture
def rig(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Any:
    """start(**params) -> (client, processes, audit path): sim_controller + hw_actuator."""
    env = graph_env()
    join_graph(env, monkeypatch.setenv)
    client = HwClient()
    procs = Processes(env, log_dir=tmp_path)
    audit = tmp_path / "audit.jsonl"

    def start(
        controller_watchdog_s: float = 0.25, **params: object
    ) -> tuple[HwClient, Processes, Path]:
        procs.start_python(
            "-m pitch_actuator.sim_controller",
            *("--host", "127.0.0.1", "--port", "0", "--rate", str(RATE_HZ)),
            *("--min-deg", "-10", "--max-deg", "30", "--seed", "3"),
            *("--watchdog-timeout", str(controller_watchdog_s)),
            *("--audit-file", str(audit)),
            name="controller",
        )
        assert wait_for(lambda: procs.log("controller").strip() != "", 20), "controller silent"
        port = int(procs.log("controller").split()[0])
        args = ["--ros-args"]
        settings = {
            "controller_host": "127.0.0.1",
            "controller_port": port,
            "bind_host": "127.0.0.1",
            "state_qos": "stream",
            "diagnostics_period_s": 0.2,
            **params,
        }
        for key, value in settings.items():
            args += ["-p", f"{key}:={value}"]
        procs.start_entry("pitch_actuator", "hw_actuator", *args, name="hw_actuator")
        assert client.wait_ready(30), "no states from hw_actuator\n" + procs.log("hw_actuator")
        return client, procs, audit

    try:
        yield start
    finally:
        procs.stop_all()
        client.close()


def test_forwards_commands_and_tracks_a_sine_at_the_controller_rate(rig: Any) -> None:
    client, procs, audit = rig(controller_watchdog_s=FORWARDING_WATCHDOG_S)
    client.stream(lambda t: 10.0, 0.6)
    f, amp = 0.5, 5.0
    n_before = len(client.sent)
    t0_ns = client.stream(lambda t: 10.0 + amp * math.sin(2 * math.pi * f * t), 2.0)
    sine_sent = client.sent[n_before:]
    t_end_ns = sine_sent[-1][0]
    client.node.spin_until(lambda: client.states[-1][0] > t_end_ns + 50_000_000, 5.0)
    applied = [r for r in _audit(audit) if r["event"] == "apply"]
    modes = [r for r in _audit(audit) if r["event"] == "mode"]
    stamps, pitch = client.series()

    # /pitch/state at the controller's rate, with the controller's acquisition stamps.
    window = (stamps >= t0_ns) & (stamps <= t_end_ns)
    dt = np.diff(stamps[window]) / 1e9
    assert 0.95 / RATE_HZ <= np.median(dt) <= 1.05 / RATE_HZ, np.median(dt)
    assert window.sum() >= 0.85 * RATE_HZ * (t_end_ns - t0_ns) / 1e9, window.sum()
    assert np.all(np.diff(stamps) > 0)

    # Measured pitch follows the sine: gain ~1, small lag, small residual.
    fit = window & (stamps >= t0_ns + 300_000_000)
    tau = (stamps[fit] - t0_ns) / 1e9
    X = np.column_stack(
        [np.ones_like(tau), np.sin(2 * np.pi * f * tau), np.cos(2 * np.pi * f * tau)]
    )
    coef, *_ = np.linalg.lstsq(X, pitch[fit], rcond=None)
    gain = math.hypot(coef[1], coef[2]) / amp
    lag_s = math.atan2(-coef[2], coef[1]) / (2 * math.pi * f)
    residual = pitch[fit] - X @ coef
    assert abs(coef[0] - 10.0) < 0.05, coef
    # (a loaded machine delays some commands: the rms allows for a few held samples)
    assert abs(gain - 1.0) < 0.03, gain
    assert 0.0 < lag_s < 0.08, lag_s
    assert np.sqrt(np.mean(residual**2)) < 0.25
    print(f"sine: gain {gain:.4f}, lag {lag_s * 1e3:.1f} ms, rms {np.std(residual):.3f}°")

    # The commands reached the controller as setpoints: each commanded value was applied
    # (between two commands the rate limiter may apply an intermediate step, as it runs over
    # the time since its last update; such a step lies within one command increment).
    at_10 = next(
        i for i, r in enumerate(applied) if abs(r["position_rad"] - math.radians(10.0)) < 1e-12
    )  # the end of the rate-limited approach from 0°; the sine's setpoints follow
    values = np.sort([r["position_rad"] for r in applied[at_10 + 1 :]])
    commanded = np.array([v for _, v in sine_sent])
    idx = np.clip(np.searchsorted(values, commanded), 1, len(values) - 1)
    found = np.minimum(np.abs(values[idx] - commanded), np.abs(values[idx - 1] - commanded))
    assert np.mean(found < 1e-12) > 0.9, np.mean(found < 1e-12)
    idx = np.clip(np.searchsorted(np.sort(commanded), values), 1, len(commanded) - 1)
    c = np.sort(commanded)
    near = np.minimum(np.abs(c[idx] - values), np.abs(c[idx - 1] - values))
    step = 2 * math.pi * f * math.radians(amp) / COMMAND_HZ
    assert np.mean(near <= step + 1e-12) > 0.95, (near.max(), step)  # a stalled command: more
    # Heartbeats and setpoints kept the controller's watchdog fed.
    assert all(m["mode"] != "watchdog" for m in modes), modes

    # A diagnostics report from after the sine (the first ones may predate its last setpoints).
    hardware_id, diag = client.wait_diagnostics(
        lambda d: (
            int(d.get("states_published", 0)) > 500
            and int(d.get("setpoints_sent", 0)) >= len(values)
        )
    )
    assert hardware_id.startswith("pwac://127.0.0.1:")
    assert int(diag["feedback_received"]) >= int(diag["states_published"]) > 500
    assert int(diag["setpoints_sent"]) >= len(values)
    assert diag["refused"] == "0"
    assert procs.procs[1].poll() is None


def test_limits_on_host_then_hold_and_ramp_when_commands_stop(rig: Any) -> None:
    # Host limits inside the controller's hard limits (-10°..30°): clamping is the host's.
    client, _, audit = rig(
        controller_watchdog_s=FORWARDING_WATCHDOG_S,
        max_deg=25.0,
        min_deg=-5.0,
        watchdog_timeout_s=WATCHDOG_S,
        hold_s=HOLD_S,
        ramp_rate_deg_s=RAMP_DEG_S,
        safe_angle_deg=SAFE_DEG,
    )
    client.stream(lambda t: 60.0, 0.5)
    client.command(math.nan)
    client.stream(lambda t: 60.0, 0.2)
    high_end = time.time_ns()
    client.stream(lambda t: -40.0, 0.7)
    low_end = time.time_ns()
    client.stream(lambda t: 12.0, 0.5)
    t_last_ns = client.sent[-1][0]
    t_done_ns = t_last_ns + int((WATCHDOG_S + HOLD_S + 10.0 / RAMP_DEG_S + 0.4) * 1e9)
    assert client.node.spin_until(lambda: client.states[-1][0] > t_done_ns, 10.0)
    records = _audit(audit)
    stamps, pitch = client.series()

    # The controller followed the host throughout (a trip would ramp it to its safe angle).
    assert "watchdog" not in [r["mode"] for r in records if r["event"] == "mode"], records[:20]
    # The pitch settles at the host limits, inside the controller's wider hard limits.
    high = (stamps > high_end - 200_000_000) & (stamps < high_end)
    low = (stamps > low_end - 200_000_000) & (stamps < low_end)
    assert abs(np.mean(pitch[high]) - 25.0) < 0.03, pitch[high]
    assert abs(np.mean(pitch[low]) + 5.0) < 0.03, pitch[low]
    # No applied setpoint beyond the host limits, none non-finite: the controller never saw
    # the 60°, the −40° or the NaN.
    applied = np.degrees([r["position_rad"] for r in records if r["event"] == "apply"])
    # (The low limit is approached by the ramp: how close it comes in 0.7 s depends on timing.)
    assert applied.max() <= 25.0 + 1e-9 and applied.min() >= -5.0 - 1e-9, applied
    assert applied.max() == pytest.approx(25.0, abs=1e-3) and applied.min() < -4.99
    assert not [r for r in records if r["event"] in ("rejected_nonfinite", "invalid")]

    # Commands stop: hold 12° through the watchdog timeout and hold_s, then ramp to safe.
    t = (stamps - t_last_ns) / 1e9
    moved = np.flatnonzero((t > 0) & (np.abs(pitch - 12.0) > 0.1))
    assert moved.size, "pitch never left 12°"
    t_ramp = t[moved[0]]
    assert WATCHDOG_S + HOLD_S <= t_ramp <= WATCHDOG_S + HOLD_S + 0.15, t_ramp
    assert np.all(np.abs(pitch[(t > 0) & (t < t_ramp)] - 12.0) <= 0.1)
    after = t >= t_ramp - 0.05
    tr, pr = t[after], pitch[after]
    # 0.2 s windows: the controller stamps its cycles on the wall clock, so a late cycle
    # followed by a catch-up squeezes a few samples; allow 20 %.
    n = round(0.2 * RATE_HZ)
    slopes = np.abs(pr[n:] - pr[:-n]) / (tr[n:] - tr[:-n])
    assert slopes.max() <= 1.2 * RAMP_DEG_S, slopes.max()
    middle = (pr < 10.0) & (pr > 4.0)
    slope = np.polyfit(tr[middle], pr[middle], 1)[0]
    assert abs(-slope - RAMP_DEG_S) < 0.1 * RAMP_DEG_S, slope
    at_safe = t > t_ramp + 10.0 / RAMP_DEG_S + 0.15
    assert at_safe.sum() >= 20
    assert np.all(np.abs(pitch[at_safe] - SAFE_DEG) < 0.06)

    _, diag = client.wait_diagnostics(lambda d: d.get("mode") == "safe")
    assert diag["refused"] == "1"
    assert int(diag["clamped"]) >= 100
    assert int(diag["watchdog_trips"]) == 1
    assert "controller_limit" not in diag  # the controller never had to clamp


def test_the_plans_end_then_silence_holds_and_ramps_with_no_error_line(rig: Any) -> None:
    """After the generator's plan_end the silence is the plan's end: the host holds, then ramps
    to the safe angle, with no watchdog trip and no ERROR line in its log."""
    client, procs, _ = rig(
        controller_watchdog_s=FORWARDING_WATCHDOG_S,
        watchdog_timeout_s=WATCHDOG_S,
        hold_s=HOLD_S,
        ramp_rate_deg_s=RAMP_DEG_S,
        safe_angle_deg=SAFE_DEG,
    )
    client.stream(lambda t: 12.0, 0.5)
    client.end_plan()
    # Commands flow until the node's diagnostics show it took the plan's end, then stop.
    deadline = time.monotonic() + 30.0
    while not any(d.get("stream_end_expected") == "True" for _, d in client.diagnostics):
        assert time.monotonic() < deadline, "the node never took the plan's end"
        client.stream(lambda t: 12.0, 0.1)
    _, diag = client.wait_diagnostics(lambda d: d.get("mode") == "safe", 30.0)
    assert diag["watchdog_trips"] == "0", diag
    n = len(client.states)
    assert client.node.spin_until(lambda: len(client.states) >= n + 40, 10.0)
    stamps, pitch = client.series()
    after = pitch[stamps > client.sent[-1][0]]
    assert after.max() <= 12.1 and np.all(np.abs(after[-20:] - SAFE_DEG) < 0.1), after
    log = procs.log("hw_actuator")
    assert "the plan has ended" in log, log
    assert [line for line in log.splitlines() if "ERROR" in line] == [], log
