"""Host-side driver of the pitch controller's UDP link (see ``docs/protocols.md``).

:class:`ControllerLink` sends setpoints, keeps the controller's watchdog fed with heartbeats,
and receives feedback, discarding anything older than the newest feedback seen. It never blocks
its caller for longer than one ``sendto``. Two ways to use it from a ROS node:

- polling: call :meth:`ControllerLink.poll` from a timer (at least twice per heartbeat period);
  it reads every pending datagram, sends a heartbeat when due and returns the fresh feedback;
- background thread: :meth:`ControllerLink.start` runs a thread that receives, sends heartbeats
  and hands each fresh feedback to a callback (or to a bounded queue that ``poll`` drains).

In polling mode a stalled node stops the heartbeats, so the controller holds: that is the
intent — the heartbeat proves that the commanding process is alive.
"""

import math
import secrets
import socket
import sys
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import cast

from pitch_actuator.controller_protocol import (
    SEQ_MODULUS,
    Arrival,
    CommandFlag,
    Feedback,
    Heartbeat,
    ProtocolError,
    SessionTracker,
    Setpoint,
    StreamCounters,
    pack,
    unpack,
)
from rig_runtime.datagram import drain_datagrams, receive_datagrams

FeedbackCallback = Callable[[Feedback], None]


@dataclass(frozen=True)
class ControllerLinkConfig:
    """Where the controller is and how the link behaves."""

    controller_host: str
    controller_port: int
    bind_host: str = "0.0.0.0"  # local interface for feedback; 127.0.0.1 in tests
    bind_port: int = 0  # 0 = any free port (the controller learns it from our packets)
    heartbeat_period_s: float = 0.05  # 20 Hz when no setpoint flows
    feedback_queue_len: int = 2000  # bounded: a slow consumer loses the oldest feedback
    first_seq: int = 0  # first host sequence number (tests start near 2**32 to cross the wrap)
    round_trip_memory: int = 512  # setpoints remembered to time the controller's echo

    def __post_init__(self) -> None:
        if not 0 < self.controller_port < 65536:
            raise ValueError(
                f"controller_port={self.controller_port}: give the controller's UDP port (1..65535)"
            )
        if not 0 <= self.bind_port < 65536:
            raise ValueError(f"bind_port={self.bind_port}: use 0 (any free port) or 1..65535")
        if not 0.001 <= self.heartbeat_period_s <= 1.0:
            raise ValueError(
                f"heartbeat_period_s={self.heartbeat_period_s}: choose 0.001..1 s, well below "
                "the controller's watchdog timeout"
            )
        if self.feedback_queue_len < 1:
            raise ValueError(f"feedback_queue_len={self.feedback_queue_len}: must be >= 1")
        if not 0 <= self.first_seq < SEQ_MODULUS:
            raise ValueError(f"first_seq={self.first_seq}: must be a u32")


@dataclass(frozen=True)
class LinkStatistics:
    """Snapshot of the link's health, for diagnostics and tests."""

    session: int  # this host's session id
    setpoints_sent: int
    heartbeats_sent: int
    send_errors: int
    last_send_error: str
    feedback: StreamCounters  # controller → host stream, counted on the host
    invalid_packets: int  # datagrams that were not valid PWAC packets (or not feedback)
    last_invalid_reason: str
    foreign_packets: int  # datagrams from an address other than the controller's
    callback_errors: int
    last_callback_error: str
    queue_overflows: int  # feedback dropped because nobody drained the queue
    controller_rx_lost: int  # host → controller stream, as reported by the controller
    controller_rx_duplicated: int
    controller_rx_reordered: int
    last_feedback_age_s: float | None  # None before the first feedback
    apply_round_trip_s: float | None  # last setpoint send → first feedback echoing it


class ControllerLink:
    """UDP driver of the pitch controller: setpoints and heartbeats out, feedback in.

    Thread-safe: ``send_setpoint``/``stop``/``hold`` may be called from any thread while the
    background thread (if started) receives and sends heartbeats.
    """

    def __init__(self, config: ControllerLinkConfig) -> None:
        self.config = config
        try:
            infos = socket.getaddrinfo(
                config.controller_host, config.controller_port, socket.AF_INET, socket.SOCK_DGRAM
            )
        except socket.gaierror as exc:
            raise ValueError(
                f"cannot resolve controller_host {config.controller_host!r}: {exc}; "
                "give an IPv4 address or a resolvable host name"
            ) from exc
        # AF_INET: the sockaddr is (host, port).
        self._controller_addr = cast(tuple[str, int], infos[0][4][:2])
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((config.bind_host, config.bind_port))
        except OSError as exc:
            self._sock.close()
            raise OSError(
                f"cannot bind the feedback socket to {config.bind_host}:{config.bind_port}: "
                f"{exc}; choose another bind_port (0 = any free port)"
            ) from exc
        self._sock.setblocking(False)
        self.session = secrets.randbits(32) or 1
        self._lock = threading.Lock()
        self._next_seq = config.first_seq
        self._flags = CommandFlag(0)  # nothing enabled until the first setpoint
        self._last_sent = -math.inf  # monotonic time of the last host packet
        self._sent_at: OrderedDict[int, int] = OrderedDict()  # seq -> monotonic_ns
        self._tracker = SessionTracker()
        self._queue: deque[Feedback] = deque(maxlen=config.feedback_queue_len)
        self._latest: Feedback | None = None
        self._latest_at_ns: int | None = None
        self._last_echo: tuple[int, int] | None = None
        self._counts = {
            "setpoints": 0,
            "heartbeats": 0,
            "send_errors": 0,
            "invalid": 0,
            "foreign": 0,
            "callback_errors": 0,
            "overflows": 0,
        }
        self._last_send_error = ""
        self._last_invalid = ""
        self._last_callback_error = ""
        self._round_trip_s: float | None = None
        self._thread: threading.Thread | None = None
        self._stop_event = threading.Event()
        self._callback: FeedbackCallback | None = None
        self._closed = False

    # -- addresses --------------------------------------------------------------------------

    @property
    def local_address(self) -> tuple[str, int]:
        """(host, port) the feedback socket is bound to."""
        host, port = self._sock.getsockname()[:2]
        return host, port

    @property
    def controller_address(self) -> tuple[str, int]:
        return self._controller_addr

    # -- sending ----------------------------------------------------------------------------

    def send_setpoint(
        self,
        position_rad: float,
        velocity_ff_rad_s: float | None = None,
        stamp_ns: int | None = None,
        enable: bool = True,
    ) -> int:
        """Send one position setpoint; returns its sequence number.

        ``stamp_ns`` is the instant the setpoint belongs to (the command's stamp); default now.
        Raises ValueError for a non-finite position or feed-forward: the caller must decide
        what to command instead, the link never guesses.
        """
        if not math.isfinite(position_rad):
            raise ValueError(
                f"setpoint position {position_rad} rad is not finite; refusing to send it"
            )
        flags = CommandFlag.ENABLE if enable else CommandFlag(0)
        ff = 0.0
        if velocity_ff_rad_s is not None:
            if not math.isfinite(velocity_ff_rad_s):
                raise ValueError(
                    f"velocity feed-forward {velocity_ff_rad_s} rad/s is not finite; pass None "
                    "to send no feed-forward"
                )
            flags |= CommandFlag.VELOCITY_FF
            ff = float(velocity_ff_rad_s)
        stamp = time.time_ns() if stamp_ns is None else stamp_ns
        with self._lock:
            self._flags = flags & ~CommandFlag.VELOCITY_FF
            seq = self._take_seq()
            message = Setpoint(self.session, seq, stamp, float(position_rad), flags, ff)
            if self._send(pack(message)):
                self._counts["setpoints"] += 1
                self._sent_at[seq] = time.monotonic_ns()
                while len(self._sent_at) > self.config.round_trip_memory:
                    self._sent_at.popitem(last=False)
        return seq

    def stop(self) -> int:
        """Command an immediate hold; every later heartbeat repeats STOP until a new setpoint."""
        with self._lock:
            self._flags = CommandFlag.STOP
            return self._send_heartbeat_locked()

    def hold(self) -> int:
        """Disable following (the controller holds where it is) without a STOP."""
        with self._lock:
            self._flags = CommandFlag(0)
            return self._send_heartbeat_locked()

    def _take_seq(self) -> int:
        seq = self._next_seq
        self._next_seq = (seq + 1) % SEQ_MODULUS
        return seq

    def _send_heartbeat_locked(self) -> int:
        seq = self._take_seq()
        if self._send(pack(Heartbeat(self.session, seq, time.time_ns(), self._flags))):
            self._counts["heartbeats"] += 1
        return seq

    def _send(self, datagram: bytes) -> bool:
        # The packet's seq is consumed even if sending fails: the controller then sees a gap,
        # which is the truth about the stream.
        self._last_sent = time.monotonic()
        try:
            self._sock.sendto(datagram, self._controller_addr)
        except OSError as exc:  # full send buffer (EAGAIN), unreachable network, ...
            self._counts["send_errors"] += 1
            self._last_send_error = f"{type(exc).__name__}: {exc}"
            return False
        return True

    def _heartbeat_if_due(self) -> None:
        with self._lock:
            if time.monotonic() - self._last_sent >= self.config.heartbeat_period_s:
                self._send_heartbeat_locked()

    # -- receiving --------------------------------------------------------------------------

    def poll(self) -> list[Feedback]:
        """Non-blocking: returns the fresh feedback received since the last call, oldest first.

        Without a background thread it also reads the socket and sends a heartbeat if due.
        """
        if self._closed:
            raise RuntimeError("ControllerLink is closed; create a new one to reconnect")
        if self._thread is None:
            self._heartbeat_if_due()
            self._drain_socket()
        with self._lock:
            out = list(self._queue)
            self._queue.clear()
        return out

    def start(self, on_feedback: FeedbackCallback | None = None) -> None:
        """Run receiving and heartbeats in a daemon thread.

        ``on_feedback`` is called from that thread for every fresh feedback; without it the
        feedback goes to the bounded queue drained by :meth:`poll`.
        """
        if self._closed:
            raise RuntimeError("ControllerLink is closed; create a new one to reconnect")
        if self._thread is not None:
            raise RuntimeError("ControllerLink.start() called twice")
        self._callback = on_feedback
        self._thread = threading.Thread(target=self._run, name="controller-link", daemon=True)
        self._thread.start()

    @property
    def latest(self) -> Feedback | None:
        """The newest fresh feedback (None before the first)."""
        return self._latest

    def _run(self) -> None:
        receive_datagrams(
            self._sock, self._stop_event, self._handle_datagram, 2048,
            wait_s=lambda: min(0.05, max(0.0, self.config.heartbeat_period_s
                                         - (time.monotonic() - self._last_sent))),
            tick=self._heartbeat_if_due,
        )  # fmt: skip

    def _drain_socket(self) -> None:
        drain_datagrams(self._sock, self._handle_datagram, 2048)

    def _handle_datagram(self, data: bytes, addr: tuple[str, int]) -> None:
        received_ns = time.monotonic_ns()
        # Filter by IP only: real-time controllers often send from another port than they read.
        if addr[0] != self._controller_addr[0]:
            self._counts["foreign"] += 1
            return
        try:
            message = unpack(data)
        except ProtocolError as exc:
            self._counts["invalid"] += 1
            self._last_invalid = str(exc)
            return
        if not isinstance(message, Feedback):
            self._counts["invalid"] += 1
            self._last_invalid = (
                f"{type(message).__name__} from {addr[0]}:{addr[1]}: the host expects only "
                "feedback; is a second host commanding the same controller?"
            )
            return
        callback = None
        with self._lock:
            if self._tracker.observe(message.session, message.seq) is not Arrival.FRESH:
                return
            self._latest = message
            self._latest_at_ns = received_ns
            echo = (message.applied_session, message.applied_seq)
            if message.applied_session == self.session and echo != self._last_echo:
                sent_ns = self._sent_at.get(message.applied_seq)
                if sent_ns is not None:
                    self._round_trip_s = (received_ns - sent_ns) * 1e-9
            self._last_echo = echo
            if self._callback is None:
                if len(self._queue) == self._queue.maxlen:
                    self._counts["overflows"] += 1
                self._queue.append(message)
            else:
                callback = self._callback
        if callback is not None:
            try:
                callback(message)
            except Exception as exc:  # a consumer bug must not kill the link (and its heartbeats)
                self._counts["callback_errors"] += 1
                self._last_callback_error = f"{type(exc).__name__}: {exc}"
                print(f"controller_link: feedback callback raised {exc!r}", file=sys.stderr)

    # -- statistics, closing ----------------------------------------------------------------

    def statistics(self) -> LinkStatistics:
        with self._lock:
            latest = self._latest
            age = (
                None
                if self._latest_at_ns is None
                else (time.monotonic_ns() - self._latest_at_ns) * 1e-9
            )
            return LinkStatistics(
                session=self.session,
                setpoints_sent=self._counts["setpoints"],
                heartbeats_sent=self._counts["heartbeats"],
                send_errors=self._counts["send_errors"],
                last_send_error=self._last_send_error,
                feedback=replace(self._tracker.counters),
                invalid_packets=self._counts["invalid"],
                last_invalid_reason=self._last_invalid,
                foreign_packets=self._counts["foreign"],
                callback_errors=self._counts["callback_errors"],
                last_callback_error=self._last_callback_error,
                queue_overflows=self._counts["overflows"],
                controller_rx_lost=0 if latest is None else latest.rx_lost,
                controller_rx_duplicated=0 if latest is None else latest.rx_duplicated,
                controller_rx_reordered=0 if latest is None else latest.rx_reordered,
                last_feedback_age_s=age,
                apply_round_trip_s=self._round_trip_s,
            )

    def close(self, hold: bool = True) -> None:
        """Stop the thread and close the socket; by default first tell the controller to hold.

        The hold (ENABLE cleared) makes a clean shutdown distinguishable from a lost link,
        which the controller's watchdog handles. Idempotent.
        """
        if self._closed:
            return
        if hold:
            self.hold()
        self._stop_event.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        self._closed = True
        self._sock.close()

    def __enter__(self) -> "ControllerLink":
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
