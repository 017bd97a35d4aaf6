"""The bridge to a real ROS 1 graph (Debian's rospy): a front end, like the GUI."""

from mexone.ros1.bridge import CLOCK_PERIOD, ROS_INSTALL, Ros1Bridge, import_rospy
from mexone.ros1.params import config_from_param_server

__all__ = ["CLOCK_PERIOD", "ROS_INSTALL", "Ros1Bridge", "config_from_param_server", "import_rospy"]
