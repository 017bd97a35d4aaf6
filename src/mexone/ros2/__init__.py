"""The simulator as a ROS 2 participant (rclpy from PyPI's ROS 2 wheels): a front end, like the
ROS 1 bridge, sharing its table of bus topics and ROS types (`mexone.bus.ros_map`)."""

from mexone.ros2.bridge import DEFAULT_NODE, ROS2_INSTALL, Ros2Bridge, check_not_both, import_rclpy

__all__ = ["DEFAULT_NODE", "ROS2_INSTALL", "Ros2Bridge", "check_not_both", "import_rclpy"]
