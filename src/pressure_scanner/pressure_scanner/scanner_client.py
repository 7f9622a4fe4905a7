"""Receiver of the pressure scanner's UDP frames (layout in ``docs/protocols.md``).

:class:`ScannerClient` turns scanner frames into tap pressures in Pa, in tap order:

1. frame counter bookkeeping: lost, duplicated and late (reordered) frames are counted and the
   recent gaps kept; only fresh frames are delivered, in counter order;
2. unit conversion to Pa from the frame's units code;
3. out-of-range detection against the scanner's full scale (and non-finite readings): such a
   channel reads NaN, so the lift integration excludes it;
4. zero (tare): on request, the mean of the next n fresh frames (wind off) becomes the
   per-channel offset subtracted from every later frame;
5. channel → tap mapping (:class:`~pressure_scanner.scanner_protocol.ChannelMap`); a tap no
   channel reads is NaN and listed in ``missing_taps``.

Bad datagrams are counted with the reason of the last one, never raised. Like the controller
link it never blocks its caller: use :meth:`ScannerClient.poll` from a timer, or
:meth:`ScannerClient.start` for a background thread delivering to a callback.
"""

import math
import socket
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from pressure_scanner.scanner_protocol import (
    PA_PER_UNIT,
    ChannelMap,
    FrameArrival,
    FrameCounters,
    FrameCounterTracker,
    FrameGap,
    ScannerFrame,
    ScannerProtocolError,
    ScannerStatus,
    unpack_frame,
)
from rig_runtime.datagram import drain_datagrams, receive_datagrams

# A ±10 inH2O module (the usual range for low-speed wind-tunnel pressure taps).
DEFAULT_FULL_SCALE_PA = 10 * 249.08891


@dataclass(frozen=True)
class ScannerClientConfig:
    """Where frames arrive and how they are turned into tap pressures."""

    channel_map: ChannelMap
    bind_host: str = "0.0.0.0"  # 127.0.0.1 in tests
    port: int = 0  # the UDP port the scanner streams to; 0 = any free port (tests)
    full_scale_pa: float = DEFAULT_FULL_SCALE_PA  # |raw reading| beyond this → NaN
    source_host: str | None = None  # accept frames only from this IPv4 address
    queue_len: int = 2000  # bounded: a slow consumer loses the oldest frames (counted)
    max_recent_gaps: int = 32
    tare_warn_pa: float | None = None  # |offset| above this is suspicious; None: 2% full scale

    def __post_init__(self) -> None:
        if not (math.isfinite(self.full_scale_pa) and self.full_scale_pa > 0):
            raise ValueError(
                f"full_scale_pa={self.full_scale_pa}: give the scanner module's range in Pa (> 0)"
            )
        if not 0 <= self.port < 65536:
            raise ValueError(f"port={self.port}: use 0 (any free port) or 1..65535")
        if self.queue_len < 1:
            raise ValueError(f"queue_len={self.queue_len}: must be >= 1")


@dataclass(frozen=True)
class TapPressures:
    """One delivered frame in tap order."""

    frame_counter: int
    stamp_ns: int  # acquisition instant from the scanner (its PTP clock)
    pressures_pa: np.ndarray  # (n_taps,) float64; NaN: out of range, not finite or missing tap
    out_of_range: np.ndarray  # (n_taps,) bool: the reading was beyond full scale or not finite
    tared: bool  # zero offsets were subtracted
    scanner_status: ScannerStatus


@dataclass(frozen=True)
class TareResult:
    """Outcome of a zero calibration (per scanner channel, Pa)."""

    offsets_pa: np.ndarray  # (n_channels,) mean wind-off reading; NaN if the channel failed
    std_pa: np.ndarray  # (n_channels,) standard deviation of the wind-off readings
    n_frames: int
    failed_channels: tuple[int, ...]  # no valid reading during the tare (read NaN afterwards)
    suspicious_channels: tuple[int, ...]  # |offset| > tare_warn_pa: is the wind really off?


@dataclass(frozen=True)
class ScannerStatistics:
    """Snapshot of the stream's health."""

    frames: FrameCounters
    recent_gaps: tuple[FrameGap, ...]
    invalid_frames: int
    last_invalid_reason: str
    foreign_datagrams: int  # from an address other than source_host
    out_of_range_samples: int  # channel readings set to NaN as beyond full scale / not finite
    queue_overflows: int
    callback_errors: int
    missing_taps: tuple[int, ...]
    tare_in_progress: bool
    tared: bool


FrameCallback = Callable[[TapPressures], None]


class ScannerClient:
    """UDP receiver of scanner frames → tap pressures in Pa. Thread-safe."""

    def __init__(self, config: ScannerClientConfig) -> None:
        self.config = config
        self.channel_map = config.channel_map
        self._source_ip: str | None = None
        if config.source_host is not None:
            try:
                self._source_ip = socket.gethostbyname(config.source_host)
            except OSError as exc:
                raise ValueError(
                    f"cannot resolve source_host {config.source_host!r}: {exc}"
                ) from exc
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            # A burst of 64-channel frames must not overflow the kernel buffer between polls.
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            self._sock.bind((config.bind_host, config.port))
        except OSError as exc:
            self._sock.close()
            raise OSError(
                f"cannot bind the scanner port {config.bind_host}:{config.port}: {exc}; "
                "is another driver already receiving on it?"
            ) from exc
        self._sock.setblocking(False)
        self._lock = threading.Lock()
        self._tracker = FrameCounterTracker(max_recent_gaps=config.max_recent_gaps)
        self._queue: deque[TapPressures] = deque(maxlen=config.queue_len)
        self._offsets: np.ndarray | None = None
        self._tare_target = 0
        self._tare_sum: np.ndarray | None = None
        self._tare_sumsq: np.ndarray | None = None
        self._tare_count: np.ndarray | None = None
        self._tare_frames = 0
        self._tare_result: TareResult | None = None
        self._tare_done = threading.Event()
        self._counts = {"invalid": 0, "foreign": 0, "oor": 0, "overflow": 0, "callback": 0}
        self._last_invalid = ""
        self._tap_oor_counts = np.zeros(self.channel_map.n_taps, dtype=np.int64)
        self._thread: threading.Thread | None = None
        self._stop_event = threading.Event()
        self._callback: FrameCallback | None = None
        self._closed = False

    @property
    def port(self) -> int:
        """The UDP port frames are received on (useful with port 0)."""
        return int(self._sock.getsockname()[1])

    # -- tare -------------------------------------------------------------------------------

    def start_tare(self, n_frames: int) -> None:
        """Average the next ``n_frames`` fresh frames (wind off!) into per-channel offsets.

        Frames keep being delivered meanwhile, with the previous offsets (if any). The result
        is available from :attr:`tare_result` / :meth:`wait_for_tare` once complete; the new
        offsets apply from the frame that completes the average on.
        """
        if n_frames < 1:
            raise ValueError(f"n_frames={n_frames}: average at least one frame (typically 100+)")
        with self._lock:
            self._tare_target = n_frames
            self._tare_frames = 0
            self._tare_sum = self._tare_sumsq = self._tare_count = None
            self._tare_done.clear()

    def wait_for_tare(self, timeout_s: float) -> TareResult:
        """Block until the tare started by :meth:`start_tare` completes (background-thread mode,
        or another thread polling). Raises TimeoutError if frames do not arrive in time."""
        if not self._tare_done.wait(timeout_s):
            with self._lock:
                got = self._tare_frames
            raise TimeoutError(
                f"tare incomplete after {timeout_s} s: {got} of {self._tare_target} frames "
                "received; is the scanner streaming to this port?"
            )
        assert self._tare_result is not None
        return self._tare_result

    @property
    def tare_result(self) -> TareResult | None:
        return self._tare_result

    @property
    def tare_in_progress(self) -> bool:
        return self._tare_target > 0

    @property
    def offsets_pa(self) -> np.ndarray | None:
        """Per-channel zero offsets in use (Pa), or None if untared."""
        return None if self._offsets is None else self._offsets.copy()

    def set_offsets(self, offsets_pa: np.ndarray | None) -> None:
        """Use saved offsets (e.g. from an earlier wind-off tare); None removes the tare."""
        if offsets_pa is not None:
            offsets_pa = np.array(offsets_pa, dtype=np.float64)
            if offsets_pa.ndim != 1 or offsets_pa.shape[0] < self.channel_map.required_channels:
                raise ValueError(
                    f"offsets of shape {offsets_pa.shape}: give one per scanner channel "
                    f"(at least {self.channel_map.required_channels})"
                )
        with self._lock:
            self._offsets = offsets_pa

    def _accumulate_tare(self, channels_pa: np.ndarray) -> None:
        n = channels_pa.shape[0]
        if self._tare_sum is None or self._tare_sum.shape[0] != n:
            self._tare_sum = np.zeros(n)
            self._tare_sumsq = np.zeros(n)
            self._tare_count = np.zeros(n, dtype=np.int64)
        assert self._tare_sumsq is not None and self._tare_count is not None
        valid = np.isfinite(channels_pa)
        values = np.where(valid, channels_pa, 0.0)
        self._tare_sum += values
        self._tare_sumsq += values * values
        self._tare_count += valid
        self._tare_frames += 1
        if self._tare_frames < self._tare_target:
            return
        count = self._tare_count
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(count > 0, self._tare_sum / count, np.nan)
            var = np.where(count > 1, (self._tare_sumsq - count * mean**2) / (count - 1), np.nan)
        warn = (
            0.02 * self.config.full_scale_pa
            if self.config.tare_warn_pa is None
            else self.config.tare_warn_pa
        )
        self._tare_result = TareResult(
            offsets_pa=mean,
            std_pa=np.sqrt(np.maximum(var, 0.0)),
            n_frames=self._tare_frames,
            failed_channels=tuple(int(c) for c in np.flatnonzero(count == 0)),
            suspicious_channels=tuple(int(c) for c in np.flatnonzero(np.abs(mean) > warn)),
        )
        self._offsets = mean
        self._tare_target = 0
        self._tare_done.set()

    # -- receiving --------------------------------------------------------------------------

    def poll(self) -> list[TapPressures]:
        """Non-blocking: the fresh frames received since the last call, in counter order.

        Without a background thread it reads the socket itself.
        """
        if self._closed:
            raise RuntimeError("ScannerClient is closed; create a new one")
        if self._thread is None:
            self._drain_socket()
        with self._lock:
            out = list(self._queue)
            self._queue.clear()
        return out

    def start(self, on_frame: FrameCallback | None = None) -> None:
        """Receive in a daemon thread; ``on_frame`` (called from that thread) gets each fresh
        frame, otherwise frames go to the bounded queue drained by :meth:`poll`."""
        if self._closed:
            raise RuntimeError("ScannerClient is closed; create a new one")
        if self._thread is not None:
            raise RuntimeError("ScannerClient.start() called twice")
        self._callback = on_frame
        self._thread = threading.Thread(target=self._run, name="scanner-client", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        receive_datagrams(self._sock, self._stop_event, self._on_datagram, 65536)

    def _drain_socket(self) -> None:
        drain_datagrams(self._sock, self._on_datagram, 65536)

    def _on_datagram(self, data: bytes, addr: tuple[str, int]) -> None:
        delivered = self._handle_datagram(data, addr)
        if delivered is not None and self._callback is not None:
            try:
                self._callback(delivered)
            except Exception as exc:  # a consumer bug must not stop reception
                self._counts["callback"] += 1
                print(f"scanner_client: frame callback raised {exc!r}", file=sys.stderr)

    def _reject(self, reason: str) -> None:
        self._counts["invalid"] += 1
        self._last_invalid = reason

    def _handle_datagram(self, data: bytes, addr: tuple[str, int]) -> TapPressures | None:
        if self._source_ip is not None and addr[0] != self._source_ip:
            self._counts["foreign"] += 1
            return None
        try:
            frame = unpack_frame(data)
        except ScannerProtocolError as exc:
            with self._lock:
                self._reject(f"from {addr[0]}:{addr[1]}: {exc}")
            return None
        with self._lock:
            return self._process(frame)

    def _process(self, frame: ScannerFrame) -> TapPressures | None:
        cmap = self.channel_map
        if frame.n_channels < cmap.required_channels:
            self._reject(
                f"frame {frame.frame_counter} has {frame.n_channels} channels but the channel map "
                f"reads channel {cmap.required_channels - 1}; check the scanner's channel count "
                "or channel_to_tap"
            )
            return None
        arrival = self._tracker.observe(frame.frame_counter, frame.stamp_ns)
        if arrival not in (FrameArrival.FRESH, FrameArrival.RESTART):
            return None
        raw_pa = frame.pressures.astype(np.float64) * PA_PER_UNIT[frame.units]
        with np.errstate(invalid="ignore"):
            oor = ~np.isfinite(raw_pa) | (np.abs(raw_pa) > self.config.full_scale_pa)
        raw_pa[oor] = np.nan
        self._counts["oor"] += int(oor.sum())
        if self._tare_target > 0:
            self._accumulate_tare(raw_pa)
        offsets = self._offsets
        if offsets is not None:
            n = min(offsets.shape[0], raw_pa.shape[0])
            raw_pa[:n] -= offsets[:n]
        tap_oor = cmap.taps_from_channels(oor.astype(np.float64), fill=0.0) > 0
        self._tap_oor_counts += tap_oor
        delivered = TapPressures(
            frame_counter=frame.frame_counter,
            stamp_ns=frame.stamp_ns,
            pressures_pa=cmap.taps_from_channels(raw_pa),
            out_of_range=tap_oor,
            tared=offsets is not None,
            scanner_status=frame.status,
        )
        if self._callback is None:
            if len(self._queue) == self._queue.maxlen:
                self._counts["overflow"] += 1
            self._queue.append(delivered)
        return delivered

    # -- statistics, closing ----------------------------------------------------------------

    def statistics(self) -> ScannerStatistics:
        with self._lock:
            return ScannerStatistics(
                frames=replace(self._tracker.counters),
                recent_gaps=tuple(self._tracker.recent_gaps),
                invalid_frames=self._counts["invalid"],
                last_invalid_reason=self._last_invalid,
                foreign_datagrams=self._counts["foreign"],
                out_of_range_samples=self._counts["oor"],
                queue_overflows=self._counts["overflow"],
                callback_errors=self._counts["callback"],
                missing_taps=self.channel_map.missing_taps,
                tare_in_progress=self._tare_target > 0,
                tared=self._offsets is not None,
            )

    @property
    def out_of_range_counts(self) -> np.ndarray:
        """(n_taps,) how many readings of each tap were set to NaN as out of range."""
        with self._lock:
            return self._tap_oor_counts.copy()

    def close(self) -> None:
        """Stop the thread and close the socket. Idempotent."""
        if self._closed:
            return
        self._stop_event.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        self._closed = True
        self._sock.close()

    def __enter__(self) -> "ScannerClient":
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def wait_frames(client: ScannerClient, n: int, timeout_s: float) -> list[TapPressures]:
    """Poll until ``n`` frames arrived or the timeout (for scripts and tests)."""
    frames: list[TapPressures] = []
    deadline = time.monotonic() + timeout_s
    while len(frames) < n and time.monotonic() < deadline:
        frames += client.poll()
        time.sleep(0.002)
    return frames
