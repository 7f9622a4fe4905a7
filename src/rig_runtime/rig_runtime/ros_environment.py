"""The ROS 2 environment a node runs in: rclpy, domain and discovery range (ROS 2's own
variables, as rmw implementations read them; docs/design.md §3.1).

- ``ROS_DOMAIN_ID``: 0..232 (the RTPS port formula's limit for participant index 0..120).
- ``ROS_AUTOMATIC_DISCOVERY_RANGE``: ``SUBNET`` (ROS's default when unset), ``LOCALHOST``,
  ``OFF`` or ``SYSTEM_DEFAULT``; ``ROS_STATIC_PEERS``: ``;``-separated addresses that are
  always contacted (unless the range is ``OFF``). rmw_fastrtps reads both itself.
- ``RIG_DDS_NETWORK=loopback|lan``: an older alias, read only when
  ``ROS_AUTOMATIC_DISCOVERY_RANGE`` is unset (loopback = LOCALHOST, lan = SUBNET).

Simulated campaigns (``aero-rig campaign``, ``aero-rig run sim``, ``sim.launch.py``) use
LOCALHOST unless the range is set: they stay on this machine (:func:`localhost_by_default`).

This module imports without rclpy: it is what says, in one line, that rclpy is missing.
"""

import os
from collections.abc import Mapping, MutableMapping


class ArgumentError(ValueError):
    """A malformed ``--ros-args`` section or ROS environment."""


# Set by the launcher for its nodes: a node whose parent process is no longer the launcher
# (it was killed, even with SIGKILL) stops instead of running on unattended (node.py).
LAUNCHER_PID_ENV = "RIG_LAUNCHER_PID"
RANGE_ENV = "ROS_AUTOMATIC_DISCOVERY_RANGE"
PEERS_ENV = "ROS_STATIC_PEERS"
DOMAIN_ENV = "ROS_DOMAIN_ID"
NETWORK_ALIAS_ENV = "RIG_DDS_NETWORK"
RANGES = ("SUBNET", "LOCALHOST", "OFF", "SYSTEM_DEFAULT")
MAX_DOMAIN_ID = 232
# How long a participant that stopped announcing itself (a paused, hung or dead process) stays
# matched: Fast DDS's default participant leaseDuration (20 s; rmw_fastrtps and
# fastdds_profiles.xml leave it). After that a reliable writer drops the reader and what it
# did not deliver; the campaign's liveness bound is derived from it (aero_rig/cli/liveness.py).
PARTICIPANT_LEASE_S = 20.0

INSTALL_RCLPY = 'pip install "ros-jazzy-rclpy[fastrtps]" ros-jazzy-common-interfaces'
# What every graph command says, in one line, where rclpy does not import.
NO_RCLPY = (
    "rclpy does not import here: the node graph needs it. Install it with "
    f"`{INSTALL_RCLPY}` (PyPI wheels: CPython 3.10-3.13, x86_64 Linux), source a ROS 2 Jazzy "
    "install, or on macOS, aarch64 and Windows install RoboStack's conda packages "
    "(`conda install -c conda-forge -c robostack-jazzy ros-jazzy-rclpy`). `aero-rig fit`, "
    "`aero-rig view BAG` and `aero-rig bag` work without it."
)

# rmw_fastrtps's publication mode: SYNCHRONOUS (its default: the publishing call sends to every
# reader) or ASYNCHRONOUS (Fast DDS's sending thread). Asynchronous streams the simulated
# campaign a third faster and adds about 3 ms of latency at real-time pace (docs/results.md).
PUBLICATION_MODE_ENV = "RMW_FASTRTPS_PUBLICATION_MODE"


def asynchronous_publication(env: Mapping[str, str] | None = None) -> dict[str, str]:
    """The environment that makes rmw_fastrtps publish asynchronously; nothing when the user
    chose a mode (``RMW_FASTRTPS_PUBLICATION_MODE`` set). The caller decides whether the
    graph is paced as fast as it goes (the simulated campaign), where latency does not
    matter."""
    env = os.environ if env is None else env
    if PUBLICATION_MODE_ENV in env:
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


def require_rclpy() -> None:
    """Raise RosEnvironmentError with :data:`NO_RCLPY` where rclpy does not import."""
    if not rclpy_available():
        raise RosEnvironmentError(NO_RCLPY)


def check(env: MutableMapping[str, str] | None = None) -> int:
    """Validate the ROS environment (raises RosEnvironmentError with one clear line) and make the
    alias visible to rmw: returns the domain id."""
    env = os.environ if env is None else env
    domain = domain_id(env)
    found = discovery_range(env)
    if not env.get(RANGE_ENV) and env.get(NETWORK_ALIAS_ENV):
        env[RANGE_ENV] = found  # rmw_fastrtps reads only the ROS variable
    return domain


def localhost_by_default(env: MutableMapping[str, str]) -> None:
    """A simulated graph stays on this machine unless the user chose a discovery range."""
    if not env.get(RANGE_ENV) and not env.get(NETWORK_ALIAS_ENV):
        env[RANGE_ENV] = "LOCALHOST"
