"""Test support for the controller UDP tests: a lossy UDP proxy and a process launcher.

Imported by test_controller_udp_*.py through their own directory on sys.path (pytest runs with
--import-mode=importlib); the module name is unique in the repository on purpose.
"""

import random
import select
import socket
import subprocess
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from pitch_actuator.controller_protocol import seq_delta, unpack
from rig_testing.processes import start_port_printer

TO_SERVER = "to_server"
TO_CLIENT = "to_client"


@dataclass
class _Direction:
    drop: float
    duplicate: float
    reorder: float
    blackhole: bool = False
    held: tuple[bytes, float] | None = None
    emitted: list[bytes] = field(default_factory=list)  # datagrams sent on, in order
    dropped: int = 0


class LossyUdpProxy:
    """UDP proxy on 127.0.0.1 between one client and one server that drops, duplicates and
    reorders datagrams at random (seeded), in both directions.

    The client sends to :attr:`address`; the proxy forwards to the server from its own back
    socket and forwards the server's replies to the last client address. Reordering holds a
    datagram back and sends it right after the next one (or after ``hold_s`` if none comes).
    Every datagram actually sent on is recorded in order, so a test can compute exactly what
    the receiver should have counted.
    """

    def __init__(
        self,
        server_addr: tuple[str, int],
        drop: float = 0.0,
        duplicate: float = 0.0,
        reorder: float = 0.0,
        seed: int = 0,
        hold_s: float = 0.03,
    ) -> None:
        self.server_addr = server_addr
        self.hold_s = hold_s
        self._rng = random.Random(seed)
        self.directions = {
            TO_SERVER: _Direction(drop, duplicate, reorder),
            TO_CLIENT: _Direction(drop, duplicate, reorder),
        }
        self._front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._front.bind(("127.0.0.1", 0))
        self._back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._back.bind(("127.0.0.1", 0))
        self._client_addr: tuple[str, int] | None = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="lossy-proxy", daemon=True)

    @property
    def address(self) -> tuple[str, int]:
        return self._front.getsockname()

    def start(self) -> "LossyUdpProxy":
        self._thread.start()
        return self

    def set_blackhole(self, direction: str, blackhole: bool) -> None:
        """Drop everything in one direction (a cable pulled) until set back to False."""
        with self._lock:
            self.directions[direction].blackhole = blackhole

    def stop(self) -> None:
        """Stop forwarding (held datagrams are discarded, not recorded) and close the sockets."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        self._front.close()
        self._back.close()

    def _emit(self, name: str, data: bytes) -> None:
        if name == TO_SERVER:
            self._back.sendto(data, self.server_addr)
        elif self._client_addr is not None:
            self._front.sendto(data, self._client_addr)
        else:
            return
        self.directions[name].emitted.append(data)

    def _forward(self, name: str, data: bytes) -> None:
        with self._lock:
            d = self.directions[name]
            if d.blackhole or self._rng.random() < d.drop:
                d.dropped += 1
                return
            held = d.held
            if held is None and self._rng.random() < d.reorder:
                d.held = (data, time.monotonic())
                return
            self._emit(name, data)
            if self._rng.random() < d.duplicate:
                self._emit(name, data)
            if held is not None:
                d.held = None
                self._emit(name, held[0])  # now after its successor: reordered

    def _flush_held(self) -> None:
        with self._lock:
            now = time.monotonic()
            for name, d in self.directions.items():
                if d.held is not None and now - d.held[1] > self.hold_s:
                    data, d.held = d.held[0], None
                    self._emit(name, data)

    def _run(self) -> None:
        while not self._stop.is_set():
            readable, _, _ = select.select([self._front, self._back], [], [], 0.01)
            for sock in readable:
                try:
                    data, addr = sock.recvfrom(4096)
                except OSError:
                    continue
                if sock is self._front:
                    self._client_addr = addr
                    self._forward(TO_SERVER, data)
                else:
                    self._forward(TO_CLIENT, data)
            self._flush_held()


@dataclass(frozen=True)
class ExpectedCounts:
    lost: int
    duplicated: int
    reordered: int


def expected_counts(datagrams: list[bytes], session: int) -> ExpectedCounts:
    """What a receiver must count for this arrival order (set logic, independent of the
    sliding-window tracker under test). Sequence numbers are unwrapped relative to the first."""
    first = None
    seen: set[int] = set()
    newest = None
    duplicated = reordered = 0
    for data in datagrams:
        message = unpack(data)
        if message.session != session:
            continue
        if first is None:
            first = message.seq
        n = seq_delta(message.seq, first)  # unwrapped position in the stream
        if n in seen:
            duplicated += 1
            continue
        seen.add(n)
        if newest is not None and n < newest:
            reordered += 1
        newest = n if newest is None else max(newest, n)
    if not seen:
        return ExpectedCounts(0, 0, 0)
    # Gaps are counted from the first arrival (index 0) on; earlier numbers are only late.
    lost = max(seen) + 1 - sum(1 for n in seen if n >= 0)
    return ExpectedCounts(lost, duplicated, reordered)


def start_sim_controller(
    args: list[str], stderr_path: Path, timeout_s: float = 30.0
) -> tuple[subprocess.Popen[str], int]:
    """Start ``python -m pitch_actuator.sim_controller`` and read the port it prints first."""
    return start_port_printer(
        "pitch_actuator.sim_controller", ["--port", "0", *args], stderr_path, timeout_s
    )


def stop_process(proc: subprocess.Popen[str], timeout_s: float = 5.0) -> int:
    """SIGTERM, wait, SIGKILL if needed; returns the exit code."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=timeout_s)
    if proc.stdout is not None:
        proc.stdout.close()
    return proc.returncode


def wait_until(predicate: Callable[[], object], timeout_s: float, poll_s: float = 0.01) -> bool:
    """Poll ``predicate()`` until true or the timeout; returns the last result."""
    deadline = time.monotonic() + timeout_s
    while True:
        if predicate():
            return True
        if time.monotonic() > deadline:
            return False
        time.sleep(poll_s)
