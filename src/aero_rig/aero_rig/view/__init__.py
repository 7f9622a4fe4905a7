"""Rerun view of a pitching-wing experiment, live (DDS) or from a rosbag: the view node
(node.py, whose docstring says what it shows), its logger, recording streams and blueprint."""

from .blueprint import CL_SCALE, CP_X_SCALE, ENTITY, TIMELINE, make_blueprint
from .logger import RigViewLogger, describe_segment
from .node import PARAMETERS, View, main
from .recording import MODES, TOPICS, close_recording, open_recording, view_bag

__all__ = [
    "CL_SCALE",
    "CP_X_SCALE",
    "ENTITY",
    "MODES",
    "PARAMETERS",
    "TIMELINE",
    "TOPICS",
    "RigViewLogger",
    "View",
    "close_recording",
    "describe_segment",
    "main",
    "make_blueprint",
    "open_recording",
    "view_bag",
]
