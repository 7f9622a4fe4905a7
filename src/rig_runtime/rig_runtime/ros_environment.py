"""The ROS 2 environment a node runs in: backend, domain and discovery range (REP-less ROS 2
conventions, as rmw implementations read them; docs/design.md §3.1).

- ``RIG_RUNTIME_BACKEND=rclpy|dds``: the runtime backend; unset, rclpy wherever it imports.
- ``ROS_DOMAIN_ID``: 0..232 (the RTPS port formula's limit for participant index 0..120).
- ``ROS_AUTOMATIC_DISCOVERY_RANGE``: ``SUBNET`` (ROS's default when unset), ``LOCALHOST``,
  ``OFF`` or ``SYSTEM_DEFAULT``; ``ROS_STATIC_PEERS``: ``;``-separated addresses that are
  always contacted (unless the range is ``OFF``). rmw_fastrtps reads both itself; the Cyclone
  DDS backend builds its configuration from them (dds_backend.cyclone_config).
- ``RIG_DDS_NETWORK=loopback|lan``: an older alias, read only when
  ``ROS_AUTOMATIC_DISCOVERY_RANGE`` is unset (loopback = LOCALHOST, lan = SUBNET).

Simulated campaigns (``aero-rig campaign``, ``aero-rig run sim``, ``sim.launch.py``) use
LOCALHOST unless the range is set: they stay on this machine (:func:`localhost_by_default`).
"""

import os
from collections.abc import Iterable, Mapping, MutableMapping

from .names import ArgumentError

BACKEND_ENV = "RIG_RUNTIME_BACKEND"
RANGE_ENV = "ROS_AUTOMATIC_DISCOVERY_RANGE"
PEERS_ENV = "ROS_STATIC_PEERS"
DOMAIN_ENV = "ROS_DOMAIN_ID"
NETWORK_ALIAS_ENV = "RIG_DDS_NETWORK"
RANGES = ("SUBNET", "LOCALHOST", "OFF", "SYSTEM_DEFAULT")
MAX_DOMAIN_ID = 232
# How long a participant that stopped announcing itself (a paused, hung or dead process) stays
# matched, per backend: Cyclone DDS's default Discovery/LeaseDuration (10 s; cyclone_config
# does not change it) and Fast DDS's default participant leaseDuration (20 s; rmw_fastrtps and
# fastdds_profiles.xml leave it). After that a reliable writer drops the reader and what it
# did not deliver; the campaign's liveness bound is derived from it (aero_rig/cli/liveness.py).
PARTICIPANT_LEASE_S = {"dds": 10.0, "rclpy": 20.0}


def participant_lease_s(backend: str | None) -> float:
    """The participant lease of a backend's DDS; the longest when it is not known."""
    return PARTICIPANT_LEASE_S.get(backend or "", max(PARTICIPANT_LEASE_S.values()))


INSTALL_RCLPY = 'pip install "ros-jazzy-rclpy[fastrtps]" ros-jazzy-common-interfaces'

# rmw_fastrtps's publication mode: SYNCHRONOUS (its default: the publishing call sends to every
# reader) or ASYNCHRONOUS (Fast DDS's sending thread). Asynchronous streams the simulated
# campaign a third faster, but loses samples at its start to Cyclone DDS readers (docs/design.md
# §3.5), and adds about 3 ms of latency at real-time pace (README, "Measured figures").
PUBLICATION_MODE_ENV = "RMW_FASTRTPS_PUBLICATION_MODE"


def asynchronous_publication(
    node_backends: Iterable[str], env: Mapping[str, str] | None = None
) -> dict[str, str]:
    """The environment that makes rmw_fastrtps publish asynchronously, for a graph whose every
    node is on rclpy (no Cyclone DDS reader among them); nothing for a mixed or DDS graph, or
    when the user chose a mode (``RMW_FASTRTPS_PUBLICATION_MODE`` set). The caller decides
    whether the graph is paced as fast as it goes (the simulated campaign), where latency does
    not matter."""
    env = os.environ if env is None else env
    if PUBLICATION_MODE_ENV in env or set(node_backends) != {"rclpy"}:
        return {}
    return {PUBLICATION_MODE_ENV: "ASYNCHRONOUS"}


class RosEnvironmentError(ArgumentError):
    """A ROS environment variable with a value no ROS 2 node would accept."""


def domain_id(env: MutableMapping[str, str] | None = None) -> int:
    env = os.environ if env is None else env
    text = env.get(DOMAIN_ENV, "0").strip() or "0"
    try:
        value = int(text)
    except ValueError:
        raise RosEnvironmentError(f"{DOMAIN_ENV}={text!r} is not an integer (0..232)") from None
    if not 0 <= value <= MAX_DOMAIN_ID:
        raise RosEnvironmentError(f"{DOMAIN_ENV}={value} is outside 0..{MAX_DOMAIN_ID}")
    return value


def discovery_range(env: MutableMapping[str, str] | None = None) -> str:
    """The automatic discovery range; unset: the alias, else SUBNET as in ROS 2 Jazzy."""
    env = os.environ if env is None else env
    text = env.get(RANGE_ENV, "").strip().upper()
    if text:
        if text not in RANGES:
            raise RosEnvironmentError(f"{RANGE_ENV}={text!r}: expected one of {', '.join(RANGES)}")
        return text
    alias = env.get(NETWORK_ALIAS_ENV, "").strip().lower()
    if alias:
        if alias not in ("loopback", "lan"):
            raise RosEnvironmentError(
                f"{NETWORK_ALIAS_ENV}={alias!r}: expected 'loopback' or 'lan'"
            )
        return "LOCALHOST" if alias == "loopback" else "SUBNET"
    return "SUBNET"


def static_peers(env: MutableMapping[str, str] | None = None) -> list[str]:
    env = os.environ if env is None else env
    return [p.strip() for p in env.get(PEERS_ENV, "").split(";") if p.strip()]


def rclpy_available() -> bool:
    try:
        import rclpy  # noqa: F401
    except ImportError:
        return False
    return True


def backend_name(env: MutableMapping[str, str] | None = None) -> str:
    """``rclpy`` or ``dds``: the variable if set (rclpy must then import), else rclpy where it
    imports, else dds."""
    env = os.environ if env is None else env
    choice = env.get(BACKEND_ENV, "").strip().lower()
    if choice in ("dds", "cyclonedds"):
        return "dds"
    if choice == "rclpy":
        if not rclpy_available():
            raise RosEnvironmentError(
                f"{BACKEND_ENV}=rclpy but rclpy does not import: install it with "
                f"`{INSTALL_RCLPY}` (CPython 3.10-3.13, x86_64 Linux), source a ROS 2 Jazzy "
                f"install, or set {BACKEND_ENV}=dds"
            )
        return "rclpy"
    if choice:
        raise RosEnvironmentError(f"{BACKEND_ENV}={choice!r}: expected 'rclpy' or 'dds'")
    return "rclpy" if rclpy_available() else "dds"


def check(env: MutableMapping[str, str] | None = None) -> str:
    """Validate the ROS environment (raises RosEnvironmentError with one clear line) and make the
    alias visible to rmw: returns the backend name."""
    env = os.environ if env is None else env
    domain_id(env)
    found = discovery_range(env)
    if not env.get(RANGE_ENV) and env.get(NETWORK_ALIAS_ENV):
        env[RANGE_ENV] = found  # rmw_fastrtps reads only the ROS variable
    return backend_name(env)


def localhost_by_default(env: MutableMapping[str, str]) -> None:
    """A simulated graph stays on this machine unless the user chose a discovery range."""
    if not env.get(RANGE_ENV) and not env.get(NETWORK_ALIAS_ENV):
        env[RANGE_ENV] = "LOCALHOST"
