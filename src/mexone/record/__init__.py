"""Recordings: rosbag-compatible bags (MCAP or ROS 1 .bag) written from the bus, read back, plotted,
recovered and rendered to video."""
