"""diagnostic_msgs/DiagnosticArray construction shared by every node that reports health."""

import time
from collections.abc import Mapping
from typing import Any

# diagnostic_msgs/DiagnosticStatus levels
OK, WARN, ERROR, STALE = 0, 1, 2, 3


def diagnostic_array(
    name: str,
    level: int,
    message: str,
    hardware_id: str,
    values: Mapping[str, object],
) -> Any:
    """An rclpy DiagnosticArray with one status, stamped now (wall clock, as diagnostics are)."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

    msg = DiagnosticArray()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(time.time_ns(), 1_000_000_000)
    msg.status = [
        DiagnosticStatus(
            level=bytes([int(level)]),
            name=name,
            message=message,
            hardware_id=hardware_id,
            values=[KeyValue(key=str(k), value=str(v)) for k, v in values.items()],
        )
    ]
    return msg
