"""Node runtime for the pitching-wing rig.

An rclpy node base class with the rig's contract (parameters, start barrier, anomalies), a graph
launcher and a rosbag2 (MCAP) recorder.

The names below load their module on first use (PEP 562), so that the light modules (the
interface contract ``rig_runtime.interface``, the graph description ``rig_runtime.graph``,
``rig_runtime.qos``) import without loading rosbags or rclpy: the ROS launch
files and the offline tools use them in processes that must not load a middleware.
"""

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # what __getattr__ loads, for the type checker
    from .messages import new_message, set_stamp, stamp_to_ns
    from .node import Node
    from .node_main import run_node
    from .params import Parameter, ParameterError
    from .qos import PROFILES, QosProfile

_EXPORTS = {
    "PROFILES": "qos",
    "QosProfile": "qos",
    "Node": "node",
    "run_node": "node_main",
    "Parameter": "params",
    "ParameterError": "params",
    "new_message": "messages",
    "set_stamp": "messages",
    "stamp_to_ns": "messages",
}

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


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'rig_runtime' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"rig_runtime.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])
