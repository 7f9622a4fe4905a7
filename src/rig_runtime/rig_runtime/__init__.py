"""Node runtime for the pitching-wing rig: one node API over rclpy or Cyclone DDS, graph launcher, rosbag2 MCAP recorder."""
