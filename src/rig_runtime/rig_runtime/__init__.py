"""Node runtime for the pitching-wing rig.

One node API over two backends (rclpy on ROS machines, Cyclone DDS everywhere else, both
speaking ROS 2's wire format), a graph launcher and a rosbag2 (MCAP) recorder.
"""

from .messages import new_message, set_stamp, stamp_to_ns
from .node import Node, run_node
from .params import Parameter, ParameterError
from .qos import PROFILES, QosProfile

__all__ = [
    "PROFILES",
    "Node",
    "Parameter",
    "ParameterError",
    "QosProfile",
    "new_message",
    "run_node",
    "set_stamp",
    "stamp_to_ns",
]
