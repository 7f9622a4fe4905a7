"""Recorder node: topics of the graph to a rosbag2 directory with MCAP storage.

Records the listed topics (or every topic with a publisher when ``topics`` is empty) as raw
CDR, with the Jazzy type hash and the offered QoS in metadata.yaml, like
``ros2 bag record -s mcap``. Readers match the offered QoS (transient-local topics are
recorded from their last latched sample; reliable topics with keep-all history so nothing is
dropped under load). Chunks are zstd-compressed (``compression``); one file per bag unless
``max_bag_size`` / ``max_bag_duration`` ask for splits. Finalised on SIGINT/SIGTERM; the open
chunk is written every ``flush_s``, so after ``kill -9`` the bag is readable up to its last
chunk (at most ``flush_s`` of data lost; ``aero-rig bag recover`` restores the footer, see
bag.py).
"""

import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .bag import COMPRESSIONS, BagWriter
from .node import Node
from .node_main import run_node
from .params import Parameter
from .qos import QosProfile

PARAMETERS = [
    Parameter("output", "", "bag directory to create (must not exist); required"),
    Parameter(
        "topics",
        [],
        "topics to record; empty = every topic that has a publisher",
        element_type=str,
    ),
    Parameter("exclude", ["/rosout", "/parameter_events"], "topics never recorded"),
    Parameter(
        "compression",
        "zstd",
        "MCAP chunk compression: zstd (default), lz4 (faster, larger) or none",
        choices=tuple(COMPRESSIONS),
    ),
    Parameter(
        "max_bag_size",
        0,
        "start a new bag file once the open one holds this many bytes (it may pass it by up to "
        "one chunk); 0 = no size split (default, like ros2 bag record)",
        min=0,
    ),
    Parameter(
        "max_bag_duration",
        0.0,
        "start a new bag file once the open one spans this many seconds of recorded time; "
        "0 = no duration split (default, like ros2 bag record)",
        min=0.0,
    ),
    Parameter(
        "flush_s",
        1.0,
        "write the open chunk and metadata.yaml at least this often [s]: the most a kill -9 "
        "can lose",
        min=0.01,
        max=3600.0,
    ),
    Parameter("discovery_period_s", 0.2, "how often to look for new topics [s]", min=0.01),
    Parameter(
        "drain_timeout_s",
        3.0,
        "on shutdown, wait this long at most for the publishers to leave, recording what they "
        "still deliver, before the bag is closed [s]",
        min=0.0,
        max=60.0,
    ),
]


class RecorderNode(Node):
    """Every reader raw (CDR bytes and receive time), written to the bag as received."""

    NODE_NAME = "recorder"
    PARAMETERS = PARAMETERS

    def __init__(self, argv: Sequence[str] | None = None) -> None:
        super().__init__(self.NODE_NAME, self.PARAMETERS, argv)
        p = self.parameter_values()
        output = p["output"]
        if not output:
            raise ValueError("parameter 'output' is required: the bag directory to create")
        self.wanted = [self.resolve_topic_name(t) for t in p["topics"]]
        self.exclude = set(p["exclude"])
        self.writer = BagWriter(
            Path(output),
            compression=p["compression"],
            max_bag_size=p["max_bag_size"],
            max_bag_duration_ns=round(p["max_bag_duration"] * 1e9),
        )
        self.readers: dict[str, Any] = {}
        self.on_shutdown(self.finalise)
        # The start barrier waits until each of these topics that a member publishes is recorded.
        self.set_records(self.wanted or ["*"], sorted(self.exclude))
        self.get_logger().info(
            f"recording {', '.join(self.wanted) or 'all topics'} to {Path(output).resolve()}"
        )
        self._discover()
        self.create_timer(p["discovery_period_s"], self._discover)
        self.create_timer(p["flush_s"], self.writer.flush)

    def _discover(self) -> None:
        for topic, (type_name, offered) in self.topic_types().items():
            if topic in self.readers or topic in self.exclude:
                continue
            if self.wanted and topic not in self.wanted:
                continue
            self._subscribe(topic, type_name, offered)

    def _subscribe(self, topic: str, type_name: str, offered: QosProfile | None) -> None:
        offered = offered or QosProfile("reliable", "volatile", 10)
        reader_qos = QosProfile(
            offered.reliability,
            offered.durability,
            0 if offered.reliability == "reliable" else 1000,
        )
        connection = self.writer.add_connection(topic, type_name, offered)

        def on_message(item: tuple[bytes, int]) -> None:
            data, receive_ns = item
            self.writer.write(connection, receive_ns, data)

        self.readers[topic] = self.create_subscription(
            type_name, topic, on_message, qos_profile=reader_qos, raw=True
        )
        self.get_logger().info(f"recording {topic} [{type_name}]")

    def _publishing(self) -> list[str]:
        """Recorded topics that still have a publisher other than this node itself (every
        node writes /graph/ready and /experiment/anomaly, the recorder too)."""
        endpoints = self.readiness_report().endpoints
        writers = [e for e in endpoints if e.kind == "writer"]
        out = []
        for e in endpoints:
            if e.kind != "reader" or e.topic not in self.readers:
                continue
            others = e.matched_count - sum(w.topic == e.topic for w in writers)
            if others > 0:
                out.append(e.topic)
        return out

    def finalise(self) -> None:
        # Stopped together with the graph (rig-launch, ros2 launch: SIGINT to every node at
        # once): the publishers send what they still hold as they leave; record it before the
        # bag is closed, so a stopped graph loses nothing.
        timeout = self.get_parameter("drain_timeout_s").value
        if not self.drain(lambda: not self._publishing(), timeout):
            self.get_logger().warning(
                f"{', '.join(self._publishing())} still published after {timeout:.1f} s: "
                "closing the bag"
            )
        self.writer.close()
        self.get_logger().info(
            f"bag {self.writer.path} finalised: {self.writer.message_count} messages in "
            f"{', '.join(self.writer.files) or 'no file'}"
        )


def main(argv: list[str] | None = None) -> int:
    return run_node(RecorderNode, argv, description=__doc__ or "")


if __name__ == "__main__":
    sys.exit(main())
