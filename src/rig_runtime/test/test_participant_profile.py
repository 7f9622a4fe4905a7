"""A node's participant discovers as ROS's range says, over UDP alone (participant_profile.py):
the profile for each range, the environment rmw reads while the participant is made, and a
real node's process, which maps no Fast DDS shared-memory port and, on LOCALHOST, listens on no
multicast discovery port."""

import json
import subprocess
import sys

import pytest

from rig_runtime import participant_profile
from rig_runtime.participant_profile import (
    PROFILES_ENV,
    PROFILES_FILE,
    participant_environment,
    participant_xml,
    profiles_xml,
)
from rig_runtime.ros_environment import RANGE_ENV, RosEnvironmentError
from rig_testing.processes import graph_env

LOCATOR = "<locator><udpv4><address>{}</address></udpv4></locator>"


@pytest.fixture(autouse=True)
def new_process(monkeypatch: pytest.MonkeyPatch) -> None:
    """Each test as a process that has made no participant yet."""
    monkeypatch.setattr(participant_profile, "_MADE_WITH", [])


def test_localhost_discovers_by_unicast_on_this_host_only() -> None:
    xml = participant_xml("LOCALHOST", ["10.0.0.7"])
    unicast = "<metatrafficUnicastLocatorList><locator><udpv4></udpv4></locator>"
    assert unicast in xml  # keeps Fast DDS from adding its multicast locator
    peers = LOCATOR.format("10.0.0.7") + LOCATOR.format("127.0.0.1")
    assert f"<initialPeersList>{peers}</initialPeersList>" in xml
    assert "<transport_id>rig_udpv4</transport_id>" in xml
    assert "<useBuiltinTransports>false</useBuiltinTransports>" in xml


def test_subnet_keeps_multicast_discovery_and_adds_peers() -> None:
    alone = participant_xml("SUBNET", [])
    assert "initialPeersList" not in alone and "metatraffic" not in alone
    with_peer = participant_xml("SUBNET", ["10.0.0.7"])
    peers = LOCATOR.format("10.0.0.7") + LOCATOR.format("239.255.0.1")
    assert f"<initialPeersList>{peers}</initialPeersList>" in with_peer


def test_participants_announce_ten_times_at_first_then_every_second() -> None:
    # Fast DDS's own timing (five announcements in 0.5 s, then one every 3 s) made a graph
    # started over a few seconds wait up to 3 s for its last pairs to match (bench/discovery.py).
    for xml in (participant_xml("LOCALHOST", []), participant_xml("SUBNET", ["10.0.0.7"])):
        builtin = xml.split("<builtin>")[1].split("</builtin>")[0]
        assert builtin.count("<discovery_config>") == 1
        assert (
            "<initialAnnouncements><count>10</count><period><sec>0</sec>"
            "<nanosec>100000000</nanosec></period></initialAnnouncements>"
        ) in builtin
        assert "<leaseAnnouncement><sec>1</sec><nanosec>0</nanosec></leaseAnnouncement>" in builtin
        # the lease itself stays Fast DDS's (ros_environment.PARTICIPANT_LEASE_S)
        assert "leaseDuration>" not in builtin


def test_the_profile_adds_the_participant_to_the_writers_settings() -> None:
    text = profiles_xml("LOCALHOST", [])
    assert text.startswith(PROFILES_FILE.read_text().split("</profiles>")[0])
    assert text.rstrip().endswith("</participant>\n</profiles>")


def test_rmw_reads_system_default_and_the_profile_only_while_the_participant_is_made() -> None:
    env = {RANGE_ENV: "LOCALHOST", "ROS_STATIC_PEERS": "127.0.0.1"}
    with participant_environment(env):
        assert env[RANGE_ENV] == "SYSTEM_DEFAULT"
        with open(env[PROFILES_ENV]) as profile:
            assert "<participant " in profile.read()
    assert env == {RANGE_ENV: "LOCALHOST", "ROS_STATIC_PEERS": "127.0.0.1"}
    # The same configuration again is fine; another one in the same process is refused: Fast
    # DDS keeps the profile it read first.
    with participant_environment(dict(env)):
        pass
    for other in ({RANGE_ENV: "SUBNET"}, {RANGE_ENV: "OFF"}, {**env, PROFILES_ENV: "/my.xml"}):
        with pytest.raises(RosEnvironmentError, match="needs a process of its own"):
            with participant_environment(dict(other)):
                pass


def test_off_and_system_default_get_the_writers_profile_and_share_a_process() -> None:
    for range_ in ("OFF", "SYSTEM_DEFAULT"):
        env = {RANGE_ENV: range_}
        with participant_environment(env):
            assert env == {RANGE_ENV: range_, PROFILES_ENV: str(PROFILES_FILE)}
        assert env == {RANGE_ENV: range_}
    with pytest.raises(RosEnvironmentError, match="needs a process of its own"):
        with participant_environment({RANGE_ENV: "LOCALHOST"}):
            pass


def test_a_node_that_failed_does_not_fix_the_process_configuration() -> None:
    with pytest.raises(ValueError):
        with participant_environment({RANGE_ENV: "OFF"}):
            raise ValueError("bad ROS arguments")
    with participant_environment({RANGE_ENV: "LOCALHOST"}):
        pass
    assert participant_profile._MADE_WITH == [("udp", "LOCALHOST")]


def test_ros_localhost_only_is_read_as_localhost_and_kept_from_rcl() -> None:
    env = {RANGE_ENV: "SUBNET", "ROS_LOCALHOST_ONLY": "1"}
    with participant_environment(env):
        assert env[RANGE_ENV] == "SYSTEM_DEFAULT" and "ROS_LOCALHOST_ONLY" not in env
        with open(env[PROFILES_ENV]) as profile:
            assert "<metatrafficUnicastLocatorList>" in profile.read()
    assert env == {RANGE_ENV: "SUBNET", "ROS_LOCALHOST_ONLY": "1"}


def test_another_rmw_is_left_the_environment_as_it_is() -> None:
    env = {RANGE_ENV: "LOCALHOST", "RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"}
    with participant_environment(env):
        assert env == {RANGE_ENV: "LOCALHOST", "RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"}
    assert participant_profile._MADE_WITH == []


def test_a_profile_file_of_the_users_own_is_left_to_rmw() -> None:
    env = {RANGE_ENV: "LOCALHOST", PROFILES_ENV: "/etc/mine.xml"}
    with participant_environment(env):
        assert env == {RANGE_ENV: "LOCALHOST", PROFILES_ENV: "/etc/mine.xml"}


def test_a_peer_that_does_not_resolve_is_a_clear_error() -> None:
    env = {RANGE_ENV: "LOCALHOST", "ROS_STATIC_PEERS": "no-such-host.invalid"}
    with pytest.raises(RosEnvironmentError, match=r"'no-such-host\.invalid' has no IPv4 address"):
        with participant_environment(env):
            pass
    assert PROFILES_ENV not in env and env[RANGE_ENV] == "LOCALHOST"


# A participant made in a process of its own: the Fast DDS shared-memory files it maps and the
# UDP ports it binds.
PROBE = """
import json, os, sys
import psutil
if sys.argv[1] == "rig":
    from rig_runtime.node import Node
    node = Node("profile_probe")
else:
    import rclpy
    rclpy.init()
    node = rclpy.create_node("profile_probe")
maps = open(f"/proc/{os.getpid()}/maps").read()
print(json.dumps(sorted({l.split()[-1] for l in maps.splitlines() if "/dev/shm/fastrtps" in l})))
print(json.dumps(sorted({c.laddr.port for c in psutil.Process().net_connections(kind="udp")})))
"""


def _probe(kind: str, range_: str = "LOCALHOST") -> tuple[list[str], list[int], str]:
    env = {**graph_env(), RANGE_ENV: range_}  # graph_env: LOCALHOST, this machine only
    done = subprocess.run(
        [sys.executable, "-c", PROBE, kind], env=env, capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stdout + done.stderr
    shm, ports = done.stdout.strip().splitlines()[-2:]
    multicast_port = 7400 + 250 * int(env["ROS_DOMAIN_ID"])  # RTPS 2.2, 9.6.1.1: PB + DG·d
    bound = [p for p in json.loads(ports) if p == multicast_port]
    return json.loads(shm), bound, done.stdout


def test_a_node_maps_no_shared_memory_port_and_on_localhost_no_multicast_port() -> None:
    shm, multicast, out = _probe("rig")
    assert shm == [] and multicast == [], out
    assert "XMLPARSER" not in out  # Fast DDS read the profile
    # The check can fail: rmw_fastrtps's own LOCALHOST maps its shared-memory ports.
    shm, multicast, _ = _probe("plain")
    assert any("fastrtps_port" in path for path in shm) and multicast == []


def test_a_node_on_subnet_maps_no_shared_memory_port_and_discovers_by_multicast() -> None:
    shm, multicast, out = _probe("rig", "SUBNET")
    assert shm == [] and multicast != [], out
    assert "XMLPARSER" not in out
