"""The receive loop of the rig's UDP links (the PWAC controller link, the pressure scanner's
client): one daemon thread waits on a non-blocking socket and hands every datagram on.

Light: standard library only, no middleware (the links also run outside a ROS graph).
"""

import select
import socket
import threading
from collections.abc import Callable

__all__ = ["drain_datagrams", "receive_datagrams"]

Address = tuple[str, int]


def receive_datagrams(
    sock: socket.socket,
    stop: threading.Event,
    handle: Callable[[bytes, Address], None],
    bufsize: int,
    wait_s: Callable[[], float] = lambda: 0.05,
    tick: Callable[[], None] | None = None,
) -> None:
    """Until ``stop`` is set: wait until ``sock`` is readable, at most ``wait_s()`` seconds;
    call ``tick`` after each wait (e.g. a heartbeat that is due); then `drain_datagrams`.

    An ICMP port-unreachable reported for an earlier send (ConnectionRefusedError: the peer is
    not up yet) is skipped; any other receive error ends the drain until the next wait; a
    socket closed under the loop (select fails) ends it."""
    while not stop.is_set():
        try:
            readable, _, _ = select.select([sock], [], [], wait_s())
        except (OSError, ValueError):  # the socket was closed (the link's close())
            return
        if tick is not None:
            tick()
        if readable:
            drain_datagrams(sock, handle, bufsize)


def drain_datagrams(
    sock: socket.socket, handle: Callable[[bytes, Address], None], bufsize: int
) -> None:
    """Take every datagram queued on the non-blocking ``sock`` and pass each to ``handle``
    (a link without its thread calls it from its ``poll``)."""
    while True:
        try:
            data, addr = sock.recvfrom(bufsize)
        except (BlockingIOError, InterruptedError):
            return
        except ConnectionRefusedError:  # ICMP port unreachable from an earlier send
            continue
        except OSError:
            return
        handle(data, addr)
