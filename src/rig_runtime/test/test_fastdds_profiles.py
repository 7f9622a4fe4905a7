"""The nodes' Fast DDS profile file (rig_runtime/fastdds_profiles.xml) is one that Fast
DDS accepts. Fast DDS ignores a file it cannot parse, whole, with one error line on stdout (its
default log consumer) and nothing else: the writers would then fall back to Fast DDS's 100 ms
max_blocking_time and 3 s heartbeat period without any sign in the graph."""

import subprocess
import sys
from pathlib import Path

from rig_runtime.participant_profile import PROFILES_ENV, PROFILES_FILE, profiles_xml
from rig_testing.processes import graph_env

# A participant and a writer made with the file as Fast DDS's default profiles.
MAKE_A_WRITER = """
import rclpy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node("profile_check")
node.create_publisher(String, "profile_check", 10)
node.destroy_node()
rclpy.shutdown()
print("writer made")
"""


def _output_of_a_writer(profiles: Path) -> str:
    env = graph_env()
    env[PROFILES_ENV] = str(profiles)
    proc = subprocess.run(
        [sys.executable, "-c", MAKE_A_WRITER],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 0 and "writer made" in proc.stdout, proc.stdout + proc.stderr
    return proc.stdout + proc.stderr


def test_fast_dds_parses_the_profile_file() -> None:
    text = PROFILES_FILE.read_text()
    assert "<max_blocking_time><sec>60</sec></max_blocking_time>" in text
    assert "<heartbeatPeriod><sec>0</sec><nanosec>100000000</nanosec></heartbeatPeriod>" in text
    assert "XMLPARSER" not in _output_of_a_writer(PROFILES_FILE)


def test_fast_dds_parses_the_participant_profiles(tmp_path: Path) -> None:
    """The files participant_profile writes for the UDP ranges: the transport, the discovery
    peers and the announcements' timing."""
    for range_, peers in (("LOCALHOST", []), ("SUBNET", ["10.0.0.7"])):
        profile = tmp_path / f"{range_}.xml"
        profile.write_text(profiles_xml(range_, peers))
        assert "<initialAnnouncements>" in profile.read_text()
        assert "XMLPARSER" not in _output_of_a_writer(profile), range_


def test_a_profile_file_fast_dds_rejects_is_seen(tmp_path: Path) -> None:
    """The check above can fail: a misspelt element makes Fast DDS reject the file (as a
    ``<heartbeat_period>`` under ``<times>`` did while this was written: Fast DDS 2.14 spells
    it ``heartbeatPeriod``)."""
    broken = tmp_path / "broken.xml"
    broken.write_text(PROFILES_FILE.read_text().replace("</qos>", "</qos><times><x/></times>"))
    assert "XMLPARSER" in _output_of_a_writer(broken)
