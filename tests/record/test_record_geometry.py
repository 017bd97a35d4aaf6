"""geometry_msgs and nav_msgs in bags (cmd_vel's Twist, goals' PoseStamped, a walk's footsteps
PoseArray and planned Path), read back by rosbags' reader as ROS's own types."""

from __future__ import annotations

import pytest
from rosbags.highlevel import AnyReader

from mexone.bus import msgs
from mexone.lab import Lab
from mexone.record.bag import BagRecorder


@pytest.mark.parametrize("suffix", [".mcap", ".bag"])
def test_geometry_and_path_messages_are_recorded(tmp_path, suffix):
    lab = Lab.create(controllers=False)
    path = tmp_path / f"walk{suffix}"
    recorder = BagRecorder(lab, path)
    header = msgs.Header(3, msgs.Time(1, 250), "world")
    pose = msgs.Pose(msgs.Point(0.1, -0.06, 0.0), msgs.Quaternion(0.0, 0.0, 0.6, 0.8))
    sent = {
        "/mex_rb/cmd_vel": msgs.Twist(msgs.Vector3(0.15, 0.0, 0.0), msgs.Vector3(0.0, 0.0, 0.4)),
        "/mex_rb/l_hand/goal": msgs.PoseStamped(header, pose),
        "/mex_rb/walk/footsteps": msgs.PoseArray(header, [pose, msgs.Pose()]),
        "/mex_rb/walk/com_plan": msgs.Path(header, [msgs.PoseStamped(
            msgs.Header(3, msgs.Time(1, 10_000_250), "world"), pose)] * 3),
    }
    for topic, msg in sent.items():
        lab.bus.publish(topic, msg)
    recorder.close()
    with AnyReader([path]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        got = {c.topic: reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()}
    assert types == {"/mex_rb/cmd_vel": "geometry_msgs/msg/Twist",
                     "/mex_rb/l_hand/goal": "geometry_msgs/msg/PoseStamped",
                     "/mex_rb/walk/footsteps": "geometry_msgs/msg/PoseArray",
                     "/mex_rb/walk/com_plan": "nav_msgs/msg/Path"}
    assert (got["/mex_rb/cmd_vel"].linear.x, got["/mex_rb/cmd_vel"].angular.z) == (0.15, 0.4)
    goal = got["/mex_rb/l_hand/goal"]
    assert goal.header.frame_id == "world" and goal.header.stamp.nanosec == 250
    assert (goal.pose.position.y, goal.pose.orientation.z, goal.pose.orientation.w) == (-0.06, 0.6, 0.8)
    steps = got["/mex_rb/walk/footsteps"].poses
    assert len(steps) == 2 and steps[0].position.x == 0.1 and steps[1].orientation.w == 1.0
    plan = got["/mex_rb/walk/com_plan"]
    assert len(plan.poses) == 3 and plan.poses[2].header.stamp.nanosec == 10_000_250
