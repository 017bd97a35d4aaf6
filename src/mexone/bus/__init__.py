"""Topics with ROS names and ROS-shaped messages, in process (and bridged to ROS 1 on request)."""

from mexone.bus.msgs import (
    ROS_TYPES,
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
from mexone.bus.topics import Bus, Subscription, Topic, resolve_name

__all__ = [
    "Bus",
    "Topic",
    "Subscription",
    "resolve_name",
    "ROS_TYPES",
    "Clock",
    "Duration",
    "Float64",
    "Float64MultiArray",
    "Header",
    "JointState",
    "JointTrajectory",
    "JointTrajectoryPoint",
    "Time",
    "TFMessage",
    "TransformStamped",
]
