"""Every test of the workspace: ROS 2 discovery on this machine only (loopback), whatever the
environment of the shell that runs pytest (tests never reach another host)."""

import os

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_STATIC_PEERS", None)
os.environ.pop("RIG_DDS_NETWORK", None)
