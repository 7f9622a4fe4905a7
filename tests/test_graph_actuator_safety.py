"""Safety of the simulated actuator node seen through DDS (docs/design.md §8).

The test process commands ``sim_actuator`` (a separate process) on ``/pitch/command`` and reads
``/pitch/state`` and ``/diagnostics``: out-of-range commands are clamped to the limits, NaN/inf
commands are refused (a state still comes back for their stamp), and a lost command stream or a
``/pitch/stop`` request makes the pitch hold, then ramp to the safe angle at the ramp rate.
Times below are experiment time: the states' stamps (5 ms apart at fs = 200 Hz).
"""

import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from graph_support import PeerReaders, subscribe_diagnostics, wait_diagnostics

from multisine_gen.plan_format import segment_event_fields
from rig_runtime.interface import (
    ALPHA_TRUE_JOINT,
    EXPERIMENT_SEGMENT,
    PITCH_COMMAND,
    PITCH_JOINT,
    PITCH_STATE,
    PITCH_STOP,
    joint_position,
)
from rig_runtime.messages import set_stamp, stamp_to_ns
from rig_runtime.node import Node
from rig_testing.processes import Processes, graph_env, join_graph, wait_for

FS = 200.0
PERIOD_NS = 5_000_000
NOISE_DEG = 0.01  # logged-pitch noise std (node default)
ENCODER_DEG = 0.005  # logged-pitch quantisation (node default)
# A logged sample may differ from the true pitch by noise (5 sigma) plus half a quantum.
MEASUREMENT_TOL_DEG = 5 * NOISE_DEG + ENCODER_DEG / 2

# Small hold and fast ramp so the whole hold -> ramp -> safe sequence takes about a second.
HOLD_S = 0.3
RAMP_DEG_S = 20.0
WATCHDOG_S = 0.25
SAFE_DEG = 2.0


class ActuatorClient:
    """In-process DDS node: commands the actuator and collects its states and diagnostics."""

    def __init__(self) -> None:
        self.node = Node("safety_test", argv=[])
        self.cmd = self.node.create_publisher(
            PITCH_COMMAND.type, PITCH_COMMAND.name, PITCH_COMMAND.qos
        )
        self.stop_pub = self.node.create_publisher(PITCH_STOP.type, PITCH_STOP.name)
        self.segment_pub = self.node.create_publisher(
            EXPERIMENT_SEGMENT.type, EXPERIMENT_SEGMENT.name, EXPERIMENT_SEGMENT.qos
        )
        self.states: list[tuple[int, float, float]] = []  # stamp, pitch [deg], alpha_true [deg]
        self.diagnostics: list[dict[str, str]] = []
        self.peers = PeerReaders(self.node)
        self.subs = [
            self.node.create_subscription(
                PITCH_STATE.type, PITCH_STATE.name, self._on_state, PITCH_STATE.qos
            ),
            subscribe_diagnostics(self.node, "pitch actuator safety", self.diagnostics),
        ]
        self.t0_ns = time.time_ns() // PERIOD_NS * PERIOD_NS
        self.next_k = 0

    def _on_state(self, msg: Any) -> None:
        pitch_rad = joint_position(msg, PITCH_JOINT)
        alpha_rad = joint_position(msg, ALPHA_TRUE_JOINT)
        assert pitch_rad is not None and alpha_rad is not None, msg
        pitch, alpha = math.degrees(pitch_rad), math.degrees(alpha_rad)
        self.states.append((stamp_to_ns(msg.header.stamp), pitch, alpha))

    def wait_ready(self, timeout_s: float = 30.0) -> bool:
        return self.node.spin_until(
            lambda: (
                self.cmd.subscription_count() > 0
                and self.stop_pub.subscription_count() > 0
                and self.segment_pub.subscription_count() > 0
                and all(sub.publisher_count() > 0 for sub in self.subs)
                and self.peers.matched(
                    [PITCH_COMMAND.name, PITCH_STOP.name, EXPERIMENT_SEGMENT.name]
                )
            ),
            timeout_s,
        )

    def stamp(self, k: int) -> int:
        return self.t0_ns + k * PERIOD_NS

    def stamps_seen(self) -> set[int]:
        return {s for s, _, _ in self.states}

    def drive(self, commands_deg: list[float], window: int = 10, timeout_s: float = 30.0) -> None:
        """Send commands k, k+1, ... (at most ``window`` unanswered) and wait for every state."""
        deadline = time.monotonic() + timeout_s
        first = self.next_k
        for value in commands_deg:
            while (
                self.next_k - first - len(self.stamps_seen() & self._range(first)) >= window
                and time.monotonic() < deadline
            ):
                self.node.spin_once(0.01)
            msg = self.node.new_message(
                "sensor_msgs/msg/JointState", name=[PITCH_JOINT], position=[math.radians(value)]
            )
            set_stamp(msg.header.stamp, self.stamp(self.next_k))
            self.cmd.publish(msg)
            self.next_k += 1
        wanted = self._range(first)
        ok = self.node.spin_until(
            lambda: wanted <= self.stamps_seen(), max(0.0, deadline - time.monotonic())
        )
        assert ok, f"states missing for {len(wanted - self.stamps_seen())} commanded stamps"

    def _range(self, first: int) -> set[int]:
        return {self.stamp(k) for k in range(first, self.next_k)}

    def end_plan(self) -> None:
        """The generator's plan_end event (multisine_gen.generator_node)."""
        event = {"event": "plan_end", "samples": self.next_k, "fs": FS, "t0_ns": self.t0_ns}
        msg = self.node.new_message(EXPERIMENT_SEGMENT.type, **segment_event_fields(event))
        set_stamp(msg.header.stamp, self.stamp(self.next_k - 1))  # the plan's last sample
        self.segment_pub.publish(msg)

    def request_stop(self, stop: bool = True) -> None:
        self.stop_pub.publish(self.node.new_message("std_msgs/msg/Bool", data=stop))

    def series(self, after_ns: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """(t [s] since stamp 0, pitch [deg]) by stamp; the first state of a stamp is kept."""
        seen: dict[int, float] = {}
        for stamp, pitch, _ in self.states:
            if stamp >= after_ns:
                seen.setdefault(stamp, pitch)
        stamps = np.array(sorted(seen), dtype=np.int64)
        return (stamps - self.t0_ns) / 1e9, np.array([seen[s] for s in stamps])

    def wait_diagnostics(self, predicate: Any, timeout_s: float = 10.0) -> dict[str, str]:
        return wait_diagnostics(self.node, self.diagnostics, predicate, timeout_s)

    def close(self) -> None:
        self.node.close()


@pytest.fixture
def actuator(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Any:
    """Start sim_actuator with the given parameters; yields (client, processes)."""
    env = graph_env()
    join_graph(env, monkeypatch.setenv)
    client = ActuatorClient()
    procs = Processes(env, log_dir=tmp_path)

    def start(**params: object) -> tuple[ActuatorClient, Processes]:
        args = ["--ros-args"]
        for key, value in {"seed": 4, "diagnostics_period_s": 0.2, **params}.items():
            args += ["-p", f"{key}:={value}"]
        procs.start_entry("pitch_actuator", "sim_actuator", *args, name="sim_actuator")
        assert client.wait_ready(30), "sim_actuator not discovered\n" + procs.log("sim_actuator")
        return client, procs

    try:
        yield start
    finally:
        procs.stop_all()
        client.close()


@pytest.fixture
def limit_run(actuator: Any) -> tuple[ActuatorClient, Processes]:
    """60° then −40° commands (limits −10°..35°), 1 s each, then diagnostics settle."""
    client, procs = actuator(max_deg=35.0, min_deg=-10.0)
    client.drive([60.0] * 200 + [-40.0] * 200)
    return client, procs


def test_out_of_range_commands_are_clamped_and_reported(limit_run: Any) -> None:
    client, procs = limit_run
    t, pitch = client.series()
    assert len(t) == 400
    # The pitch settles at the limit, not at the command (mean over the last 0.25 s).
    assert abs(np.mean(pitch[150:200]) - 35.0) < 0.01, pitch[150:200]
    assert abs(np.mean(pitch[350:400]) + 10.0) < 0.01, pitch[350:400]
    diag = client.wait_diagnostics(lambda d: d.get("clamped") == "400")
    assert diag["refused"] == "0"
    assert "clamped" in procs.log("sim_actuator")


def test_state_never_leaves_the_limits(limit_run: Any) -> None:
    client, _ = limit_run
    _, pitch = client.series()
    assert len(pitch) == 400
    assert pitch.max() <= 35.0 + MEASUREMENT_TOL_DEG, f"max pitch {pitch.max():.3f}°"
    assert pitch.min() >= -10.0 - MEASUREMENT_TOL_DEG, f"min pitch {pitch.min():.3f}°"


def test_non_finite_commands_are_refused_and_still_answered(actuator: Any) -> None:
    client, procs = actuator()
    client.drive([8.0] * 60)
    k_nan = client.next_k
    client.drive([math.nan, 8.0, math.inf, 8.0] + [8.0] * 20)
    t, pitch = client.series()
    assert len(t) == 84
    # A state came back for the NaN and the inf stamps, finite, where the pitch was.
    for k in (k_nan, k_nan + 2):
        i = int(np.flatnonzero(np.round(t * FS).astype(int) == k)[0])
        assert math.isfinite(pitch[i])
        assert abs(pitch[i] - 8.0) < 0.05, pitch[i]
    assert np.all(np.abs(pitch[50:] - 8.0) < 0.05)
    # The status that counts all 84 commands: one published while the node was still working
    # through them can arrive after the last state (seen with a campaign running beside it).
    diag = client.wait_diagnostics(
        lambda d: int(d.get("accepted", 0)) + int(d.get("refused", 0)) >= 84
    )
    assert (diag["accepted"], diag["refused"]) == ("82", "2")
    assert procs.procs[0].poll() is None  # the node lives on
    # Events are logged by their own 0.1 s timer: the periodic status may count them first.
    assert wait_for(lambda: "refused non-finite pitch command" in procs.log("sim_actuator"), 5.0)


def _check_hold_then_ramp(
    t: np.ndarray,
    pitch: np.ndarray,
    hold_from: float,
    hold_deg: float,
    ramp_start_window: tuple[float, float],
) -> None:
    """Pitch holds ``hold_deg`` from ``hold_from`` until the ramp starts inside the window,
    then ramps to SAFE_DEG no faster than RAMP_DEG_S and stays there."""
    moved = np.flatnonzero((t > hold_from) & (np.abs(pitch - hold_deg) > 0.1))
    assert moved.size, "pitch never left the hold"
    t_ramp = t[moved[0]]
    lo, hi = ramp_start_window
    assert lo <= t_ramp <= hi, f"ramp started at {t_ramp:.3f} s, expected in [{lo:.3f}, {hi:.3f}]"
    holding = (t > hold_from) & (t < t_ramp)
    assert np.all(np.abs(pitch[holding] - hold_deg) <= 0.1)
    # No 0.1 s window moves faster than the ramp rate (10 % for the loop's transient and noise).
    after = t >= t_ramp - 0.05
    tr, pr = t[after], pitch[after]
    n = round(0.1 * FS)
    slopes = np.abs(pr[n:] - pr[:-n]) / (tr[n:] - tr[:-n])
    assert slopes.max() <= 1.1 * RAMP_DEG_S, f"ramp at {slopes.max():.2f}°/s"
    # The middle of the ramp runs at the ramp rate (not a jump, not a crawl).
    span = hold_deg - SAFE_DEG
    middle = (np.abs(pr - SAFE_DEG) < 0.8 * abs(span)) & (np.abs(pr - SAFE_DEG) > 0.2 * abs(span))
    slope = np.polyfit(tr[middle], pr[middle], 1)[0]
    assert abs(abs(slope) - RAMP_DEG_S) < 0.05 * RAMP_DEG_S, f"ramp slope {slope:.2f}°/s"
    t_safe = t_ramp + abs(span) / RAMP_DEG_S + 0.1
    at_safe = t > t_safe
    assert at_safe.sum() >= 20, "the ramp did not reach the safe angle in time"
    assert np.all(np.abs(pitch[at_safe] - SAFE_DEG) <= MEASUREMENT_TOL_DEG)


# The node's settings when its command stream falls silent: a short hold and a fast ramp.
SILENCE = {
    "stream_timeout_s": 0.2,
    "watchdog_timeout_s": WATCHDOG_S,
    "hold_s": HOLD_S,
    "ramp_rate_deg_s": RAMP_DEG_S,
    "safe_angle_deg": SAFE_DEG,
}


def _wait_hold_and_ramp(client: ActuatorClient) -> float:
    """After the last command (at 12°), wait for the states of the hold and of the ramp to the
    safe angle (the node runs on in real time: about 1.4 s of them); the last command's time."""
    t_last = (client.stamp(client.next_k - 1) - client.t0_ns) / 1e9
    t_end = t_last + WATCHDOG_S + HOLD_S + (12.0 - SAFE_DEG) / RAMP_DEG_S + 0.3
    done = client.node.spin_until(lambda: client.series()[0][-1] >= t_end, 15.0)
    assert done, f"states stopped at {client.series()[0][-1]:.3f} s, wanted {t_end:.3f} s"
    return t_last


def test_lost_command_stream_holds_then_ramps_to_safe_angle(actuator: Any) -> None:
    client, _ = actuator(**SILENCE)
    client.drive([12.0] * 100)
    t_last = _wait_hold_and_ramp(client)
    t, pitch = client.series()
    # Free-running states continue the stamp grid: one per 5 ms, none twice.
    assert np.all(np.diff(np.round(t * FS).astype(int)) == 1)
    assert len(client.states) == len(t)
    trip = t_last + WATCHDOG_S
    _check_hold_then_ramp(t, pitch, t_last, 12.0, (trip + HOLD_S, trip + HOLD_S + 0.06))
    diag = client.wait_diagnostics(lambda d: d.get("mode") == "safe")
    assert int(diag["watchdog_trips"]) == 1


def test_the_plans_end_then_silence_holds_and_ramps_with_no_error_line(actuator: Any) -> None:
    """The plan's end disarms the stream watchdog: the silence after it holds, then ramps to
    the safe angle as after a trip, but the node trips nothing and logs no ERROR line."""
    client, procs = actuator(**SILENCE)
    client.drive([12.0] * 100)
    client.end_plan()
    # Commands flow until the node's diagnostics say it expects the stream's end (no race
    # between the event and the watchdog), then they stop as at a plan's end.
    deadline = time.monotonic() + 30.0
    while not any(d.get("stream_end_expected") == "True" for d in client.diagnostics):
        assert time.monotonic() < deadline, "the node never took the plan's end"
        client.drive([12.0] * 10)
    t_last = _wait_hold_and_ramp(client)
    diag = client.wait_diagnostics(lambda d: d.get("mode") == "safe", 15.0)
    assert diag["watchdog_trips"] == "0", diag
    t, pitch = client.series()
    hold_end = t_last + WATCHDOG_S + HOLD_S
    _check_hold_then_ramp(t, pitch, t_last, 12.0, (hold_end, hold_end + 0.06))
    log = procs.log("sim_actuator")
    assert "the plan has ended" in log, log
    assert [line for line in log.splitlines() if "ERROR" in line] == [], log


def test_stop_request_holds_then_ramps_while_commands_flow(actuator: Any) -> None:
    client, _ = actuator(
        hold_s=HOLD_S, ramp_rate_deg_s=RAMP_DEG_S, safe_angle_deg=SAFE_DEG, max_deg=35.0
    )
    client.drive([12.0] * 100)
    t_stop_min = (max(s for s, _, _ in client.states) - client.t0_ns) / 1e9
    client.request_stop()
    # Commands keep asking for 12°; the node must ignore them and go to the safe angle.
    client.drive([12.0] * 260)
    t, pitch = client.series()
    _check_hold_then_ramp(
        t, pitch, t_stop_min, 12.0, (t_stop_min + HOLD_S, t_stop_min + HOLD_S + 0.25)
    )
    # Every command after the stop took effect (a few in flight) was ignored.
    diag = client.wait_diagnostics(
        lambda d: d.get("mode") == "safe" and int(d.get("ignored_after_stop", 0)) >= 250
    )
    assert diag["stops"] == "1"
    assert diag["watchdog_trips"] == "0"
