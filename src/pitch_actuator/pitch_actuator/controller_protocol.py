"""Wire format of the host ↔ pitch-controller link (UDP, little endian, fixed-size packets).

``docs/protocols.md`` documents every byte so that a real-time controller (dSPACE, PLC) can
implement the controller side. This module is the single source of truth for the layout: the
host driver (:mod:`pitch_actuator.controller_link`) and the simulated controller
(:mod:`pitch_actuator.sim_controller`) both pack and unpack through it.

Every packet starts with the same 24-byte header::

    magic "PWAC" | version u8 | type u8 | length u16 | session u32 | seq u32 | stamp_ns u64

``session`` identifies one run of the sender (random, chosen at start): a receiver restarts its
sequence bookkeeping when the peer's session changes, so a restarted host or controller is not
mistaken for a stream of stale packets. ``seq`` counts the sender's packets (setpoints and
heartbeats share the host's counter) and is compared with RFC 1982 serial-number arithmetic.
"""

import struct
from collections import deque
from dataclasses import dataclass
from enum import Enum, IntEnum, IntFlag

MAGIC = b"PWAC"
VERSION = 1
SEQ_MODULUS = 1 << 32
# RFC 1982 §3.2: with SERIAL_BITS = 32, s1 is newer than s2 when 0 < (s1 - s2) mod 2^32 < 2^31.
_SEQ_HALF = 1 << 31


class MessageType(IntEnum):
    """Value of the header's ``type`` byte."""

    SETPOINT = 1
    HEARTBEAT = 2
    FEEDBACK = 3


class CommandFlag(IntFlag):
    """Bits of the ``flags`` word of setpoints and heartbeats (host → controller)."""

    ENABLE = 1 << 0  # follow setpoints; clear = hold the present position
    STOP = 1 << 1  # hold the present position now; latched until ENABLE without STOP
    VELOCITY_FF = 1 << 2  # the setpoint's velocity feed-forward field is valid


class Status(IntFlag):
    """Bits of the ``status`` word of feedback packets (controller → host)."""

    ENABLED = 1 << 0  # following the host's setpoints
    HOLDING = 1 << 1  # not following: holding (disabled, stopped or watchdog)
    FAULT = 1 << 2  # the last setpoint was rejected (not finite)
    LIMIT = 1 << 3  # the target was clamped to the controller's hard limits
    WATCHDOG = 1 << 4  # the hold was caused by the heartbeat watchdog
    STOPPED = 1 << 5  # the hold was commanded by a STOP flag
    RAMPING = 1 << 6  # moving to the safe angle after a watchdog hold


HEADER = struct.Struct("<4sBBHIIQ")
_SETPOINT_BODY = struct.Struct("<IIdd")
_HEARTBEAT_BODY = struct.Struct("<II")
_FEEDBACK_BODY = struct.Struct("<IIIIIIddd")

SETPOINT_SIZE = HEADER.size + _SETPOINT_BODY.size
HEARTBEAT_SIZE = HEADER.size + _HEARTBEAT_BODY.size
FEEDBACK_SIZE = HEADER.size + _FEEDBACK_BODY.size
PACKET_SIZES = {
    MessageType.SETPOINT: SETPOINT_SIZE,
    MessageType.HEARTBEAT: HEARTBEAT_SIZE,
    MessageType.FEEDBACK: FEEDBACK_SIZE,
}


class ProtocolError(ValueError):
    """A datagram is not a valid packet of this protocol (or a record cannot be packed)."""


@dataclass(frozen=True)
class Setpoint:
    """Host → controller: position setpoint for the pitch axis."""

    session: int
    seq: int
    stamp_ns: int  # host clock, the instant the setpoint belongs to (ns since Unix epoch)
    position_rad: float
    flags: CommandFlag = CommandFlag.ENABLE
    velocity_ff_rad_s: float = 0.0  # valid only with CommandFlag.VELOCITY_FF


@dataclass(frozen=True)
class Heartbeat:
    """Host → controller: keeps the controller's watchdog fed when no setpoint flows."""

    session: int
    seq: int
    stamp_ns: int  # host clock at sending
    flags: CommandFlag = CommandFlag.ENABLE


@dataclass(frozen=True)
class Feedback:
    """Controller → host: one measured sample of the pitch axis."""

    session: int  # controller session
    seq: int  # controller's feedback counter
    stamp_ns: int  # acquisition instant of the measurement, controller clock (PTP-synchronised)
    status: Status
    applied_session: int  # host session of applied_seq (0 before any setpoint was applied)
    applied_seq: int  # seq of the last setpoint the controller applied
    rx_lost: int  # controller-side counters of the host → controller stream
    rx_duplicated: int
    rx_reordered: int
    position_rad: float  # measured
    velocity_rad_s: float
    target_rad: float  # position the controller is tracking now (after clamping / hold logic)


Message = Setpoint | Heartbeat | Feedback


def _header(kind: MessageType, session: int, seq: int, stamp_ns: int) -> bytes:
    return HEADER.pack(MAGIC, VERSION, kind, PACKET_SIZES[kind], session, seq, stamp_ns)


def pack(message: Message) -> bytes:
    """Serialise one record to its datagram; raises ProtocolError for out-of-range fields."""
    try:
        if isinstance(message, Setpoint):
            head = _header(MessageType.SETPOINT, message.session, message.seq, message.stamp_ns)
            body = _SETPOINT_BODY.pack(
                int(message.flags), 0, message.position_rad, message.velocity_ff_rad_s
            )
        elif isinstance(message, Heartbeat):
            head = _header(MessageType.HEARTBEAT, message.session, message.seq, message.stamp_ns)
            body = _HEARTBEAT_BODY.pack(int(message.flags), 0)
        elif isinstance(message, Feedback):
            head = _header(MessageType.FEEDBACK, message.session, message.seq, message.stamp_ns)
            body = _FEEDBACK_BODY.pack(
                int(message.status),
                message.applied_session,
                message.applied_seq,
                message.rx_lost % SEQ_MODULUS,
                message.rx_duplicated % SEQ_MODULUS,
                message.rx_reordered % SEQ_MODULUS,
                message.position_rad,
                message.velocity_rad_s,
                message.target_rad,
            )
        else:
            raise ProtocolError(f"cannot pack {type(message).__name__}: not a protocol record")
    except struct.error as exc:
        raise ProtocolError(
            f"cannot pack {message!r}: {exc}; session and seq are u32, stamp_ns is u64"
        ) from exc
    return head + body


def unpack(data: bytes) -> Message:
    """Parse one datagram; raises ProtocolError saying what is wrong with it."""
    if len(data) < HEADER.size:
        raise ProtocolError(
            f"datagram of {len(data)} bytes is shorter than the {HEADER.size}-byte header; "
            "the sender does not speak the PWAC protocol"
        )
    magic, version, kind_raw, length, session, seq, stamp_ns = HEADER.unpack_from(data)
    if magic != MAGIC:
        raise ProtocolError(
            f"bad magic {magic!r} (expected {MAGIC!r}); the datagram is not a PWAC packet — "
            "check that nothing else sends to this port"
        )
    if version != VERSION:
        raise ProtocolError(
            f"protocol version {version}, this implementation speaks version {VERSION}; "
            "update the controller or the host driver so both match"
        )
    try:
        kind = MessageType(kind_raw)
    except ValueError:
        raise ProtocolError(
            f"unknown message type {kind_raw} (known: "
            + ", ".join(f"{t.value}={t.name}" for t in MessageType)
            + ")"
        ) from None
    expected = PACKET_SIZES[kind]
    if length != expected or len(data) != expected:
        raise ProtocolError(
            f"{kind.name} packet has length field {length} and {len(data)} bytes received, "
            f"expected exactly {expected}; the sender's layout differs from docs/protocols.md"
        )
    if kind is MessageType.SETPOINT:
        flags, _, position, velocity_ff = _SETPOINT_BODY.unpack_from(data, HEADER.size)
        return Setpoint(session, seq, stamp_ns, position, CommandFlag(flags), velocity_ff)
    if kind is MessageType.HEARTBEAT:
        flags, _ = _HEARTBEAT_BODY.unpack_from(data, HEADER.size)
        return Heartbeat(session, seq, stamp_ns, CommandFlag(flags))
    fields = _FEEDBACK_BODY.unpack_from(data, HEADER.size)
    return Feedback(session, seq, stamp_ns, Status(fields[0]), *fields[1:])


def seq_newer(candidate: int, reference: int) -> bool:
    """True if ``candidate`` is newer than ``reference`` (RFC 1982 serial numbers, 32 bits).

    Wrap-around safe: 0 is newer than 2**32 - 1. Two numbers exactly 2**31 apart are undefined
    in RFC 1982; they count as not newer here, so such a packet is never applied.
    """
    delta = (candidate - reference) % SEQ_MODULUS
    return 0 < delta < _SEQ_HALF


def seq_delta(candidate: int, reference: int) -> int:
    """Signed serial distance candidate − reference in [−2**31, 2**31).

    Consistent with :func:`seq_newer`: the undefined distance 2**31 counts as older.
    """
    delta = (candidate - reference) % SEQ_MODULUS
    return delta - SEQ_MODULUS if delta >= _SEQ_HALF else delta


class Arrival(Enum):
    """Classification of one received packet by :class:`SessionTracker`."""

    FRESH = "fresh"  # newer than any seen from this session: act on it
    DUPLICATE = "duplicate"  # already received
    LATE = "late"  # older than the newest (reordered): never act on it
    RETIRED_SESSION = "retired_session"  # from a session the peer has since replaced


@dataclass
class StreamCounters:
    """Counters of one received stream, accumulated over all peer sessions.

    ``lost`` counts sequence numbers after the first one received from a session that never
    arrived (a late arrival within the tracking window takes its number back out of ``lost``);
    ``duplicated`` counts repeated arrivals; ``reordered`` counts late arrivals (older than the
    newest already received), which are discarded.
    """

    received: int = 0
    fresh: int = 0
    lost: int = 0
    duplicated: int = 0
    reordered: int = 0
    retired_session: int = 0
    session_changes: int = 0


class SessionTracker:
    """Sequence bookkeeping of one peer's stream: fresh/duplicate/late, gaps, peer restarts.

    Keeps a bitmap of the last ``window`` sequence numbers (the anti-replay window of IPsec,
    RFC 4303 §3.4.3) so that a late packet can be told from a duplicate.
    """

    def __init__(self, window: int = 64, retired_sessions: int = 8) -> None:
        if not 1 <= window <= 1024:
            raise ValueError(f"window={window}: choose 1..1024 sequence numbers")
        self.window = window
        self.counters = StreamCounters()
        self.session: int | None = None
        self.newest: int | None = None
        self._first = 0  # first seq received from the present session
        self._seen = 0  # bit i set: newest - i was received
        self._retired: deque[int] = deque(maxlen=retired_sessions)

    def observe(self, session: int, seq: int) -> Arrival:
        """Classify one arrival and update the counters."""
        c = self.counters
        c.received += 1
        if session != self.session:
            if session in self._retired:
                c.retired_session += 1
                return Arrival.RETIRED_SESSION
            if self.session is not None:
                self._retired.append(self.session)
                c.session_changes += 1
            self.session, self.newest, self._first, self._seen = session, seq, seq, 1
            c.fresh += 1
            return Arrival.FRESH
        assert self.newest is not None
        delta = seq_delta(seq, self.newest)
        if delta > 0:
            c.lost += delta - 1
            self._seen = ((self._seen << delta) | 1) & ((1 << self.window) - 1)
            self.newest = seq
            c.fresh += 1
            return Arrival.FRESH
        age = -delta
        if age < self.window:
            if self._seen >> age & 1:
                c.duplicated += 1
                return Arrival.DUPLICATE
            self._seen |= 1 << age
            if seq_delta(seq, self._first) > 0:  # gaps are counted from the first arrival on
                c.lost -= 1
        # Older than the window: cannot tell duplicate from late; it is late either way.
        c.reordered += 1
        return Arrival.LATE
