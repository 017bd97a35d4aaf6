"""Messages for routines: ``from mexone.msgs import Float64, JointState`` (rospy's
``from std_msgs.msg import Float64`` and ``from sensor_msgs.msg import JointState``)."""

from mexone.bus.msgs import *  # noqa: F403 - this module is the routines' name for them
from mexone.bus.msgs import __all__  # noqa: F401
