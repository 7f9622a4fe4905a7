"""Rerun view of a pitching-wing experiment, live (DDS) or from a rosbag.

Shows, on the ``experiment_time`` timeline (the message stamps): commanded and measured pitch
[deg] and C_l over time; the Cp distribution over the chord (−Cp up, upper and lower surface,
decimated); on each ``/identification/model`` update the FRF |G| [dB] with its noise and
nonlinear-distortion variances [dB] per level, the cluster label of every period, the models'
C_l–α predictions against the measured sine records and the validation table; segment events and
identification status as text logs. A blueprint lays these out.

Modes: ``save`` writes ``rrd_path``; ``spawn`` starts a Rerun Viewer; ``serve`` runs a gRPC
server a viewer connects to; ``connect`` streams to a running viewer at ``url``; ``none`` only
counts messages (not ``off``: YAML reads that as false). With ``rrd_path`` set, every mode
also saves to that file.

This module imports rerun (numpy >= 2): run it from the project's virtual environment on the
Cyclone DDS backend, never in an rclpy process (docs/design.md §3). ``RigViewLogger`` has no
middleware and takes plain messages; ``view_bag`` replays a recorded bag through it.
"""

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
