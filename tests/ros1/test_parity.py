"""ROS parity (issue 14) against Debian's ROS 1 on a free loopback port: the controller manager
services, dynparam, the follow_joint_trajectory action, gazebo_ros' services and topics, /clock
while paused and across a reset, /rosout, robot_state_publisher and tf2 on clean stamps, and
a second simulator on the same master. One roscore and one `mexone sim --ros` for the module."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

sys.path.insert(0, str(Path(__file__).parent))
from test_bridge import RSP, ros_env, stop  # noqa: E402

pytestmark = pytest.mark.slow


def start_sim(port: int, *extra: str, rtf: str = "1") -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "mexone", "sim", "--ros", "--headless",
                             "--rtf", rtf, *extra], env=ros_env(port), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)


@pytest.fixture(scope="module")
def ros(ros_master):
    rospy, port = ros_master
    sim = start_sim(port)
    from sensor_msgs.msg import JointState

    rospy.wait_for_message("/mex_rb/joint_states", JointState, timeout=60)
    yield rospy, port, sim
    stop(sim)


def service(rospy, name: str, kind):
    rospy.wait_for_service(name, timeout=30)
    return rospy.ServiceProxy(name, kind)


def joints(rospy) -> dict[str, float]:
    from sensor_msgs.msg import JointState

    msg = rospy.wait_for_message("/mex_rb/joint_states", JointState, timeout=10)
    return dict(zip(msg.name, msg.position, strict=True))


def wait_sim(rospy, seconds: float) -> None:
    """Wait for `seconds` of sim time (the sim runs at real time; allow for a slow machine)."""
    from rosgraph_msgs.msg import Clock

    start = rospy.wait_for_message("/clock", Clock, timeout=10).clock.to_sec()
    deadline = time.time() + 10 * seconds + 10
    while time.time() < deadline:
        if rospy.wait_for_message("/clock", Clock, timeout=10).clock.to_sec() >= start + seconds:
            return
    raise AssertionError("sim time did not advance")


def test_sensor_topics_reach_ros_while_someone_subscribes(ros):
    """The sensors publish only while someone listens: a ROS subscriber is someone. The IMU at
    rest reads gravity; the Kinect's cloud comes in its optical frame, points in front of it."""
    rospy, port, _ = ros
    from sensor_msgs import point_cloud2
    from sensor_msgs.msg import PointCloud2

    out = subprocess.run(["rostopic", "echo", "-n1", "/mex_rb/imu"], env=ros_env(port),
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    imu = yaml.safe_load(out.stdout.split("---")[0])
    assert imu["header"]["frame_id"] == "pelvis"
    acc = imu["linear_acceleration"]
    assert acc["z"] == pytest.approx(9.81, abs=0.3) and abs(acc["x"]) < 0.3, acc
    cloud = rospy.wait_for_message("/mex_rb/kinect/depth/points", PointCloud2, timeout=60)
    assert cloud.header.frame_id == "kinect_depth_optical_frame"
    assert cloud.width * cloud.height > 10_000
    points = list(point_cloud2.read_points(cloud, ("x", "y", "z"), skip_nans=True))
    assert len(points) > 1000 and all(0.05 < z < 20.0 for _, _, z in points[::97]), points[:3]


def test_controller_manager_services_load_switch_and_the_trajectory_action(ros):
    rospy, port, _ = ros
    import actionlib
    from control_msgs.msg import FollowJointTrajectoryAction, FollowJointTrajectoryGoal, JointTolerance
    from control_msgs.srv import QueryTrajectoryState
    from controller_manager_msgs.srv import (
        ListControllers,
        ListControllerTypes,
        LoadController,
        SwitchController,
        UnloadController,
    )
    from trajectory_msgs.msg import JointTrajectoryPoint

    base = "/mex_rb/controller_manager/"
    listed = service(rospy, base + "list_controllers", ListControllers)().controller
    states = {c.name: c.state for c in listed}
    assert states["l_elbow_position_controller"] == "running" and len(states) == 22
    elbow = next(c for c in listed if c.name == "l_elbow_position_controller")
    assert elbow.claimed_resources[0].resources == ["l_elbow"]
    types = service(rospy, base + "list_controller_types", ListControllerTypes)().types
    assert "effort_controllers/JointTrajectoryController" in types
    # ros_control reads a controller's configuration from the parameter server when loading it
    rospy.set_param("/mex_rb/arm_controller", {
        "type": "effort_controllers/JointTrajectoryController",
        "joints": ["l_shoulder_pitch", "l_elbow"],
        "gains": {"l_shoulder_pitch": {"p": 100.0, "d": 1.5}, "l_elbow": {"p": 60.0, "d": 0.8}}})
    load = service(rospy, base + "load_controller", LoadController)
    assert load("arm_controller").ok
    assert not load("arm_controller").ok  # already loaded
    assert not load("no_such_controller").ok
    switch = service(rospy, base + "switch_controller", SwitchController)
    # STRICT: the joints are still driven by the position controllers -> refused, nothing changes
    assert not switch(["arm_controller"], [], 2, False, 0.0).ok
    assert not switch(["arm_controller", "nope"], ["l_elbow_position_controller",
                                                   "l_shoulder_pitch_position_controller"], 2, False, 0.0).ok
    assert switch(["arm_controller"], ["l_elbow_position_controller",
                                       "l_shoulder_pitch_position_controller"], 2, False, 0.0).ok
    client = actionlib.SimpleActionClient("/mex_rb/arm_controller/follow_joint_trajectory",
                                          FollowJointTrajectoryAction)
    assert client.wait_for_server(rospy.Duration(30))
    goal = FollowJointTrajectoryGoal()
    goal.trajectory.joint_names = ["l_elbow", "l_shoulder_pitch"]
    goal.trajectory.points = [JointTrajectoryPoint(positions=[-0.6, -0.4],
                                                   time_from_start=rospy.Duration(1.0))]
    goal.goal_tolerance = [JointTolerance("l_elbow", 0.03, 0, 0), JointTolerance("l_shoulder_pitch", 0.03, 0, 0)]
    goal.goal_time_tolerance = rospy.Duration(2.0)
    client.send_goal(goal)
    query = service(rospy, "/mex_rb/arm_controller/query_state", QueryTrajectoryState)
    assert client.wait_for_result(rospy.Duration(30))
    assert client.get_state() == actionlib.GoalStatus.SUCCEEDED
    assert client.get_result().error_code == 0
    q = joints(rospy)
    assert q["l_elbow"] == pytest.approx(-0.6, abs=0.03) and q["l_shoulder_pitch"] == pytest.approx(-0.4, abs=0.03)
    state = query(rospy.get_rostime() + rospy.Duration(100))  # after the end: the last point
    assert state.name == ["l_shoulder_pitch", "l_elbow"] and state.position == pytest.approx([-0.4, -0.6])
    # an impossible tolerance aborts with GOAL_TOLERANCE_VIOLATED
    goal.goal_tolerance = [JointTolerance("l_elbow", 1e-7, 0, 0)]
    goal.goal_time_tolerance = rospy.Duration(0.01)
    goal.trajectory.points[0].positions = [-0.2, -0.2]
    client.send_goal(goal)
    assert client.wait_for_result(rospy.Duration(30))
    assert client.get_state() == actionlib.GoalStatus.ABORTED and client.get_result().error_code == -5
    # back as it was
    assert switch(["l_elbow_position_controller", "l_shoulder_pitch_position_controller"],
                  ["arm_controller"], 2, False, 0.0).ok
    assert service(rospy, base + "unload_controller", UnloadController)("arm_controller").ok


def test_dynparam_set_changes_the_gain_seen_on_the_state_topic(ros):
    rospy, port, _ = ros
    from control_msgs.msg import JointControllerState

    topic = "/mex_rb/l_elbow_position_controller/state"
    assert rospy.wait_for_message(topic, JointControllerState, timeout=10).p == 60.0
    env = ros_env(port) | {"PATH": "/usr/bin:" + os.environ["PATH"]}  # dynparam: env python3
    out = subprocess.run(["rosrun", "dynamic_reconfigure", "dynparam", "set",
                          "/mex_rb/l_elbow_position_controller/pid", "p", "50"], env=env,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert rospy.wait_for_message(topic, JointControllerState, timeout=10).p == 50.0
    subprocess.run(["rosrun", "dynamic_reconfigure", "dynparam", "set",
                    "/mex_rb/l_elbow_position_controller/pid", "p", "60"], env=env, timeout=60,
                   capture_output=True)


def test_apply_body_wrench_changes_the_base_velocity_by_the_impulse(ros):
    rospy, port, _ = ros
    from gazebo_msgs.msg import ModelState
    from gazebo_msgs.srv import ApplyBodyWrench, GetModelState, SetModelState
    from geometry_msgs.msg import Point, Wrench
    from std_srvs.srv import Empty

    get = service(rospy, "/gazebo/get_model_state", GetModelState)
    service(rospy, "/gazebo/pause_physics", Empty)()
    try:
        state = ModelState(model_name="mex_rb")
        state.pose.position.z = 30.0  # in the air: no friction takes part of the impulse (and
        # the fall stays in the air for 2 s of wall time however late the pause arrives)
        state.pose.orientation.w = 1.0
        assert service(rospy, "/gazebo/set_model_state", SetModelState)(state).success
        wrench = Wrench()
        wrench.force.x = 30.0
        push = service(rospy, "/gazebo/apply_body_wrench", ApplyBodyWrench)
        answer = push("mex_rb::pelvis", "world", Point(), wrench, rospy.Time(0), rospy.Duration(0.1))
        assert answer.success, answer.status_message
        bad = push("mex_rb::nose", "world", Point(), wrench, rospy.Time(0), rospy.Duration(0.1))
        assert not bad.success and "nose" in bad.status_message
        before = get("mex_rb", "world").twist.linear.x
        service(rospy, "/gazebo/unpause_physics", Empty)()
        wait_sim(rospy, 0.25)
        service(rospy, "/gazebo/pause_physics", Empty)()
        after = get("mex_rb", "world")
        assert after.pose.position.z > 1.0  # still flying
        assert after.twist.linear.x - before == pytest.approx(30.0 * 0.1 / 15.0, rel=0.10)
    finally:
        service(rospy, "/gazebo/reset_simulation", Empty)()
        service(rospy, "/gazebo/unpause_physics", Empty)()


def test_set_model_configuration_moves_joints_and_they_stay(ros):
    rospy, port, _ = ros
    from gazebo_msgs.srv import SetModelConfiguration

    set_config = service(rospy, "/gazebo/set_model_configuration", SetModelConfiguration)
    answer = set_config("mex_rb", "robot_description", ["r_elbow", "neck_yaw"], [-0.9, 0.4])
    assert answer.success, answer.status_message
    wait_sim(rospy, 0.5)
    q = joints(rospy)
    assert q["r_elbow"] == pytest.approx(-0.9, abs=0.03) and q["neck_yaw"] == pytest.approx(0.4, abs=0.03)
    assert not set_config("mex_rb", "", ["r_elbow"], [0.1, 0.2]).success
    assert not set_config("mex_rb", "", ["wing"], [0.1]).success
    assert set_config("mex_rb", "", ["r_elbow", "neck_yaw"], [0.0, 0.0]).success


BOX = """<robot name="tray"><link name="tray"><inertial><mass value="0.3"/>
<inertia ixx="0.02" iyy="0.02" izz="0.04" ixy="0" ixz="0" iyz="0"/></inertial>
<collision><geometry><box size="0.7 0.7 0.03"/></geometry></collision></link></robot>"""


def test_spawn_urdf_model_adds_a_box_resting_on_the_robot_and_delete_removes_it(ros):
    rospy, port, _ = ros
    from gazebo_msgs.srv import DeleteModel, GetModelState, GetWorldProperties, SpawnModel
    from geometry_msgs.msg import Pose

    spawn = service(rospy, "/gazebo/spawn_urdf_model", SpawnModel)
    pose = Pose()
    pose.position.z, pose.orientation.w = 1.4, 1.0
    answer = spawn("tray", BOX, "", pose, "world")
    assert answer.success, answer.status_message
    assert not spawn("tray", BOX, "", pose, "world").success  # the name is taken
    assert not spawn("junk", "<robot", "", pose, "world").success
    assert "tray" in service(rospy, "/gazebo/get_world_properties", GetWorldProperties)().model_names
    wait_sim(rospy, 1.5)
    get = service(rospy, "/gazebo/get_model_state", GetModelState)
    z = get("tray", "world").pose.position.z
    assert 0.6 < z < 1.3  # lying on the robot's head and shoulders, not on the ground
    assert service(rospy, "/gazebo/delete_model", DeleteModel)("tray").success
    assert not get("tray", "world").success


def test_get_link_state_agrees_with_tf2_and_states_topics(ros):
    rospy, port, _ = ros
    import tf2_ros
    from gazebo_msgs.msg import LinkStates, ModelStates
    from gazebo_msgs.srv import GetLinkState
    from std_srvs.srv import Empty

    rsp = subprocess.Popen([RSP, "joint_states:=/mex_rb/joint_states"], env=ros_env(port),
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        buffer = tf2_ros.Buffer()
        tf2_ros.TransformListener(buffer)
        wait_sim(rospy, 1.0)
        service(rospy, "/gazebo/pause_physics", Empty)()
        time.sleep(0.5)
        tf = buffer.lookup_transform("world", "l_forearm", rospy.Time(0), rospy.Duration(10.0))
        state = service(rospy, "/gazebo/get_link_state", GetLinkState)("mex_rb::l_forearm", "world")
        assert state.success
        p, t = state.link_state.pose.position, tf.transform.translation
        assert [p.x, p.y, p.z] == pytest.approx([t.x, t.y, t.z], abs=1e-3)
        o, r = state.link_state.pose.orientation, tf.transform.rotation
        assert abs(o.x * r.x + o.y * r.y + o.z * r.z + o.w * r.w) == pytest.approx(1.0, abs=1e-4)
        relative = service(rospy, "/gazebo/get_link_state", GetLinkState)("l_forearm", "pelvis")
        tf_rel = buffer.lookup_transform("pelvis", "l_forearm", rospy.Time(0), rospy.Duration(5.0))
        t = tf_rel.transform.translation
        p = relative.link_state.pose.position
        assert [p.x, p.y, p.z] == pytest.approx([t.x, t.y, t.z], abs=1e-3)
        service(rospy, "/gazebo/unpause_physics", Empty)()  # states flow while time does, as in Gazebo
        models = rospy.wait_for_message("/gazebo/model_states", ModelStates, timeout=10)
        assert models.name == ["ground_plane", "mex_rb"]
        links = rospy.wait_for_message("/gazebo/link_states", LinkStates, timeout=10)
        assert "mex_rb::l_forearm" in links.name
    finally:
        service(rospy, "/gazebo/unpause_physics", Empty)()
        stop(rsp)


def test_clock_is_published_while_paused(ros):
    rospy, port, _ = ros
    from rosgraph_msgs.msg import Clock
    from std_srvs.srv import Empty

    service(rospy, "/gazebo/pause_physics", Empty)()
    try:
        # this process already listens to /clock (sim time): let clocks sent before the pause
        # drain from its connection before taking the paused one
        time.sleep(0.3)
        first = rospy.wait_for_message("/clock", Clock, timeout=5).clock
        time.sleep(0.5)
        again = rospy.wait_for_message("/clock", Clock, timeout=5).clock  # what hung before
        assert again == first
    finally:
        service(rospy, "/gazebo/unpause_physics", Empty)()


def test_warnings_reach_rosout(ros):
    rospy, port, _ = ros
    from rosgraph_msgs.msg import Log
    from std_msgs.msg import Float64

    heard: list[Log] = []
    sub = rospy.Subscriber("/rosout", Log, heard.append)
    pub = rospy.Publisher("/mex_rb/neck_pitch_position_controller/command", Float64, queue_size=1)
    try:
        deadline = time.time() + 20
        while time.time() < deadline and not any("clamped" in m.msg for m in heard):
            pub.publish(Float64(9.0))  # beyond the joint limit: clamped, with a warning
            time.sleep(0.3)
        found = [m for m in heard if "clamped" in m.msg]
        assert found and found[0].name == "/mexone" and found[0].level == Log.WARN
    finally:
        pub.publish(Float64(0.0))
        pub.unregister()
        sub.unregister()


def test_robot_state_publisher_keeps_every_update_and_tf2_never_extrapolates(ros):
    """Integer-nanosecond stamps: robot_state_publisher at its default 50 Hz publishes >= 98% of
    joint_states updates (stamps 1 ns short of 20 ms apart made it skip every other one; a
    loaded machine still costs it the odd message from its queue), and 10,000 tf2 lookups at
    joint_states stamps all succeed."""
    rospy, port, _ = ros
    import tf2_ros
    from sensor_msgs.msg import JointState
    from tf2_msgs.msg import TFMessage

    rsp = subprocess.Popen([RSP, "joint_states:=/mex_rb/joint_states"], env=ros_env(port),
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    def published() -> tuple[int, list]:
        """(how many of 8 s of joint_states updates robot_state_publisher turned into the
        forearm's tf, those updates' stamps) in this process's view."""
        stamps: list = []
        forearm: set = set()

        def on_tf(msg):
            for t in msg.transforms:
                if t.child_frame_id == "l_forearm":
                    forearm.add(t.header.stamp.to_nsec())
        subs = [rospy.Subscriber("/mex_rb/joint_states", JointState,
                                 lambda m: stamps.append(m.header.stamp)),
                rospy.Subscriber("/tf", TFMessage, on_tf)]
        wait_sim(rospy, 8.0)
        for sub in subs:
            sub.unregister()
        time.sleep(0.5)
        return sum(s.to_nsec() in forearm for s in stamps[5:-5]), stamps

    def every_one(kept: int, stamps: list) -> bool:
        return len(stamps) - 10 > 300 and kept / (len(stamps) - 10) >= 0.98

    try:
        buffer = tf2_ros.Buffer(cache_time=rospy.Duration(60))
        tf2_ros.TransformListener(buffer)
        wait_sim(rospy, 1.0)
        tries = [published()]
        # a C++ node starved by a stalled host or another job loses a burst from its queue; the
        # bug (stamps 1 ns short of 20 ms) loses every other one in any window: a miss is
        # measured again, up to three windows of 8 s
        while not every_one(*tries[-1]) and len(tries) < 3:
            tries.append(published())
        print(f"kept by robot_state_publisher: {[(k, len(s) - 10) for k, s in tries]}")
        assert any(every_one(*t) for t in tries), [(k, len(s) - 10) for k, s in tries]
        kept, stamps = tries[-1]
        window = stamps[5:-5]
        assert all(s.to_nsec() % 1_000_000 == 0 for s in stamps)  # whole milliseconds, never 1 ns off
        failures = 0
        for i in range(10_000):
            stamp = window[i % len(window)]
            try:
                buffer.lookup_transform("pelvis", "l_forearm", stamp)
            except tf2_ros.ExtrapolationException:
                failures += 1
        assert failures == 0
    finally:
        stop(rsp)


def test_reset_restarts_time_at_zero_at_once_without_a_flood(ros):
    rospy, port, _ = ros
    from gazebo_msgs.srv import GetPhysicsProperties, SetPhysicsProperties
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    from std_srvs.srv import Empty

    get = service(rospy, "/gazebo/get_physics_properties", GetPhysicsProperties)
    physics = get()
    put = service(rospy, "/gazebo/set_physics_properties", SetPhysicsProperties)
    fast = put(physics.time_step, 0.0, physics.gravity, physics.ode_config)  # flat out
    assert fast.success, fast.status_message
    try:
        deadline = time.time() + 120
        while rospy.wait_for_message("/clock", Clock, timeout=10).clock.to_sec() < 60.0:
            assert time.time() < deadline, "did not reach 60 s of sim time"
            time.sleep(0.5)
    finally:
        assert put(physics.time_step, 1000.0, physics.gravity, physics.ode_config).success
    reset = service(rospy, "/gazebo/reset_simulation", Empty)  # found before the clock starts

    def reset_at_once() -> tuple[float, float, list[tuple[float, float]]]:
        """(wall time of the reset's call, of the first /clock back below 1 s after it, the
        joint states' (wall, stamp) meanwhile)."""
        clocks: list[tuple[float, float]] = []
        states: list[tuple[float, float]] = []
        subs = [rospy.Subscriber("/clock", Clock,
                                 lambda m: clocks.append((time.time(), m.clock.to_sec()))),
                rospy.Subscriber("/mex_rb/joint_states", JointState,
                                 lambda m: states.append((time.time(), m.header.stamp.to_sec())))]
        time.sleep(1.0)
        called = time.time()
        reset()
        time.sleep(1.5)
        for sub in subs:
            sub.unregister()
        return called, next(w for w, t in clocks if w >= called and t < 1.0), states

    called, first_zero, states = reset_at_once()
    tries = [first_zero - called]
    # a stall of the host or a neighbour's burst during the call (a service's round trip: two
    # processes' Python) says nothing of the reset: a miss is measured again, once the clock is
    # past 1 s again, up to three resets in all; a reset that waits misses all three
    while tries[-1] >= 0.1 + 0.05 and len(tries) < 3:
        wait_sim(rospy, 1.5)
        tries.append((lambda c, z, _: z - c)(*reset_at_once()))
    print(f"/clock back at zero {[round(t, 3) for t in tries]} s after the reset's call")
    assert min(tries) < 0.1 + 0.05  # + the service round trip
    after = [t for w, t in states if w > called and t < 5.0]
    assert len(after) <= 50 * 1.5 + 10  # 50 Hz of sim time, nothing replayed up to 60 s
    assert all(b > a for a, b in zip(after, after[1:], strict=False))
    subprocess.run(["rostopic", "pub", "-1", "/mex_rb/waist_yaw_position_controller/command",
                    "std_msgs/Float64", "data: 0.3"], env=ros_env(port), timeout=60, capture_output=True)
    wait_sim(rospy, 1.0)
    assert joints(rospy)["waist_yaw"] == pytest.approx(0.3, abs=0.02)
    subprocess.run(["rostopic", "pub", "-1", "/mex_rb/waist_yaw_position_controller/command",
                    "std_msgs/Float64", "data: 0.0"], env=ros_env(port), timeout=60, capture_output=True)


def test_a_second_simulator_needs_its_own_name_and_both_are_commanded(ros):
    rospy, port, _ = ros
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64

    clash = start_sim(port, "--duration", "1")
    out, err = clash.communicate(timeout=90)
    assert clash.returncode == 2 and "already runs" in err and "Traceback" not in err, err
    second = start_sim(port, "--name", "sim2", "--namespace", "robot2")
    try:
        msg = rospy.wait_for_message("/robot2/joint_states", JointState, timeout=90)
        assert "l_elbow" in msg.name
        first = rospy.Publisher("/mex_rb/l_elbow_position_controller/command", Float64, queue_size=1)
        other = rospy.Publisher("/robot2/l_elbow_position_controller/command", Float64, queue_size=1)
        deadline = time.time() + 30
        q1 = q2 = {}
        while time.time() < deadline:
            first.publish(Float64(-0.5))
            other.publish(Float64(-1.0))
            time.sleep(0.5)
            q1 = joints(rospy)
            m = rospy.wait_for_message("/robot2/joint_states", JointState, timeout=10)
            q2 = dict(zip(m.name, m.position, strict=True))
            if abs(q1["l_elbow"] + 0.5) < 0.03 and abs(q2["l_elbow"] + 1.0) < 0.03:
                break
        assert q1["l_elbow"] == pytest.approx(-0.5, abs=0.03)
        assert q2["l_elbow"] == pytest.approx(-1.0, abs=0.03)
        rospy.wait_for_service("/sim2/get_model_state", timeout=10)  # its own gazebo services
        first.publish(Float64(0.0))
        assert second.poll() is None and ros[2].poll() is None
    finally:
        stop(second)


def test_one_simulator_two_robots_each_with_its_own_controllers(ros):
    """spawn_urdf_model with a robot_namespace, as gazebo_ros' spawn_model -robot_namespace: the
    second Mex-One gets a controller manager at /robot2, the spawner starts the controllers
    from the parameter server there (all of them, so it stands), and each robot follows only
    its own commands."""
    rospy, port, _ = ros
    from controller_manager_msgs.srv import ListControllers
    from gazebo_msgs.srv import DeleteModel, GetModelState, SpawnModel
    from geometry_msgs.msg import Pose
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64
    from std_srvs.srv import Empty

    from mexone.robots import mex_one

    params = yaml.safe_load(mex_one.controllers_path().read_text())["mex_rb"]
    rospy.set_param("/robot2", params)
    pose = Pose()
    pose.position.y, pose.orientation.w = 1.5, 1.0
    get_state = service(rospy, "/gazebo/get_model_state", GetModelState)
    pose.position.z = get_state("mex_rb", "world").pose.position.z
    service(rospy, "/gazebo/pause_physics", Empty)()  # as spawn_model without -unpause: it
    spawn = service(rospy, "/gazebo/spawn_urdf_model", SpawnModel)  # stands once controlled
    answer = spawn("robot2", rospy.get_param("/robot_description"), "/robot2", pose, "world")
    assert answer.success, answer.status_message
    clash = spawn("robot3", rospy.get_param("/robot_description"), "/robot2", pose, "world")
    assert not clash.success and "/robot2" in clash.status_message
    every = [name for name, value in params.items() if isinstance(value, dict) and "type" in value]
    spawner = subprocess.Popen(["rosrun", "controller_manager", "spawner", "--namespace", "/robot2",
                                *every], env=ros_env(port),
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                               start_new_session=True)
    try:
        listed = service(rospy, "/robot2/controller_manager/list_controllers", ListControllers)
        deadline = time.time() + 60
        while time.time() < deadline and sum(c.state == "running"
                                             for c in listed().controller) < len(every):
            time.sleep(0.2)
        assert sorted(c.name for c in listed().controller if c.state == "running") == sorted(every)
        service(rospy, "/gazebo/unpause_physics", Empty)()
        msg = rospy.wait_for_message("/robot2/joint_states", JointState, timeout=60)
        assert "l_elbow" in msg.name
        first = rospy.Publisher("/mex_rb/l_elbow_position_controller/command", Float64, queue_size=1)
        other = rospy.Publisher("/robot2/l_elbow_position_controller/command", Float64, queue_size=1)
        neck = rospy.Publisher("/robot2/neck_yaw_position_controller/command", Float64, queue_size=1)
        deadline = time.time() + 30
        q1 = q2 = {}
        while time.time() < deadline:
            first.publish(Float64(-0.5))
            other.publish(Float64(-1.0))
            neck.publish(Float64(0.5))
            time.sleep(0.5)
            q1 = joints(rospy)
            m = rospy.wait_for_message("/robot2/joint_states", JointState, timeout=10)
            q2 = dict(zip(m.name, m.position, strict=True))
            if abs(q1["l_elbow"] + 0.5) < 0.03 and abs(q2["l_elbow"] + 1.0) < 0.03 \
                    and abs(q2["neck_yaw"] - 0.5) < 0.03:
                break
        assert q1["l_elbow"] == pytest.approx(-0.5, abs=0.03)
        assert q1["neck_yaw"] == pytest.approx(0.0, abs=0.03)
        assert q2["l_elbow"] == pytest.approx(-1.0, abs=0.03)
        assert q2["neck_yaw"] == pytest.approx(0.5, abs=0.03)
        first.publish(Float64(0.0))
        assert get_state("robot2", "world").pose.position.z > 0.5  # standing, held by its own
    finally:
        service(rospy, "/gazebo/unpause_physics", Empty)()
        stop(spawner)
        assert service(rospy, "/gazebo/delete_model", DeleteModel)("robot2").success
        rospy.delete_param("/robot2")
    import rosservice

    deadline = time.time() + 10  # its controller manager went with it
    while time.time() < deadline and rosservice.get_service_list(namespace="/robot2"):
        time.sleep(0.2)
    assert rosservice.get_service_list(namespace="/robot2") == [] and ros[2].poll() is None
