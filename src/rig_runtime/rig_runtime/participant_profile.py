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
(``FASTRTPS_DEFAULT_PROFILES_FILE``) and the ranges OFF and SYSTEM_DEFAULT are left to rmw; an
rmw other than Fast DDS's is left the environment as it is.

The environment is the process's: nodes are made one at a time (not thread-safe).
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
RMW_ENV = "RMW_IMPLEMENTATION"
FASTDDS_RMWS = ("", "rmw_fastrtps_cpp", "rmw_fastrtps_dynamic_cpp")  # "": Jazzy's default
# Deprecated in Jazzy; rcl then makes the range LOCALHOST whatever ROS_AUTOMATIC_DISCOVERY_RANGE
# says (rcl 9.2, init.c), so it is read as LOCALHOST here and kept from rcl.
LOCALHOST_ONLY_ENV = "ROS_LOCALHOST_ONLY"

# The Fast DDS configuration this process's participants were made with: Fast DDS keeps the
# profile it read first, so a node with another one needs a process of its own.
_MADE_WITH: list[tuple[str, ...]] = []


def _ipv4(peer: str) -> str:
    """A static peer's IPv4 address as rmw_fastrtps takes it: the first of the name's addresses
    in string order (a std::set of them)."""
    try:
        found = socket.getaddrinfo(peer, None, socket.AF_INET)
    except (OSError, UnicodeError):
        found = []
    addresses = sorted({str(info[4][0]) for info in found})
    if not addresses:
        raise RosEnvironmentError(
            f"ROS_STATIC_PEERS: {peer!r} has no IPv4 address (rmw_fastrtps reaches static "
            "peers over IPv4)"
        )
    return addresses[0]


def _describe(config: tuple[str, ...]) -> str:
    if config[0] == "profile":
        return f"the Fast DDS profile file {config[1]}"
    return f"discovery range {config[1]} over UDP with peers {list(config[2:])}"


def _locator(address: str | None) -> str:
    inner = f"<address>{address}</address>" if address else ""
    return f"<locator><udpv4>{inner}</udpv4></locator>"


# SPDP announcements (Fast DDS ``initialAnnouncements`` and ``leaseAnnouncement``): ten at
# 100 ms, then one a second, where Fast DDS 2.14 sends five at 100 ms, then one every 3 s. A
# participant learns of one that it did not hear announce within its first 0.5 s, or that did
# not hear it, only at one of these periodic announcements. A graph's processes start over a
# few seconds (imports, a plant's tables), so with Fast DDS's timing the start barrier waited up
# to 3 s for the last pairs of endpoints to match; now at most a second. The lease (how long a
# silent participant stays matched) is Fast DDS's, ros_environment.PARTICIPANT_LEASE_S.
ANNOUNCEMENTS = (
    "<discovery_config>"
    "<initialAnnouncements><count>10</count>"
    "<period><sec>0</sec><nanosec>100000000</nanosec></period></initialAnnouncements>"
    "<leaseAnnouncement><sec>1</sec><nanosec>0</nanosec></leaseAnnouncement>"
    "</discovery_config>"
)


def participant_xml(range_: str, peers: list[str]) -> str:
    """The default participant profile for ``range_`` (LOCALHOST or SUBNET) and the static peers'
    IPv4 addresses: what rmw_fastrtps configures for them, with UDPv4 as the only transport, and
    announcements that let a graph started over a few seconds match within about a second
    (ANNOUNCEMENTS)."""
    builtin = [ANNOUNCEMENTS]
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
    """The environment rmw reads while a participant is made (``rclpy.init`` and the context's
    first node), restored after.

    LOCALHOST and SUBNET become SYSTEM_DEFAULT with a profile that configures them over UDP;
    other ranges get PROFILES_FILE; a profile file the user set is left as it is. A process
    whose participants were made with another of these configurations is refused.
    """
    env = os.environ if env is None else env
    if env.get(RMW_ENV, "").strip() not in FASTDDS_RMWS:
        yield  # not Fast DDS: its own configuration
        return
    saved = {key: env.get(key) for key in (PROFILES_ENV, RANGE_ENV, LOCALHOST_ONLY_ENV)}
    localhost_only = env.get(LOCALHOST_ONLY_ENV, "").strip() == "1"
    range_ = "LOCALHOST" if localhost_only else discovery_range(env)
    with tempfile.TemporaryDirectory(prefix="rig_fastdds_") as tmp:
        if PROFILES_ENV in env:
            config: tuple[str, ...] = ("profile", env[PROFILES_ENV])
        elif range_ in OVER_UDP:
            config = ("udp", range_, *(_ipv4(p) for p in static_peers(env)))
        else:
            config = ("profile", str(PROFILES_FILE))
        if _MADE_WITH and _MADE_WITH[0] != config:
            raise RosEnvironmentError(
                f"this process's participants were made with {_describe(_MADE_WITH[0])}; a "
                f"node with {_describe(config)} needs a process of its own (Fast DDS keeps "
                "the profile it read first)"
            )
        if config[0] == "udp":
            profile = Path(tmp) / "fastdds_profiles.xml"
            profile.write_text(profiles_xml(range_, list(config[2:])))
            env[PROFILES_ENV] = str(profile)
            env[RANGE_ENV] = "SYSTEM_DEFAULT"
            env.pop(LOCALHOST_ONLY_ENV, None)
        else:
            env[PROFILES_ENV] = config[1]
        try:
            yield
            _MADE_WITH[:1] = [config]  # not before: a node that failed may have made none
        finally:
            for key, value in saved.items():
                if value is None:
                    env.pop(key, None)
                else:
                    env[key] = value
