"""ControllerLink against the simulated controller process over loopback (direct and lossy)."""

import itertools
import json
import math
import socket
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from controller_udp_support import (
    TO_CLIENT,
    TO_SERVER,
    LossyUdpProxy,
    expected_counts,
    start_sim_controller,
    stop_process,
    wait_until,
)

from pitch_actuator.controller_link import ControllerLink, ControllerLinkConfig
from pitch_actuator.controller_protocol import (
    SEQ_MODULUS,
    CommandFlag,
    Feedback,
    Setpoint,
    Status,
    pack,
    seq_delta,
    unpack,
)


def _audit(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text().splitlines()]


EIGHT = math.radians(8.0)


def at_rest(f: Feedback, position_rad: float) -> bool:
    """Within 0.1° of the position and slower than 1°/s (not a pass on the way)."""
    return abs(f.position_rad - position_rad) < math.radians(0.1) and abs(
        f.velocity_rad_s
    ) < math.radians(1.0)


def hold_setpoint(
    link: ControllerLink,
    received: list[Feedback],
    setpoint_deg: float,
    reached: Callable[[Feedback], bool],
    timeout_s: float = 10.0,
) -> Feedback:
    """Send ``setpoint_deg`` at the host's control period (5 ms) until a feedback that echoes
    the last one sent satisfies ``reached``; that feedback (bounded: fails after timeout_s)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        seq = link.send_setpoint(math.radians(setpoint_deg))

        def echoed(s: int = seq) -> bool:
            return bool(received) and received[-1].applied_seq >= s

        wait_until(echoed, 0.005, poll_s=0.001)  # one control period, or until it is echoed
        last = received[-1] if received else None
        if last is not None and last.applied_seq == seq and reached(last):
            return last
    raise AssertionError(f"no feedback reached {setpoint_deg}° in {timeout_s} s: {received[-1:]}")


def test_setpoints_are_followed_echoed_and_clamped_to_the_controller_limits(
    tmp_path: Path,
) -> None:
    audit = tmp_path / "audit.jsonl"
    proc, port = start_sim_controller(
        ["--max-deg", "12", "--audit-file", str(audit)], tmp_path / "err.txt"
    )
    link = ControllerLink(ControllerLinkConfig("127.0.0.1", port, bind_host="127.0.0.1"))
    try:
        received: list[Feedback] = []
        link.start(received.append)
        # The host's loop sends 8° until a feedback that echoes it shows the pitch settled there.
        settled = hold_setpoint(link, received, 8.0, lambda f: at_rest(f, EIGHT))
        assert settled.status & Status.ENABLED and not settled.status & Status.HOLDING
        assert settled.applied_session == link.session
        assert settled.position_rad == pytest.approx(math.radians(8.0), abs=math.radians(0.1))
        # Feedback reaches the host in order with strictly increasing acquisition stamps.
        stamps = [f.stamp_ns for f in received]
        assert all(b > a for a, b in itertools.pairwise(stamps))
        assert abs(stamps[-1] - time.time_ns()) < 1e9

        # 20° asked, the controller's own hard limit is 12°: it settles on the limit.
        clamped = hold_setpoint(link, received, 20.0, lambda f: at_rest(f, math.radians(12.0)))
        assert clamped.status & Status.LIMIT
        assert clamped.target_rad == pytest.approx(math.radians(12.0))
        # The commanded target never passes the limit (the position may overshoot it by the
        # closed loop's ~5 % before settling on it).
        assert max(f.target_rad for f in received) <= math.radians(12.0) + 1e-12
        assert clamped.position_rad == pytest.approx(math.radians(12.0), abs=math.radians(0.1))
        stats = link.statistics()
        assert stats.apply_round_trip_s is not None and stats.apply_round_trip_s < 0.5
        assert stats.feedback.lost == 0 and stats.invalid_packets == 0
    finally:
        link.close()
        stop_process(proc)
    records = _audit(audit)
    applied = [r for r in records if r["event"] == "apply"]
    assert applied[-1]["target_rad"] == pytest.approx(math.radians(12.0))
    # The clean close told the controller to hold instead of leaving it to the watchdog.
    modes = [r["mode"] for r in records if r["event"] == "mode"]
    assert modes[-1] == "disabled"


def test_lossy_link_never_applies_a_stale_setpoint_and_counts_every_fault(
    tmp_path: Path,
) -> None:
    audit = tmp_path / "audit.jsonl"
    proc, port = start_sim_controller(["--audit-file", str(audit)], tmp_path / "err.txt")
    proxy = LossyUdpProxy(
        ("127.0.0.1", port), drop=0.08, duplicate=0.08, reorder=0.12, seed=3
    ).start()
    # Start near the top of the u32 range so the stream crosses the wrap-around.
    config = ControllerLinkConfig(
        *proxy.address, bind_host="127.0.0.1", first_seq=SEQ_MODULUS - 150
    )
    link = ControllerLink(config)
    sent: dict[int, float] = {}
    try:
        link.start()
        t0 = time.monotonic()
        for k in range(400):  # 2 s of a 1 Hz, 5° sine at 200 Hz
            position = math.radians(5.0 * math.sin(2 * math.pi * k / 200))
            sent[link.send_setpoint(position)] = position
            time.sleep(max(0.0, t0 + (k + 1) / 200 - time.monotonic()))
        delivered = link.poll()
        # Nothing more reaches the controller; its feedback reports what it counted.
        proxy.set_blackhole(TO_SERVER, True)

        def controller_counted_all() -> bool:
            expected = expected_counts(proxy.directions[TO_SERVER].emitted, link.session)
            stats = link.statistics()
            reported = (
                stats.controller_rx_lost,
                stats.controller_rx_duplicated,
                stats.controller_rx_reordered,
            )
            return reported == (expected.lost, expected.duplicated, expected.reordered)

        assert wait_until(controller_counted_all, 5.0), "the controller's counters never settled"
        proxy.stop()  # nothing more in flight after this point
        to_host_emitted = proxy.directions[TO_CLIENT].emitted
        assert wait_until(lambda: link.statistics().feedback.received == len(to_host_emitted), 5.0)
        delivered += link.poll()
        host_stats = link.statistics()
    finally:
        link.close(hold=False)
        proxy.stop()
        stop_process(proc)

    records = _audit(audit)
    applied = [r for r in records if r["event"] == "apply"]
    refused_late = [
        r
        for r in records
        if r["event"] == "refused" and r["kind"] == "setpoint" and r["arrival"] == "late"
    ]
    # The faults really happened on the way to the controller ...
    assert len(refused_late) >= 5
    assert len(applied) > 300
    # ... and yet every applied setpoint is newer than the one before (across the wrap) and is
    # exactly what the host sent under that number.
    deltas = [seq_delta(b["seq"], a["seq"]) for a, b in itertools.pairwise(applied)]
    assert all(d > 0 for d in deltas)
    assert all(r["position_rad"] == sent[r["seq"]] for r in applied)
    assert any(r["seq"] < 100 for r in applied) and any(
        r["seq"] > SEQ_MODULUS - 100 for r in applied
    )

    # Controller-side counters equal what the proxy actually delivered to it.
    to_controller = expected_counts(proxy.directions[TO_SERVER].emitted, link.session)
    stats = next(r for r in reversed(records) if r["event"] == "stats")
    assert (stats["lost"], stats["duplicated"], stats["reordered"]) == (
        to_controller.lost,
        to_controller.duplicated,
        to_controller.reordered,
    )
    assert to_controller.lost > 0 and to_controller.duplicated > 0

    # Host-side: feedback delivered strictly in order; counters equal the proxy's record.
    to_host_datagrams = proxy.directions[TO_CLIENT].emitted
    controller_session = unpack(to_host_datagrams[0]).session
    to_host = expected_counts(to_host_datagrams, controller_session)
    fb = host_stats.feedback
    assert (fb.lost, fb.duplicated, fb.reordered) == (
        to_host.lost,
        to_host.duplicated,
        to_host.reordered,
    )
    assert to_host.lost > 0 and to_host.duplicated > 0 and to_host.reordered > 0
    seqs = [f.seq for f in delivered]
    assert all(seq_delta(b, a) > 0 for a, b in itertools.pairwise(seqs))
    assert len(seqs) == fb.fresh


def test_losing_the_heartbeat_makes_the_controller_hold_then_ramp_to_the_safe_angle(
    tmp_path: Path,
) -> None:
    audit = tmp_path / "audit.jsonl"
    proc, port = start_sim_controller(
        [
            "--watchdog-timeout",
            "0.15",
            "--hold",
            "0.3",
            "--safe-deg",
            "0",
            "--safe-ramp-deg-s",
            "20",
            "--audit-file",
            str(audit),
        ],
        tmp_path / "err.txt",
    )
    proxy = LossyUdpProxy(("127.0.0.1", port)).start()
    link = ControllerLink(ControllerLinkConfig(*proxy.address, bind_host="127.0.0.1"))
    received: list[Feedback] = []
    try:
        link.start(received.append)
        for _ in range(40):
            link.send_setpoint(math.radians(8.0))
            time.sleep(0.005)
        # Setpoints stop; the link's 20 Hz heartbeats alone keep the controller following,
        # over ten heartbeats (0.5 s, past the watchdog's timeout).
        heartbeats = link.statistics().heartbeats_sent
        n_before = len(received)
        assert wait_until(lambda: link.statistics().heartbeats_sent >= heartbeats + 10, 5.0)
        assert len(received) > n_before, "no feedback from the controller"
        quiet = received[n_before:]
        assert all(f.status & Status.ENABLED for f in quiet)
        assert all(f.target_rad == pytest.approx(math.radians(8.0)) for f in quiet)

        proxy.set_blackhole(TO_SERVER, True)  # host → controller cable pulled
        t_cut = time.time_ns()
        assert wait_until(lambda: received[-1].status & Status.WATCHDOG, 1.0)
        tripped = next(f for f in received if f.status & Status.WATCHDOG)
        assert tripped.status & Status.HOLDING and not tripped.status & Status.ENABLED
        trip_delay_s = (tripped.stamp_ns - t_cut) * 1e-9
        assert 0.05 < trip_delay_s < 0.4
        assert wait_until(lambda: received[-1].status & Status.RAMPING, 1.0)
        assert wait_until(lambda: received[-1].target_rad < math.radians(4.0), 1.5)

        # The link comes back: heartbeats alone do not resume motion ...
        lost_in_the_cut = link.statistics().controller_rx_lost
        proxy.set_blackhole(TO_SERVER, False)
        # A heartbeat has arrived: the controller counts the ones the cut took as lost.
        assert wait_until(lambda: link.statistics().controller_rx_lost > lost_in_the_cut, 2.0)
        n_back = len(received)
        assert wait_until(lambda: len(received) > n_back, 1.0)
        assert received[-1].status & Status.WATCHDOG
        # ... a fresh setpoint does.
        for _ in range(10):
            link.send_setpoint(math.radians(3.0))
            time.sleep(0.005)
        assert wait_until(lambda: received[-1].status & Status.ENABLED, 1.0)
        assert received[-1].target_rad == pytest.approx(math.radians(3.0))
    finally:
        link.close()
        proxy.stop()
        stop_process(proc)
    modes = [r["mode"] for r in _audit(audit) if r["event"] == "mode"]
    assert modes[:3] == ["following", "watchdog", "following"]


def test_non_finite_setpoints_are_refused_by_the_host_driver() -> None:
    link = ControllerLink(ControllerLinkConfig("127.0.0.1", 9, bind_host="127.0.0.1"))
    try:
        with pytest.raises(ValueError, match="not finite"):
            link.send_setpoint(math.nan)
        with pytest.raises(ValueError, match="feed-forward"):
            link.send_setpoint(0.0, velocity_ff_rad_s=math.inf)
        assert link.statistics().setpoints_sent == 0
    finally:
        link.close(hold=False)


def test_the_controller_refuses_a_non_finite_setpoint_that_reaches_it(tmp_path: Path) -> None:
    """A foreign host (not our driver) sends NaN: the controller flags FAULT and keeps going."""
    audit = tmp_path / "audit.jsonl"
    proc, port = start_sim_controller(["--audit-file", str(audit)], tmp_path / "err.txt")
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(1.0)
    try:
        sock.sendto(
            pack(Setpoint(77, 1, 0, math.radians(4.0), CommandFlag.ENABLE)), ("127.0.0.1", port)
        )
        sock.sendto(pack(Setpoint(77, 2, 0, math.nan, CommandFlag.ENABLE)), ("127.0.0.1", port))
        sock.sendto(b"garbage", ("127.0.0.1", port))
        deadline = time.monotonic() + 2.0
        status = Status(0)
        target = math.nan
        while time.monotonic() < deadline:
            fb = unpack(sock.recvfrom(2048)[0])
            assert isinstance(fb, Feedback)
            status, target = fb.status, fb.target_rad
            if status & Status.FAULT:
                break
        assert status & Status.FAULT and status & Status.ENABLED
        assert target == pytest.approx(math.radians(4.0))  # the last valid setpoint stands
    finally:
        sock.close()
        stop_process(proc)
    events = [r["event"] for r in _audit(audit)]
    assert "rejected_nonfinite" in events and "invalid" in events


def test_a_restarted_host_in_polling_mode_is_followed_at_once(tmp_path: Path) -> None:
    """A driver node restarts (new session, seq from 0 again) and polls from a timer."""
    audit = tmp_path / "audit.jsonl"
    proc, port = start_sim_controller(["--audit-file", str(audit)], tmp_path / "err.txt")
    try:
        first = ControllerLink(
            ControllerLinkConfig("127.0.0.1", port, bind_host="127.0.0.1", first_seq=10_000)
        )
        for _ in range(20):
            first.send_setpoint(math.radians(5.0))
            first.poll()
            time.sleep(0.005)
        first.close()

        second = ControllerLink(ControllerLinkConfig("127.0.0.1", port, bind_host="127.0.0.1"))
        try:
            received: list[Feedback] = []
            deadline = time.monotonic() + 2.0
            seq = second.send_setpoint(math.radians(2.0))
            assert seq == 0
            # No setpoints after the first: poll() alone must keep the heartbeats going.
            while time.monotonic() < deadline and not (
                received and received[-1].applied_seq == seq and len(received) > 80
            ):
                received += second.poll()
                time.sleep(0.01)
            last = received[-1]
            assert last.applied_session == second.session and last.applied_seq == seq
            assert last.status & Status.ENABLED and not last.status & Status.WATCHDOG
            assert second.statistics().heartbeats_sent >= 5
        finally:
            second.close()
    finally:
        stop_process(proc)
    applied = [(r["session"], r["seq"]) for r in _audit(audit) if r["event"] == "apply"]
    assert applied[-1] == (second.session, 0)
