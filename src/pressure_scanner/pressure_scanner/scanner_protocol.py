"""Binary UDP frames of the electronic pressure scanner, and the scanner-channel → tap table.

The frame follows the pattern of Scanivalve DSA/ZOC Ethernet scanners streaming binary
packets over UDP (a header with packet type, frame counter, PTP time stamp, units; then one
float32 per channel). The exact layout is this project's and is documented byte by byte in
``docs/protocols.md``; a driver for a scanner with another native layout converts to it.

    offset size type   field
    0      4    char   magic "PWSC"
    4      1    u8     version (1)
    5      1    u8     packet type (1 = pressure frame)
    6      2    u16    number of channels n (1..64)
    8      4    u32    frame counter (wraps)
    12     4    u32    acquisition time, seconds (Unix/PTP epoch)
    16     4    u32    acquisition time, nanoseconds (0..999 999 999)
    20     2    u16    units code (:class:`Units`)
    22     2    u16    scanner status bits (:class:`ScannerStatus`)
    24     4    u32    scanner serial number
    28     4    u32    reserved (0)
    32     4n   f32[n] pressures, channel 0 first, in the units of the units code
"""

import math
import struct
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from enum import Enum, IntEnum, IntFlag
from pathlib import Path

import numpy as np

MAGIC = b"PWSC"
VERSION = 1
PACKET_TYPE_PRESSURE = 1
MAX_CHANNELS = 64
HEADER = struct.Struct("<4sBBHIIIHHII")
COUNTER_MODULUS = 1 << 32
_HALF = 1 << 31


class Units(IntEnum):
    """Units code of a frame (this project's table; docs/protocols.md)."""

    PA = 0
    KPA = 1
    PSI = 2
    INH2O = 3  # conventional inch of water
    MMH2O = 4  # conventional millimetre of water
    MBAR = 5
    TORR = 6


PA_PER_UNIT: dict[Units, float] = {
    Units.PA: 1.0,
    Units.KPA: 1000.0,
    Units.PSI: 6894.757293168361,  # NIST SP 811: lbf/in²
    Units.INH2O: 249.08891,  # NIST SP 811: inch of water (conventional)
    Units.MMH2O: 9.80665,
    Units.MBAR: 100.0,
    Units.TORR: 101325.0 / 760.0,
}


class ScannerStatus(IntFlag):
    """Scanner status bits carried in each frame."""

    NONE = 0
    OVERRANGE = 1 << 0  # the scanner itself flags a channel beyond its range
    ZEROING = 1 << 1  # scanner-side zero calibration (valve switched to reference)


class ScannerProtocolError(ValueError):
    """A datagram is not a valid scanner frame."""


@dataclass(frozen=True)
class ScannerFrame:
    """One decoded frame, as the scanner sent it (pressures in ``units``)."""

    frame_counter: int
    stamp_s: int
    stamp_subsec_ns: int
    units: Units
    pressures: np.ndarray  # (n_channels,) float32, in `units`
    status: ScannerStatus = ScannerStatus.NONE
    serial: int = 0

    @property
    def stamp_ns(self) -> int:
        """Acquisition instant in ns since the epoch."""
        return self.stamp_s * 1_000_000_000 + self.stamp_subsec_ns

    @property
    def n_channels(self) -> int:
        return int(self.pressures.shape[0])


def frame_size(n_channels: int) -> int:
    return HEADER.size + 4 * n_channels


def pack_frame(frame: ScannerFrame) -> bytes:
    """Serialise a frame; raises ScannerProtocolError for fields out of range."""
    n = frame.n_channels
    if not 1 <= n <= MAX_CHANNELS:
        raise ScannerProtocolError(f"{n} channels: a frame carries 1..{MAX_CHANNELS}")
    if not 0 <= frame.stamp_subsec_ns < 1_000_000_000:
        raise ScannerProtocolError(
            f"stamp_subsec_ns={frame.stamp_subsec_ns}: must be 0..999999999 (carry into stamp_s)"
        )
    try:
        head = HEADER.pack(
            MAGIC,
            VERSION,
            PACKET_TYPE_PRESSURE,
            n,
            frame.frame_counter,
            frame.stamp_s,
            frame.stamp_subsec_ns,
            int(frame.units),
            int(frame.status),
            frame.serial,
            0,
        )
    except struct.error as exc:
        raise ScannerProtocolError(f"cannot pack frame header: {exc}") from exc
    return head + np.asarray(frame.pressures, dtype="<f4").tobytes()


def unpack_frame(data: bytes) -> ScannerFrame:
    """Parse and validate one datagram; ScannerProtocolError says what is wrong with it."""
    if len(data) < HEADER.size:
        raise ScannerProtocolError(
            f"datagram of {len(data)} bytes is shorter than the {HEADER.size}-byte frame header"
        )
    (magic, version, ptype, n, counter, sec, nsec, units, status, serial, _) = HEADER.unpack_from(
        data
    )
    if magic != MAGIC:
        raise ScannerProtocolError(
            f"bad magic {magic!r} (expected {MAGIC!r}): not a scanner frame; check that only the "
            "scanner streams to this port and that it is set to binary output"
        )
    if version != VERSION:
        raise ScannerProtocolError(
            f"frame version {version}, this client reads version {VERSION}; update one side"
        )
    if ptype != PACKET_TYPE_PRESSURE:
        raise ScannerProtocolError(
            f"packet type {ptype} is not a pressure frame ({PACKET_TYPE_PRESSURE})"
        )
    if not 1 <= n <= MAX_CHANNELS:
        raise ScannerProtocolError(f"frame announces {n} channels, a frame carries 1..64")
    if len(data) != frame_size(n):
        raise ScannerProtocolError(
            f"frame announces {n} channels ({frame_size(n)} bytes) but has {len(data)} bytes: "
            "truncated or padded datagram"
        )
    if nsec >= 1_000_000_000:
        raise ScannerProtocolError(f"nanoseconds field {nsec} is not below 10**9")
    try:
        unit = Units(units)
    except ValueError:
        raise ScannerProtocolError(
            f"unknown units code {units}; known: " + ", ".join(f"{u.value}={u.name}" for u in Units)
        ) from None
    pressures = np.frombuffer(data, dtype="<f4", count=n, offset=HEADER.size)
    return ScannerFrame(counter, sec, nsec, unit, pressures, ScannerStatus(status), serial)


# -- channel → tap table -------------------------------------------------------------------


@dataclass(frozen=True)
class ChannelMap:
    """Which tap each scanner channel reads.

    ``channel_to_tap[c]`` is the tap index (0..n_taps-1, tap order of the wing) measured by
    scanner channel ``c``, or -1 for an unused or reference channel. A tap read by no channel
    is *missing*: its pressure is NaN and it is reported, never invented.
    """

    channel_to_tap: tuple[int, ...]
    n_taps: int = 49

    def __post_init__(self) -> None:
        if self.n_taps < 1:
            raise ValueError(f"n_taps={self.n_taps}: must be >= 1")
        if not 1 <= len(self.channel_to_tap) <= MAX_CHANNELS:
            raise ValueError(
                f"channel_to_tap has {len(self.channel_to_tap)} entries; give one per scanner "
                f"channel (1..{MAX_CHANNELS}), -1 for unused channels"
            )
        seen: dict[int, int] = {}
        for channel, tap in enumerate(self.channel_to_tap):
            if not isinstance(tap, int | np.integer) or not -1 <= tap < self.n_taps:
                raise ValueError(
                    f"channel_to_tap[{channel}] = {tap!r}: must be a tap index 0..{self.n_taps - 1}"
                    " or -1 (unused)"
                )
            if tap >= 0:
                if tap in seen:
                    raise ValueError(
                        f"tap {tap} is mapped from channels {seen[tap]} and {channel}; "
                        "each tap is read by one channel"
                    )
                seen[tap] = channel

    @classmethod
    def identity(cls, n_taps: int = 49, n_channels: int | None = None) -> "ChannelMap":
        """Channel i reads tap i; extra channels unused."""
        n = n_taps if n_channels is None else n_channels
        return cls(tuple(i if i < n_taps else -1 for i in range(n)), n_taps)

    @classmethod
    def from_mapping(cls, params: Mapping[str, object]) -> "ChannelMap":
        """From a parameter mapping with ``channel_to_tap`` (list) and optional ``n_taps``."""
        if "channel_to_tap" not in params:
            raise ValueError(
                "parameters have no 'channel_to_tap' list (index = scanner channel, value = "
                "tap index or -1); see docs/protocols.md"
            )
        raw = params["channel_to_tap"]
        if not isinstance(raw, list | tuple):
            raise ValueError(f"channel_to_tap must be a list of integers, got {raw!r}")
        n_taps = params.get("n_taps", 49)
        if not isinstance(n_taps, int):
            raise ValueError(f"n_taps must be an integer, got {n_taps!r}")
        return cls(tuple(raw), n_taps)

    @classmethod
    def from_yaml(cls, path: str | Path, node_name: str | None = None) -> "ChannelMap":
        """Read the table from a YAML file: a ROS 2 parameter file
        (``<node>: {ros__parameters: {channel_to_tap: [...], n_taps: 49}}``, wildcard node
        names allowed) or a plain mapping with the same two keys."""
        import yaml

        text = Path(path).read_text(encoding="utf-8")
        try:
            doc = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise ValueError(f"{path}: not valid YAML: {exc}") from exc
        if not isinstance(doc, dict):
            raise ValueError(f"{path}: expected a mapping at the top level")
        if "channel_to_tap" in doc:
            return cls.from_mapping(doc)
        for name, section in doc.items():
            if node_name is not None and name not in (node_name, f"/{node_name}", "/**"):
                continue
            params = section.get("ros__parameters") if isinstance(section, dict) else None
            if isinstance(params, dict) and "channel_to_tap" in params:
                try:
                    return cls.from_mapping(params)
                except ValueError as exc:
                    raise ValueError(f"{path} [{name}]: {exc}") from exc
        raise ValueError(
            f"{path}: no channel_to_tap found"
            + (f" for node {node_name!r}" if node_name else "")
            + "; expected <node>: ros__parameters: channel_to_tap: [...]"
        )

    @property
    def n_channels(self) -> int:
        return len(self.channel_to_tap)

    @property
    def missing_taps(self) -> tuple[int, ...]:
        """Taps no channel reads (their pressure is always NaN)."""
        mapped = set(self.channel_to_tap)
        return tuple(t for t in range(self.n_taps) if t not in mapped)

    @property
    def required_channels(self) -> int:
        """A frame must carry at least this many channels to serve every mapped tap."""
        used = [c for c, t in enumerate(self.channel_to_tap) if t >= 0]
        return max(used) + 1 if used else 0

    def _index(self) -> tuple[np.ndarray, np.ndarray]:
        channels = np.array([c for c, t in enumerate(self.channel_to_tap) if t >= 0], dtype=int)
        taps = np.array([t for t in self.channel_to_tap if t >= 0], dtype=int)
        return channels, taps

    def taps_from_channels(self, channel_values: np.ndarray, fill: float = math.nan) -> np.ndarray:
        """(n_channels≥required,) → (n_taps,) float64 in tap order; unread taps get ``fill``."""
        channels, taps = self._index()
        out = np.full(self.n_taps, fill, dtype=np.float64)
        out[taps] = channel_values[channels]
        return out

    def channels_from_taps(
        self, tap_values: np.ndarray, n_channels: int | None = None
    ) -> np.ndarray:
        """(n_taps,) → (n_channels,) float64; unused channels read 0 (as a vented port)."""
        n = self.n_channels if n_channels is None else n_channels
        channels, taps = self._index()
        out = np.zeros(n, dtype=np.float64)
        out[channels] = np.asarray(tap_values, dtype=np.float64)[taps]
        return out


# -- frame counter bookkeeping --------------------------------------------------------------


def counter_delta(candidate: int, reference: int) -> int:
    """Signed distance of two u32 frame counters in [−2**31, 2**31) (RFC 1982 arithmetic)."""
    delta = (candidate - reference) % COUNTER_MODULUS
    return delta - COUNTER_MODULUS if delta >= _HALF else delta


class FrameArrival(Enum):
    FRESH = "fresh"  # newer than every frame so far: deliver
    DUPLICATE = "duplicate"
    LATE = "late"  # older than the newest (reordered): discarded to keep the stream in order
    RESTART = "restart"  # scanner restarted its counter: bookkeeping resynchronised, deliver


@dataclass(frozen=True)
class FrameGap:
    """A run of frame counters that never arrived."""

    after_frame: int  # last frame counter received before the gap
    missing: int  # number of frames in the gap
    detected_stamp_ns: int  # stamp of the frame that revealed it


@dataclass
class FrameCounters:
    """``lost``: counters after the first frame that never arrived (a late frame inside the
    window is taken back out); ``late``: arrived after a newer frame, discarded;
    ``duplicated``: arrived again; ``restarts``: counter jumped back (scanner restarted)."""

    received: int = 0
    fresh: int = 0
    lost: int = 0
    duplicated: int = 0
    late: int = 0
    restarts: int = 0


class FrameCounterTracker:
    """Loss, duplicate and reorder detection on the u32 frame counter (no peer sessions:
    a scanner that restarts its counter is recognised by two consecutive frames far behind).

    Keeps a bitmap of the last ``window`` counters (the anti-replay window of RFC 4303) to tell
    a late frame from a duplicate, and the most recent gaps for reporting.
    """

    def __init__(self, window: int = 64, max_recent_gaps: int = 32) -> None:
        if not 1 <= window <= 1024:
            raise ValueError(f"window={window}: choose 1..1024 frames")
        self.window = window
        self.counters = FrameCounters()
        self.recent_gaps: deque[FrameGap] = deque(maxlen=max_recent_gaps)
        self.newest: int | None = None
        self._first = 0
        self._seen = 0
        self._restart_candidate: int | None = None

    def _resync(self, counter: int) -> None:
        self.newest = self._first = counter
        self._seen = 1
        self._restart_candidate = None

    def observe(self, counter: int, stamp_ns: int) -> FrameArrival:
        c = self.counters
        c.received += 1
        if self.newest is None:
            self._resync(counter)
            c.fresh += 1
            return FrameArrival.FRESH
        delta = counter_delta(counter, self.newest)
        if delta > 0:
            if delta > 1:
                c.lost += delta - 1
                self.recent_gaps.append(FrameGap(self.newest, delta - 1, stamp_ns))
            self._seen = ((self._seen << delta) | 1) & ((1 << self.window) - 1)
            self.newest = counter
            self._restart_candidate = None
            c.fresh += 1
            return FrameArrival.FRESH
        age = -delta
        if age < self.window:
            if self._seen >> age & 1:
                c.duplicated += 1
                return FrameArrival.DUPLICATE
            self._seen |= 1 << age
            if counter_delta(counter, self._first) > 0:
                c.lost -= 1
            c.late += 1
            return FrameArrival.LATE
        # Far behind: a straggler, or the scanner restarted its counter. Two consecutive
        # frames far behind tell a restart; the first of them is counted late.
        candidate = self._restart_candidate
        if candidate is not None and 0 < counter_delta(counter, candidate) <= 2:
            self._resync(counter)
            c.restarts += 1
            c.fresh += 1
            return FrameArrival.RESTART
        self._restart_candidate = counter
        c.late += 1
        return FrameArrival.LATE
