"""Bringup for the pitching-wing rig.

Graph descriptions, parameter files, ROS launch files, the ``aero-rig`` command line and the
Rerun view node.
"""
