"""Whole-body motion commanded from ROS, end to end: `mexone run walk_cmd_vel --ros` walks where
a real rospy node's geometry_msgs/Twist on /mex_rb/cmd_vel says and shows ROS its plan
(footsteps, ZMP); `mexone run reach_goals --ros` moves the hand to a geometry_msgs/PoseStamped
goal, read back through gazebo_ros' /gazebo/get_link_state."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import numpy as np
import pytest
from test_bridge import ros_env, stop

from mexone.robots.mex_one import END_EFFECTORS


def start_run(port: int, routine: str, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "mexone", "run", routine, "--ros", "--json",
                             "--quiet", "--rtf", "2", *extra], env=ros_env(port),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)


def started(rospy, run: subprocess.Popen) -> float:
    """The run's sim time once it is on ROS (its first joint_states), s."""
    from sensor_msgs.msg import JointState

    msg = rospy.wait_for_message("/mex_rb/joint_states", JointState, timeout=90)
    assert run.poll() is None
    return msg.header.stamp.to_sec()


def sim_time_wait(rospy, run: subprocess.Popen, until: float, every=None) -> None:
    """Wait (calling `every` each 50 ms of wall time) until the run's sim time reaches `until`."""
    deadline = time.time() + 120
    while rospy.get_time() < until and run.poll() is None and time.time() < deadline:
        if every:
            every()
        time.sleep(0.05)


def report(run: subprocess.Popen) -> dict:
    out, err = run.communicate(timeout=120)
    assert run.returncode == 0, err
    return json.loads(out)


def test_cmd_vel_from_a_ros_node_walks_and_the_plan_reaches_ros(ros_master):
    rospy, port = ros_master
    from geometry_msgs.msg import PoseArray, Twist
    from nav_msgs.msg import Path

    run = start_run(port, "walk_cmd_vel", "--duration", "14")
    try:
        t0 = started(rospy, run)
        footsteps, zmp = [], []
        subs = [rospy.Subscriber("/mex_rb/walk/footsteps", PoseArray, footsteps.append),
                rospy.Subscriber("/mex_rb/walk/zmp_plan", Path, zmp.append)]
        pub = rospy.Publisher("/mex_rb/cmd_vel", Twist, queue_size=1)
        forward = Twist()
        forward.linear.x = 0.1
        # 6 s of sim time at 0.1 m/s, then silence: the walk stops 0.5 s after the last command
        sim_time_wait(rospy, run, t0 + 6.0, every=lambda: pub.publish(forward))
        result = report(run)
    finally:
        stop(run)
        for sub in subs:
            sub.unregister()
    assert not result["fell"] and result["error"] is None
    # 0.6 m commanded, plus the steps planned while the last command was fresh (0.5 s) and the
    # feet's forward slip (8-22 %: the README's limits); 0.77 m measured; straight ahead
    assert 0.45 < result["distance_x"] < 1.0, result
    assert abs(result["drift_y"]) < 0.1 and abs(result["yaw"]) < 5
    # the plan as rviz sees it: sole centres stepping forward in the world frame, and a ZMP path
    assert footsteps and zmp and zmp[-1].poses
    assert footsteps[-1].header.frame_id == "world"
    ahead = max(p.position.x for msg in footsteps for p in msg.poses)
    assert ahead > 0.3
    assert all(abs(p.position.y) < 0.2 for msg in footsteps for p in msg.poses)


def test_a_posestamped_goal_from_a_ros_node_moves_the_hand(ros_master):
    rospy, port = ros_master
    from gazebo_msgs.srv import GetLinkState
    from geometry_msgs.msg import PoseStamped

    goal = np.array([0.25, 0.2, 0.75])
    run = start_run(port, "reach_goals", "--duration", "6")
    try:
        t0 = started(rospy, run)
        pub = rospy.Publisher("/mex_rb/l_hand/goal", PoseStamped, queue_size=1, latch=True)
        msg = PoseStamped()
        msg.header.frame_id = "world"
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = goal
        pub.publish(msg)
        sim_time_wait(rospy, run, t0 + 4.5)  # 1 s to move, then holding and trimming
        rospy.wait_for_service("/gazebo/get_link_state", timeout=30)
        link, offset = END_EFFECTORS["l_hand"]
        state = rospy.ServiceProxy("/gazebo/get_link_state", GetLinkState)(f"mex_rb::{link}",
                                                                           "world")
        result = report(run)
    finally:
        stop(run)
        pub.unregister()
    assert state.success, state.status_message
    p, q = state.link_state.pose.position, state.link_state.pose.orientation
    import mujoco

    rotation = np.zeros(9)
    mujoco.mju_quat2Mat(rotation, np.array([q.w, q.x, q.y, q.z]))
    hand = np.array([p.x, p.y, p.z]) + rotation.reshape(3, 3) @ np.array(offset)
    assert np.linalg.norm(hand - goal) == pytest.approx(0.0, abs=0.006)
    assert not result["fell"] and result["error"] is None
