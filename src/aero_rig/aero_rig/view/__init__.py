"""Rerun view of a pitching-wing experiment, live (an rclpy node) or from a rosbag: the view node
(node.py, whose docstring says what it shows), its logger, recording streams and blueprint.

The node module is not imported here: it needs rclpy, which ``view_bag`` does not."""

from .blueprint import (
    CL_SCALE,
    CP_X_SCALE,
    ENTITY,
    PREDICTION_COLORS,
    SPARE_COLORS,
    TIMELINE,
    make_blueprint,
    slug,
)
from .logger import RigViewLogger, describe_segment
from .recording import MODES, TOPICS, close_recording, open_recording, view_bag

__all__ = [
    "CL_SCALE",
    "CP_X_SCALE",
    "ENTITY",
    "MODES",
    "PREDICTION_COLORS",
    "SPARE_COLORS",
    "TIMELINE",
    "TOPICS",
    "RigViewLogger",
    "close_recording",
    "describe_segment",
    "make_blueprint",
    "open_recording",
    "slug",
    "view_bag",
]
