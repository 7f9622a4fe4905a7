"""Simulated real-time pitch controller speaking the PWAC UDP protocol (``docs/protocols.md``).

Run as a process::

    python -m pitch_actuator.sim_controller --port 0 --rate 200 --audit-file audit.jsonl

The first line on stdout is the UDP port it bound (so tests can ask for port 0). Every cycle
(200 Hz by default, paced by the wall clock) it reads all pending datagrams, applies only fresh
setpoints (RFC 1982 newer than anything seen from the host's session), steps the
:class:`pitch_actuator.dynamics.ActuatorModel`, and sends one feedback packet to the address
the newest fresh host packet came from. It clamps to its own hard limits, and if no fresh
setpoint or heartbeat arrives within the watchdog timeout it holds, then ramps to a safe angle.

The audit file (JSON lines, flushed per line) records every applied setpoint, every packet it
refused, every mode change and, on exit, the stream counters: tests use it to prove that no
stale setpoint was ever applied.
"""

import argparse
import json
import math
import secrets
import signal
import socket
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from enum import Enum
from typing import Protocol, TextIO

from pitch_actuator.controller_protocol import (
    Arrival,
    CommandFlag,
    Feedback,
    Heartbeat,
    ProtocolError,
    SessionTracker,
    Setpoint,
    Status,
    pack,
    unpack,
)
from rig_runtime.signals import StopSignals


class _Sample(Protocol):
    @property
    def position_rad(self) -> float: ...
    @property
    def velocity_rad_s(self) -> float: ...


class _Model(Protocol):
    def step(self, command_rad: float) -> _Sample: ...


@dataclass(frozen=True)
class SimControllerConfig:
    """The controller's own settings. Its hard limits are independent of the host's on purpose
    (a second guard, as on the rig's PWAC controller), so they are not
    rig_runtime.interface.ActuatorLimits: the simulated controller allows −10°…30°."""

    rate_hz: float = 200.0
    min_rad: float = math.radians(-10.0)
    max_rad: float = math.radians(30.0)
    watchdog_timeout_s: float = 0.25
    hold_s: float = 1.0  # hold time after a watchdog trip before ramping to the safe angle
    safe_rad: float = 0.0
    safe_ramp_rad_s: float = math.radians(2.0)

    def __post_init__(self) -> None:
        if not 1.0 <= self.rate_hz <= 10_000.0:
            raise ValueError(f"rate_hz={self.rate_hz}: choose 1..10000 Hz")
        if not self.min_rad < self.max_rad:
            raise ValueError(
                f"hard limits min={math.degrees(self.min_rad):.3f}° >= "
                f"max={math.degrees(self.max_rad):.3f}°: give min < max"
            )
        if not self.min_rad <= self.safe_rad <= self.max_rad:
            raise ValueError(
                f"safe angle {math.degrees(self.safe_rad):.3f}° is outside the hard limits "
                f"[{math.degrees(self.min_rad):.3f}°, {math.degrees(self.max_rad):.3f}°]"
            )
        if self.watchdog_timeout_s <= 0 or self.hold_s < 0 or self.safe_ramp_rad_s <= 0:
            raise ValueError(
                "watchdog_timeout_s and safe_ramp_rad_s must be > 0 and hold_s >= 0 "
                f"(got {self.watchdog_timeout_s}, {self.safe_ramp_rad_s}, {self.hold_s})"
            )


class Mode(Enum):
    DISABLED = "disabled"  # no host yet, or the host cleared ENABLE: hold
    FOLLOWING = "following"
    STOPPED = "stopped"  # host sent STOP: hold
    WATCHDOG = "watchdog"  # host stream lost: hold, then ramp to the safe angle


class ControllerCore:
    """Controller logic without sockets or clocks (the process loop feeds it)."""

    def __init__(
        self, config: SimControllerConfig, model: _Model, audit: TextIO | None = None
    ) -> None:
        self.config = config
        self.model = model
        self.audit = audit
        self.session = secrets.randbits(32) or 1
        self.tracker = SessionTracker()
        self.mode = Mode.DISABLED
        self.seq = 0
        self.applied_session = 0
        self.applied_seq = 0
        self.target_rad = 0.0
        self.position_rad = 0.0
        self.velocity_rad_s = 0.0
        self.fault = False
        self.limited = False
        self._last_fresh_s: float | None = None
        self._hold_rad = 0.0
        self._mode_since_s = 0.0
        self._dt = 1.0 / config.rate_hz
        self.rejected_invalid = 0

    def _log(self, event: str, **fields: object) -> None:
        if self.audit is not None:
            self.audit.write(json.dumps({"event": event, **fields}) + "\n")
            self.audit.flush()

    def _enter(self, mode: Mode, now_s: float, reason: str) -> None:
        if mode is self.mode:
            return
        if mode is not Mode.FOLLOWING:
            self._hold_rad = self._clamp(self.position_rad)
        self.mode = mode
        self._mode_since_s = now_s
        self._log("mode", mode=mode.value, reason=reason, t=now_s)

    def _clamp(self, angle_rad: float) -> float:
        return min(max(angle_rad, self.config.min_rad), self.config.max_rad)

    def on_datagram(self, data: bytes, now_s: float) -> bool:
        """Process one datagram; True if it was a fresh host packet (the sender is the host)."""
        try:
            message = unpack(data)
        except ProtocolError as exc:
            self.rejected_invalid += 1
            self._log("invalid", reason=str(exc))
            return False
        if not isinstance(message, Setpoint | Heartbeat):
            self.rejected_invalid += 1
            self._log("invalid", reason=f"{type(message).__name__} sent to the controller")
            return False
        arrival = self.tracker.observe(message.session, message.seq)
        if arrival is not Arrival.FRESH:
            kind = "setpoint" if isinstance(message, Setpoint) else "heartbeat"
            self._log("refused", arrival=arrival.value, kind=kind, seq=message.seq)
            return False
        self._last_fresh_s = now_s
        flags = message.flags
        if flags & CommandFlag.STOP:
            self._enter(Mode.STOPPED, now_s, "STOP flag")
        elif not flags & CommandFlag.ENABLE:
            if self.mode is not Mode.WATCHDOG:  # only a setpoint ends a watchdog hold
                self._enter(Mode.DISABLED, now_s, "ENABLE cleared")
        elif isinstance(message, Setpoint):
            self._apply(message, now_s)
        return True

    def _apply(self, setpoint: Setpoint, now_s: float) -> None:
        if not math.isfinite(setpoint.position_rad):
            self.fault = True
            self._log("rejected_nonfinite", seq=setpoint.seq, position_rad=setpoint.position_rad)
            return
        self.fault = False
        self.applied_session, self.applied_seq = setpoint.session, setpoint.seq
        self.target_rad = self._clamp(setpoint.position_rad)
        self.limited = self.target_rad != setpoint.position_rad
        self._enter(Mode.FOLLOWING, now_s, "setpoint")
        self._log(
            "apply",
            session=setpoint.session,
            seq=setpoint.seq,
            position_rad=setpoint.position_rad,
            target_rad=self.target_rad,
        )

    def step(self, now_s: float, stamp_ns: int) -> Feedback:
        """One control cycle: watchdog, target, model step; returns the feedback to send."""
        cfg = self.config
        if (
            self._last_fresh_s is not None
            and self.mode is not Mode.WATCHDOG
            and now_s - self._last_fresh_s > cfg.watchdog_timeout_s
        ):
            gap = now_s - self._last_fresh_s
            self._enter(
                Mode.WATCHDOG,
                now_s,
                f"no setpoint or heartbeat for {gap:.3f} s (timeout {cfg.watchdog_timeout_s} s)",
            )
        status = Status(0)
        if self.mode is Mode.FOLLOWING:
            command = self.target_rad
            status |= Status.ENABLED
            if self.limited:
                status |= Status.LIMIT
        else:
            status |= Status.HOLDING
            if self.mode is Mode.WATCHDOG:
                status |= Status.WATCHDOG
                if now_s - self._mode_since_s >= cfg.hold_s:
                    status |= Status.RAMPING
                    step = cfg.safe_ramp_rad_s * self._dt
                    error = cfg.safe_rad - self._hold_rad
                    self._hold_rad += max(-step, min(step, error))
            elif self.mode is Mode.STOPPED:
                status |= Status.STOPPED
            command = self._hold_rad
        if self.fault:
            status |= Status.FAULT
        sample = self.model.step(self._clamp(command))
        self.position_rad = float(sample.position_rad)
        self.velocity_rad_s = float(sample.velocity_rad_s)
        c = self.tracker.counters
        feedback = Feedback(
            session=self.session,
            seq=self.seq,
            stamp_ns=stamp_ns,
            status=status,
            applied_session=self.applied_session,
            applied_seq=self.applied_seq,
            rx_lost=max(c.lost, 0),
            rx_duplicated=c.duplicated,
            rx_reordered=c.reordered,
            position_rad=self.position_rad,
            velocity_rad_s=self.velocity_rad_s,
            target_rad=self._clamp(command),
        )
        self.seq = (self.seq + 1) % (1 << 32)
        return feedback

    def log_statistics(self, overruns: int) -> None:
        self._log(
            "stats",
            **asdict(self.tracker.counters),
            invalid=self.rejected_invalid,
            overruns=overruns,
            feedback_sent=self.seq,
        )


def _drain(sock: socket.socket, core: ControllerCore, now: float) -> tuple[str, int] | None:
    """Feed every pending datagram to the core; returns the address of the newest fresh host
    packet (where feedback goes), or None if there was none."""
    host_addr = None
    while True:
        try:
            data, addr = sock.recvfrom(2048)
        except (BlockingIOError, InterruptedError):
            return host_addr
        except ConnectionRefusedError:  # ICMP from a host that went away
            continue
        if core.on_datagram(data, now):
            host_addr = addr


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m pitch_actuator.sim_controller",
        description="Simulated pitch controller (PWAC UDP protocol, ActuatorModel dynamics).",
    )
    p.add_argument("--host", default="127.0.0.1", help="interface to bind (default loopback)")
    p.add_argument("--port", type=int, default=0, help="UDP port to bind; 0 = any free port")
    p.add_argument("--rate", type=float, default=200.0, help="control/feedback rate [Hz]")
    p.add_argument("--min-deg", type=float, default=-10.0, help="hard lower limit [deg]")
    p.add_argument("--max-deg", type=float, default=30.0, help="hard upper limit [deg]")
    p.add_argument("--watchdog-timeout", type=float, default=0.25, help="[s] without host packets")
    p.add_argument("--hold", type=float, default=1.0, help="hold time before ramping [s]")
    p.add_argument("--safe-deg", type=float, default=0.0, help="safe angle after a trip [deg]")
    p.add_argument("--safe-ramp-deg-s", type=float, default=2.0, help="ramp rate [deg/s]")
    p.add_argument("--seed", type=int, default=0, help="ActuatorModel noise seed")
    p.add_argument("--audit-file", default=None, help="append JSON-lines audit records here")
    p.add_argument("--duration", type=float, default=0.0, help="stop after [s]; 0 = run forever")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        config = SimControllerConfig(
            rate_hz=args.rate,
            min_rad=math.radians(args.min_deg),
            max_rad=math.radians(args.max_deg),
            watchdog_timeout_s=args.watchdog_timeout,
            hold_s=args.hold,
            safe_rad=math.radians(args.safe_deg),
            safe_ramp_rad_s=math.radians(args.safe_ramp_deg_s),
        )
    except ValueError as exc:
        print(f"sim_controller: invalid settings: {exc}", file=sys.stderr)
        return 2
    from pitch_actuator.dynamics import ActuatorModel

    model = ActuatorModel(fs=config.rate_hz, seed=args.seed)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind((args.host, args.port))
    sock.setblocking(False)
    print(sock.getsockname()[1], flush=True)

    stop = StopSignals(signal.SIGTERM, signal.SIGINT).install()  # for the process's life

    audit = open(args.audit_file, "a", encoding="utf-8") if args.audit_file else None
    core = ControllerCore(config, model, audit)
    host_addr: tuple[str, int] | None = None
    period = 1.0 / config.rate_hz
    start = next_tick = time.monotonic()
    overruns = 0
    try:
        while not stop:
            now = time.monotonic()
            if args.duration > 0 and now - start >= args.duration:
                break
            host_addr = _drain(sock, core, now) or host_addr
            feedback = core.step(now, time.time_ns())
            if host_addr is not None:
                try:
                    sock.sendto(pack(feedback), host_addr)
                except OSError:
                    pass  # a real controller keeps its cycle whatever the network does
            next_tick += period
            delay = next_tick - time.monotonic()
            if delay < -5 * period:  # badly late (descheduled): restart pacing, no burst
                overruns += 1
                next_tick = time.monotonic()
            elif delay > 0:
                time.sleep(delay)
    finally:
        # Account for what arrived before the stop, so the audit's counters are complete.
        _drain(sock, core, time.monotonic())
        core.log_statistics(overruns)
        if audit is not None:
            audit.close()
        sock.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
