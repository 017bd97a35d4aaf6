"""Messages for routines: ``from mexone.msgs import Float64, JointState`` (rospy's
``from std_msgs.msg import Float64`` and ``from sensor_msgs.msg import JointState``)."""

from mexone.bus.msgs import (
    Clock,
    Duration,
    Float64,
    Float64MultiArray,
    Header,
    JointState,
    JointTrajectory,
    JointTrajectoryPoint,
    TFMessage,
    Time,
    TransformStamped,
)

__all__ = ["Clock", "Duration", "Float64", "Float64MultiArray", "Header", "JointState",
           "JointTrajectory", "JointTrajectoryPoint", "Time", "TFMessage", "TransformStamped"]
