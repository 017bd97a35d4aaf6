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


def test_the_walk_plan_types_are_ros_own(geometry):
    """Footsteps and planned paths go to ROS as geometry_msgs/PoseArray and nav_msgs/Path
    (rviz's PoseArray and Path displays), field for field."""
    from mexone.ros1 import convert

    assert convert.ros_class(msgs.PoseArray)._md5sum == "916c28c5764443f268b296bb671b9d97"
    assert convert.ros_class(msgs.Path)._md5sum == "6227e2b7e9cce15051f669a5e197bbf7"
    header = msgs.Header(2, msgs.Time(4, 7), "world")
    pose = msgs.Pose(msgs.Point(0.05, 0.06, 0.0), msgs.Quaternion(0.0, 0.0, 0.6, 0.8))
    assert convert.can_send(msgs.PoseArray) and convert.can_send(msgs.Path)
    steps = convert.to_ros(msgs.PoseArray(header, [pose]), convert.ros_class(msgs.PoseArray))
    assert steps.header.frame_id == "world" and (steps.header.stamp.secs, steps.header.stamp.nsecs) == (4, 7)
    assert (steps.poses[0].position.y, steps.poses[0].orientation.z) == (0.06, 0.6)
    path = convert.to_ros(msgs.Path(header, [msgs.PoseStamped(header, pose)] * 2),
                          convert.ros_class(msgs.Path))
    assert len(path.poses) == 2 and path.poses[1].pose.orientation.w == 0.8
    assert path.poses[1].header.stamp.nsecs == 7
    buffer = __import__("io").BytesIO()
    path.serialize(buffer)  # what rospy sends: the types are complete
    assert len(buffer.getvalue()) > 0


def test_a_topic_whose_ros_package_is_missing_is_skipped_with_a_warning(monkeypatch, caplog):
    """A ROS without nav_msgs still bridges everything else; the walk plan's Path topics are
    named once, with the package to install (sync_topics on a bare bridge: no master needed)."""
    from types import SimpleNamespace

    from mexone.bus.topics import Bus
    from mexone.ros1 import bridge, convert

    monkeypatch.setattr(convert, "ros_class", lambda bus_type: None)
    bus = Bus()
    bus.advertise("/mex_rb/walk/com_plan", msgs.Path)
    fake = SimpleNamespace(lab=SimpleNamespace(bus=bus), _known_topics=-1, _mirrors={},
                           _inbound={}, _unsendable=set())
    with caplog.at_level("WARNING", logger="mexone.ros"):
        bridge.Ros1Bridge.sync_topics(fake)
        bus.advertise("/mex_rb/walk/zmp_plan", msgs.Path)
        bridge.Ros1Bridge.sync_topics(fake)
        bridge.Ros1Bridge.sync_topics(fake)
    assert fake._mirrors == {}
    assert fake._unsendable == {"/mex_rb/walk/com_plan", "/mex_rb/walk/zmp_plan"}
    warnings = [r.getMessage() for r in caplog.records]
    assert len(warnings) == 2
    assert "nav_msgs/Path" in warnings[0] and "python3-nav-msgs" in warnings[0]
