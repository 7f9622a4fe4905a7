"""The Fast DDS profile a node's participant is made with: ROS's discovery range, over UDP alone.

rmw_fastrtps configures the LOCALHOST and SUBNET ranges itself (rmw_fastrtps_shared_cpp,
``participant.cpp``), with Fast DDS's shared-memory transport beside UDPv4. That transport's
ports are rings in shared memory, guarded by interprocess mutexes that time out after about a
second and watched by a listener watchdog (Fast DDS 2.14, ``SharedMemGlobal.hpp``). A process
stopped for a second or more (SIGSTOP, a debugger, swapping), while it listens on a port or
while it holds a port's mutex, makes its peers mark the port broken and build it anew; now and
then one writer's channel to the rebuilt port stays dead for the rest of the run. Its reliable
reader is still matched but receives nothing, and the writer's keep-all history fills until
publishing blocks (docs/known_issues.md, "A reader stuck after a pause"). Over UDP a stopped
process only loses datagrams, which the reliable protocol sends again.

So, for LOCALHOST and SUBNET, a node writes the discovery configuration rmw_fastrtps would make
into a Fast DDS profile, with UDPv4 as its only transport, and rmw is given the range
SYSTEM_DEFAULT, with which it leaves the participant to the profile. The profile also carries
the writers' settings of ``fastdds_profiles.xml``. A profile file of the user's own
(``FASTRTPS_DEFAULT_PROFILES_FILE``) and the ranges OFF and SYSTEM_DEFAULT are left to rmw.
"""

import os
import socket
import tempfile
from collections.abc import Iterator, MutableMapping
from contextlib import contextmanager
from pathlib import Path

from .ros_environment import RANGE_ENV, RosEnvironmentError, discovery_range, static_peers

# Fast DDS reads its default profiles from this file when a process makes its first participant.
PROFILES_ENV = "FASTRTPS_DEFAULT_PROFILES_FILE"
PROFILES_FILE = Path(__file__).with_name("fastdds_profiles.xml")
UDP_TRANSPORT = "rig_udpv4"  # the transport descriptor's id in PROFILES_FILE
MULTICAST_DISCOVERY = "239.255.0.1"  # RTPS's default SPDP multicast group (RTPS 2.2, 9.6.1.4.1)
# The ranges rmw_fastrtps would configure with shared memory, written here over UDP instead.
OVER_UDP = ("LOCALHOST", "SUBNET")

# The discovery configuration this process's participants were made with (Fast DDS keeps the
# profile it read first): a node with another one needs a process of its own.
_MADE_WITH: list[tuple[str, tuple[str, ...]]] = []


def _ipv4(peer: str) -> str:
    """The first IPv4 address of a static peer, as rmw_fastrtps resolves it."""
    try:
        return str(socket.getaddrinfo(peer, None, socket.AF_INET)[0][4][0])
    except (OSError, IndexError):
        raise RosEnvironmentError(f"ROS_STATIC_PEERS: cannot resolve {peer!r}") from None


def _locator(address: str | None) -> str:
    inner = f"<address>{address}</address>" if address else ""
    return f"<locator><udpv4>{inner}</udpv4></locator>"


def participant_xml(range_: str, peers: list[str]) -> str:
    """The default participant profile for ``range_`` (LOCALHOST or SUBNET) and the static peers'
    IPv4 addresses: what rmw_fastrtps configures for them, with UDPv4 as the only transport."""
    builtin = []
    initial = list(peers)
    if range_ == "LOCALHOST":
        # No multicast discovery: a unicast metatraffic locator keeps Fast DDS from adding its
        # default multicast one; this host is always a peer.
        builtin.append(
            f"<metatrafficUnicastLocatorList>{_locator(None)}</metatrafficUnicastLocatorList>"
        )
        initial.append("127.0.0.1")
    elif peers:
        initial.append(MULTICAST_DISCOVERY)  # with peers, announce on the multicast group too
    if initial:
        builtin.append(
            "<initialPeersList>" + "".join(_locator(a) for a in initial) + "</initialPeersList>"
        )
    return (
        '<participant profile_name="rig_runtime_participant" is_default_profile="true"><rtps>'
        f"<builtin>{''.join(builtin)}</builtin>"
        f"<userTransports><transport_id>{UDP_TRANSPORT}</transport_id></userTransports>"
        "<useBuiltinTransports>false</useBuiltinTransports>"
        "</rtps></participant>"
    )


def profiles_xml(range_: str, peers: list[str]) -> str:
    """PROFILES_FILE with the participant profile of ``range_`` added."""
    text = PROFILES_FILE.read_text()
    return text.replace("</profiles>", participant_xml(range_, peers) + "\n</profiles>")


@contextmanager
def participant_environment(env: MutableMapping[str, str] | None = None) -> Iterator[None]:
    """The environment rmw reads while a participant is made (``rclpy.init``), restored after.

    LOCALHOST and SUBNET become SYSTEM_DEFAULT with a profile that configures them over UDP;
    other ranges get PROFILES_FILE; a profile file the user set is left as it is.
    """
    env = os.environ if env is None else env
    if PROFILES_ENV in env:
        yield
        return
    range_ = discovery_range(env)
    saved = {key: env.get(key) for key in (PROFILES_ENV, RANGE_ENV)}
    with tempfile.TemporaryDirectory(prefix="rig_fastdds_") as tmp:
        if range_ in OVER_UDP:
            peers = tuple(_ipv4(p) for p in static_peers(env))
            if _MADE_WITH and _MADE_WITH[0] != (range_, peers):
                made_range, made_peers = _MADE_WITH[0]
                raise RosEnvironmentError(
                    f"this process's participants use discovery range {made_range} with "
                    f"peers {list(made_peers)}; a node with range {range_} and peers "
                    f"{list(peers)} needs a process of its own"
                )
            profile = Path(tmp) / "fastdds_profiles.xml"
            profile.write_text(profiles_xml(range_, list(peers)))
            env[PROFILES_ENV] = str(profile)
            env[RANGE_ENV] = "SYSTEM_DEFAULT"
            _MADE_WITH[:1] = [(range_, peers)]
        else:
            env[PROFILES_ENV] = str(PROFILES_FILE)
        try:
            yield
        finally:
            for key, value in saved.items():
                if value is None:
                    env.pop(key, None)
                else:
                    env[key] = value
