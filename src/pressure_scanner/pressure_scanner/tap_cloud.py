"""Tap pressures <-> sensor_msgs/PointCloud2 (docs/design.md §4 ``/pressure/taps``).

One point per tap, in tap order: x, y, z [m, wing frame: x along the chord from the leading
edge, y spanwise, z normal, upper side positive] and pressure [Pa], all float32 (16 bytes per
point). A missing or invalid tap is a NaN pressure; its point stays, so the order holds.
"""

from typing import Any

import numpy as np

FIELDS = ("x", "y", "z", "pressure")
POINT_STEP = 16
FLOAT32 = 7  # sensor_msgs/PointField.FLOAT32


def point_fields(new_message: Any) -> list[Any]:
    """The four PointField descriptions of a tap cloud (build once, reuse per message)."""
    return [
        new_message(
            "sensor_msgs/msg/PointField", name=name, offset=4 * i, datatype=FLOAT32, count=1
        )
        for i, name in enumerate(FIELDS)
    ]


def fill_cloud(
    msg: Any,
    new_message: Any,
    tap_xyz: np.ndarray,
    pressures_pa: np.ndarray,
    fields: list[Any] | None = None,
) -> Any:
    """Fill a PointCloud2 message in place from (n, 3) positions and (n,) pressures."""
    n = len(pressures_pa)
    points = np.empty((n, 4), dtype=np.float32)
    points[:, :3] = tap_xyz
    points[:, 3] = pressures_pa
    msg.height = 1
    msg.width = n
    msg.fields = fields if fields is not None else point_fields(new_message)
    msg.is_bigendian = False
    msg.point_step = POINT_STEP
    msg.row_step = POINT_STEP * n
    msg.data = points.view(np.uint8).ravel()
    msg.is_dense = bool(np.all(np.isfinite(pressures_pa)))
    return msg


def read_cloud(msg: Any) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) tap positions [m] and (n,) pressures [Pa] (float64) of a tap cloud.

    Raises ValueError when the cloud does not have the x, y, z, pressure float32 layout.
    """
    names = [f.name for f in msg.fields]
    if names[:4] != list(FIELDS) or int(msg.point_step) != POINT_STEP or msg.is_bigendian:
        raise ValueError(
            f"/pressure/taps cloud has fields {names}, point_step {msg.point_step}: expected "
            f"{list(FIELDS)} float32 little endian, 16 bytes per point"
        )
    raw = np.asarray(msg.data, dtype=np.uint8)
    points = np.frombuffer(raw.tobytes(), dtype=np.float32).reshape(-1, 4)
    return points[:, :3].astype(np.float64), points[:, 3].astype(np.float64)
