"""A lab of machines inside one Linux machine, for tests and benches of a graph on several hosts.

Each host is a network namespace with one interface (``eth0``) on a switch: a bridge in a
namespace of its own, so that no address or route of the machine's own namespaces is touched.
The addresses are the lab's (``10.233.0.0/24`` by default), used only inside its namespaces;
every namespace is removed when the lab closes. A host's processes are started under
``ip netns exec`` (:meth:`NetLab.command`); pulling a host's cable is :meth:`NetLab.link`.

Needs root (CAP_SYS_ADMIN, CAP_NET_ADMIN) and iproute2's ``ip``: :func:`unavailable` says why
not, for a skip. Namespaces share the file system, so Fast DDS's shared-memory transport could
join two hosts; the graph's nodes do not use it (``participant_profile.py``), so a pulled cable
stops their data (``tests/test_two_hosts.py``).
"""

import os
import shutil
import subprocess
from dataclasses import dataclass, field
from types import TracebackType

SUBNET = "10.233.0"  # the lab's /24
SWITCH = "sw"


class NetLabError(RuntimeError):
    """The lab could not be built or changed (the failing ``ip`` command and its message)."""


def unavailable() -> str | None:
    """Why a lab cannot be built here, or None."""
    if shutil.which("ip") is None:
        return "iproute2's `ip` is not installed"
    if os.geteuid() != 0:
        return "network namespaces need root (CAP_SYS_ADMIN and CAP_NET_ADMIN)"
    probe = f"aerolab-probe-{os.getpid()}"
    made = subprocess.run(["ip", "netns", "add", probe], capture_output=True, text=True)
    if made.returncode != 0:
        return f"`ip netns add` failed: {made.stderr.strip()}"
    subprocess.run(["ip", "netns", "delete", probe], capture_output=True)
    return None


def _ip(*args: str) -> None:
    done = subprocess.run(["ip", *args], capture_output=True, text=True)
    if done.returncode != 0:
        raise NetLabError(f"ip {' '.join(args)}: {done.stderr.strip()}")


@dataclass
class NetLab:
    """Hosts (network namespaces) on one switch. ``with NetLab(["rig", "workstation"]) as lab``."""

    hosts: list[str]
    prefix: str = field(default_factory=lambda: f"aerolab{os.getpid()}")
    made: list[str] = field(default_factory=list)  # namespaces made, for close()

    def namespace(self, host: str) -> str:
        return f"{self.prefix}-{host}"

    def address(self, host: str) -> str:
        """The host's IPv4 address in the lab."""
        return f"{SUBNET}.{self.hosts.index(host) + 1}"

    def command(self, host: str, argv: list[str]) -> list[str]:
        """``argv`` run on ``host`` (``ip netns exec`` execs it: the process is argv's)."""
        return ["ip", "netns", "exec", self.namespace(host), *argv]

    def _port(self, host: str) -> str:
        """The switch's port of ``host`` (the veth end in the switch's namespace)."""
        return f"p{self.hosts.index(host)}"

    def link(self, host: str, up: bool) -> None:
        """Plug (``up``) or pull the cable of ``host`` at the switch."""
        _ip("-n", self.namespace(SWITCH), "link", "set", self._port(host), "up" if up else "down")

    def open(self) -> "NetLab":
        switch = self.namespace(SWITCH)
        self._add(switch)
        _ip("-n", switch, "link", "add", "br0", "type", "bridge")
        _ip("-n", switch, "link", "set", "br0", "up")
        for host in self.hosts:
            ns, port = self.namespace(host), self._port(host)
            self._add(ns)
            _ip(
                "-n",
                switch,
                "link",
                "add",
                port,
                "type",
                "veth",
                "peer",
                "name",
                "eth0",
                "netns",
                ns,
            )
            _ip("-n", switch, "link", "set", port, "master", "br0")
            _ip("-n", switch, "link", "set", port, "up")
            _ip("-n", ns, "addr", "add", f"{self.address(host)}/24", "dev", "eth0")
            _ip("-n", ns, "link", "set", "eth0", "up")
            _ip("-n", ns, "link", "set", "lo", "up")
            # Multicast (DDS discovery's 239.255.0.1) leaves by the LAN, as on a host whose
            # default route is its LAN.
            _ip("-n", ns, "route", "add", "224.0.0.0/4", "dev", "eth0")
        return self

    def _add(self, ns: str) -> None:
        _ip("netns", "add", ns)
        self.made.append(ns)

    def close(self) -> None:
        """Remove every namespace the lab made (their interfaces go with them)."""
        for ns in reversed(self.made):
            subprocess.run(["ip", "netns", "delete", ns], capture_output=True)
        self.made.clear()

    def __enter__(self) -> "NetLab":
        try:
            return self.open()
        except BaseException:
            self.close()
            raise

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()
