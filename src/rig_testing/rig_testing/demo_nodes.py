"""Talker and listener: minimal nodes to check a graph, the transport and the launcher (their
processes: talker.py and listener.py).

``talker`` publishes ``count`` numbered messages (JointState, or a 49-tap PointCloud2) at
``rate_hz`` (0 = as fast as the transport takes); ``listener`` counts them, checks their order
and writes a JSON summary to ``result_file`` when it stops. Like demo_nodes_py, but with
loss and order accounting.
"""

import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rig_runtime.interface import PITCH_JOINT
from rig_runtime.messages import set_stamp
from rig_runtime.node import Node
from rig_runtime.params import Parameter
from rig_runtime.qos_profiles import QOS_BY_NAME

COMMON = [
    Parameter("topic", "/chatter", "topic name"),
    Parameter("message", "joint_state", "payload", choices=("joint_state", "taps")),
    Parameter("qos", "stream", "QoS profile", choices=("default", "sensor", "latched", "stream")),
]

TALKER_PARAMETERS = [
    *COMMON,
    Parameter("count", 100, "messages to publish", min=1),
    Parameter("rate_hz", 0.0, "publish rate [Hz]; 0 = as fast as possible", min=0.0),
    Parameter("wait_for_subscribers", 1, "subscribers to wait for before publishing", min=0),
    Parameter("start_delay_s", 0.0, "wait this long after the subscribers matched [s]", min=0.0),
    Parameter("exit_code", 0, "exit with this code once done (launcher tests)", min=0, max=255),
    Parameter("linger_s", 1.0, "keep running this long after the last message [s]", min=0.0),
]

LISTENER_PARAMETERS = [
    *COMMON,
    Parameter("count", 0, "stop after this many messages (0 = run until stopped)", min=0),
    Parameter("result_file", "", "write a JSON summary here when stopping"),
]

TAP_COUNT = 49
MESSAGE_TYPES = {"joint_state": "sensor_msgs/msg/JointState", "taps": "sensor_msgs/msg/PointCloud2"}


def make_message(node: Node, kind: str, seq: int) -> Any:
    if kind == "joint_state":
        msg = node.new_message(
            "sensor_msgs/msg/JointState", name=[PITCH_JOINT], position=[float(seq)]
        )
    else:
        fields = [
            node.new_message(
                "sensor_msgs/msg/PointField", name=n, offset=4 * i, datatype=7, count=1
            )
            for i, n in enumerate(("x", "y", "z", "pressure"))
        ]
        points = np.zeros((TAP_COUNT, 4), dtype=np.float32)
        points[:, 3] = seq  # float32 holds integers exactly up to 2**24
        msg = node.new_message(
            "sensor_msgs/msg/PointCloud2",
            height=1,
            width=TAP_COUNT,
            fields=fields,
            point_step=16,
            row_step=16 * TAP_COUNT,
            data=points.view(np.uint8).ravel(),
            is_dense=True,
        )
    set_stamp(msg.header.stamp, time.time_ns())
    return msg


def sequence_number(kind: str, msg: Any) -> int:
    if kind == "joint_state":
        return int(msg.position[0])
    return int(np.frombuffer(np.asarray(msg.data, dtype=np.uint8).tobytes(), np.float32)[3])


class TalkerNode(Node):
    """Its messages on the serialized path (node.py), as the rig's streams."""

    NODE_NAME = "talker"
    PARAMETERS = TALKER_PARAMETERS

    def __init__(self, argv: Sequence[str] | None = None) -> None:
        super().__init__(self.NODE_NAME, self.PARAMETERS, argv)
        p = self.p = self.parameter_values()  # all read-only
        self.kind = p["message"]
        type_name = MESSAGE_TYPES[self.kind]
        self.pub = self.create_publisher(type_name, p["topic"], QOS_BY_NAME[p["qos"]])
        self.sent = 0
        self.matched_at: float | None = None
        self.done_at: float | None = None
        period = 1.0 / p["rate_hz"] if p["rate_hz"] > 0 else 0.001
        self.create_timer(period, self.tick)

    def tick(self) -> None:
        p = self.p
        if self.done_at is not None:
            if time.monotonic() - self.done_at >= p["linger_s"]:
                self.request_shutdown(p["exit_code"])
            return
        if self.matched_at is None:
            if self.pub.subscription_count() < p["wait_for_subscribers"]:
                return
            self.matched_at = time.monotonic()
            self.get_logger().info(
                f"{self.pub.subscription_count()} subscriber(s) matched; publishing in "
                f"{p['start_delay_s']:g} s"
            )
        if time.monotonic() - self.matched_at < p["start_delay_s"]:
            return
        burst = 1 if p["rate_hz"] > 0 else 500
        for _ in range(burst):
            self.pub.publish(make_message(self, self.kind, self.sent))
            self.sent += 1
            if self.sent >= p["count"]:
                self.get_logger().info(f"published {self.sent} messages")
                self.done_at = time.monotonic()
                return


class ListenerNode(Node):
    NODE_NAME = "listener"
    PARAMETERS = LISTENER_PARAMETERS

    def __init__(self, argv: Sequence[str] | None = None) -> None:
        super().__init__(self.NODE_NAME, self.PARAMETERS, argv)
        p = self.p = self.parameter_values()  # all read-only
        self.kind = p["message"]
        type_name = MESSAGE_TYPES[self.kind]
        self.received = 0
        self.out_of_order = 0
        self.last = -1
        self.first_ns: int | None = None
        self.last_ns = 0
        self.create_subscription(type_name, p["topic"], self.on_message, QOS_BY_NAME[p["qos"]])
        self.on_shutdown(self.write_summary)

    def on_message(self, msg: Any) -> None:
        seq = sequence_number(self.kind, msg)
        if seq <= self.last:
            self.out_of_order += 1
        self.last = seq
        self.received += 1
        now = time.monotonic_ns()
        if self.first_ns is None:
            self.get_logger().info(f"receiving: first message {seq}")
        self.first_ns = self.first_ns or now
        self.last_ns = now
        if self.p["count"] and self.received >= self.p["count"]:
            self.request_shutdown()

    def write_summary(self) -> None:
        if self.p["result_file"]:
            summary = {
                "received": self.received,
                "out_of_order": self.out_of_order,
                "last": self.last,
                "span_s": (self.last_ns - (self.first_ns or self.last_ns)) / 1e9,
            }
            Path(self.p["result_file"]).write_text(json.dumps(summary))
