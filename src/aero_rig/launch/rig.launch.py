"""Wind-tunnel campaign under ROS 2: the nodes of aero_rig/config/rig.yaml.

    ros2 launch aero_rig rig.launch.py [record:=true] [run_dir:=runs/wing1] [graph:=...]

Everything is built from the graph YAML by aero_rig.launch_description (docs/ros_machine.md).
"""

from aero_rig.launch_description import generate_graph_launch_description


def generate_launch_description():
    return generate_graph_launch_description("rig.yaml")
