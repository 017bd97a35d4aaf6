"""Commands ROS nodes send to routines: geometry_msgs/Twist (cmd_vel) and PoseStamped (goals)
from Debian's rospy messages into the bus's, field for field; the bus classes name ROS's types
with ROS's md5sums (what a subscriber on ROS checks)."""

from __future__ import annotations

from pathlib import Path

import pytest

from mexone.bus import msgs

ROSCORE = "/usr/bin/roscore"


@pytest.fixture(scope="module")
def geometry():
    if not Path(ROSCORE).exists():
        pytest.skip("Debian ROS 1 is not installed (ros-core, python3-rospy)")
    from mexone.ros1.bridge import import_rospy

    import_rospy()
    import geometry_msgs.msg

    return geometry_msgs.msg


def test_twist_from_ros(geometry):
    from mexone.ros1 import convert

    ros = geometry.Twist()
    ros.linear.x, ros.linear.y, ros.angular.z = 0.15, -0.05, 0.4
    bus = convert.from_ros(ros)
    assert bus == msgs.Twist(msgs.Vector3(0.15, -0.05, 0.0), msgs.Vector3(0.0, 0.0, 0.4))
    assert convert.ros_class(msgs.Twist)._md5sum == "9f195f881246fdfa2798d1d3eebca84a"


def test_pose_stamped_from_ros(geometry):
    import rospy

    from mexone.ros1 import convert

    ros = geometry.PoseStamped()
    ros.header.frame_id, ros.header.seq = "world", 7
    ros.header.stamp = rospy.Time(3, 500)
    ros.pose.position.x, ros.pose.position.y, ros.pose.position.z = 0.25, 0.2, 0.75
    ros.pose.orientation.w = 1.0
    bus = convert.from_ros(ros)
    assert bus.header == msgs.Header(7, msgs.Time(3, 500), "world")
    assert bus.pose == msgs.Pose(msgs.Point(0.25, 0.2, 0.75), msgs.Quaternion(0.0, 0.0, 0.0, 1.0))
    assert convert.ros_class(msgs.PoseStamped)._md5sum == "d3812c3cbc69362b77dc0b19b345f8f5"
