"""Hostile input from the ROS graph (issue 30): no service call, action goal or command may end
the simulation or pass for a success. Real round trips (rosservice, rospy, actionlib) against one
`mexone sim --ros` for the module; property-based tests (hypothesis) drive the same handler
functions in-process on a lab of their own, where a ROS round trip per example would be too slow.

The property tests run derandomized with a bounded number of examples. A longer run with fresh
examples: `MEXONE_FUZZ_EXAMPLES=2000 pytest -m fuzz tests/ros1/test_hostile_ros.py
--hypothesis-seed=1234`."""

from __future__ import annotations

import math
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from helpers import fuzz, wait_until

sys.path.insert(0, str(Path(__file__).parent))
from test_bridge import ros_env, start_mexone, stop  # noqa: E402

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import event, given  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

pytestmark = pytest.mark.slow

GAZEBO = ("pause_physics", "unpause_physics", "reset_simulation", "reset_world", "get_model_state",
          "set_model_state", "get_link_state", "set_link_state", "apply_body_wrench",
          "clear_body_wrenches", "apply_joint_effort", "clear_joint_forces", "get_world_properties",
          "get_model_properties", "get_physics_properties", "set_physics_properties",
          "set_model_configuration", "spawn_urdf_model", "spawn_sdf_model", "delete_model")
ARM = {"type": "effort_controllers/JointTrajectoryController", "joints": ["l_shoulder_pitch", "l_elbow"],
       "gains": {"l_shoulder_pitch": {"p": 100.0, "d": 1.5}, "l_elbow": {"p": 60.0, "d": 0.8}}}
BOX = """<robot name="box"><link name="box"><inertial><mass value="0.3"/>
<inertia ixx="0.002" iyy="0.002" izz="0.002" ixy="0" ixz="0" iyz="0"/></inertial>
<collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision></link></robot>"""
ARM_BOT = """<robot name="bot"><link name="base"><inertial><mass value="1"/>
<inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
<collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision></link>
<joint name="hinge" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>
<limit lower="-1" upper="1" effort="5" velocity="2"/></joint>
<link name="arm"><inertial><origin xyz="0 0 0.1"/><mass value="0.2"/>
<inertia ixx="0.001" iyy="0.001" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial></link>
<transmission name="t"><type>transmission_interface/SimpleTransmission</type>
<joint name="hinge"><hardwareInterface>hardware_interface/EffortJointInterface</hardwareInterface></joint>
<actuator name="m"><mechanicalReduction>1</mechanicalReduction></actuator></transmission></robot>"""
SDF_BOX = """<sdf version="1.6"><model name="box"><link name="box"><inertial><mass>0.3</mass>
<inertia><ixx>0.002</ixx><iyy>0.002</iyy><izz>0.002</izz></inertia></inertial>
<collision name="c"><geometry><box><size>0.1 0.1 0.1</size></box></geometry></collision></link>
</model></sdf>"""



# ----- one simulator for the module's round trips ---------------------------------------------
class Sim:
    def __init__(self, rospy, port, proc):
        self.rospy, self.port, self.proc = rospy, port, proc
        self.rosout: list = []
        self.services_at_first_states: set[str] = set()
        self.services_when_advertised: set[str] | None = None
        self.early_spawn: list = []  # the answer to a spawn sent as soon as the service was listed

    def service(self, name: str, kind):
        self.rospy.wait_for_service(name, timeout=30)
        return self.rospy.ServiceProxy(name, kind)

    def warnings(self, text: str) -> list[str]:
        return [m.msg for m in list(self.rosout) if m.name == "/mexone" and text in m.msg]

    def heard(self, text: str, timeout: float = 30.0) -> list[str]:
        """The simulator's /rosout lines containing `text`, waiting for the first (/rosout is a
        topic of its own: a line may arrive after the answer it explains)."""
        wait_until(lambda: self.warnings(text), timeout)
        return self.warnings(text)

    def assert_alive(self) -> None:
        """The process runs, /clock advances and the joint states are finite."""
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import JointState

        rospy = self.rospy
        assert self.proc.poll() is None, self.proc.stderr.read()
        first = rospy.wait_for_message("/clock", Clock, timeout=20).clock.to_sec()
        deadline = time.time() + 30
        while time.time() < deadline:
            now = rospy.wait_for_message("/clock", Clock, timeout=20).clock.to_sec()
            if now != first:
                break
        else:
            raise AssertionError("/clock did not advance")
        msg = rospy.wait_for_message("/mex_rb/joint_states", JointState, timeout=20)
        assert len(msg.position) == 21 and np.isfinite(msg.position).all(), msg.position
        assert np.isfinite(msg.velocity).all(), msg.velocity


def _gazebo_services(port: int) -> tuple[set[str], set[str]]:
    """(the /gazebo services, the published topics) the master lists now."""
    import rosgraph

    try:
        state = rosgraph.Master("/hostile_probe", master_uri=f"http://127.0.0.1:{port}").getSystemState()
    except Exception:  # noqa: BLE001 - the master is busy: no snapshot this time
        return set(), set()
    return {s for s, _ in state[2] if s.startswith("/gazebo/")}, {t for t, _ in state[0]}


@pytest.fixture(scope="module")
def sim(ros_master):
    """The module's simulator, watched while it starts: which /gazebo services the master lists
    when its joint_states are first advertised and when the first message arrives."""
    rospy, port = ros_master
    from rosgraph_msgs.msg import Log
    from sensor_msgs.msg import JointState

    s = Sim(rospy, port, None)
    first = threading.Event()

    def on_states(_msg):
        if not first.is_set():
            s.services_at_first_states = _gazebo_services(port)[0]
            first.set()
    sub = rospy.Subscriber("/mex_rb/joint_states", JointState, on_states)
    out = rospy.Subscriber("/rosout", Log, s.rosout.append)
    s.proc = start_mexone(port)

    def spawn_early() -> None:  # what a script does that calls spawn as soon as it can
        from gazebo_msgs.srv import SpawnModel
        from geometry_msgs.msg import Pose

        pose = Pose()
        pose.position.x, pose.position.z, pose.orientation.w = 2.0, 0.3, 1.0
        s.early_spawn.append(rospy.ServiceProxy("/gazebo/spawn_urdf_model", SpawnModel)(
            "early_box", BOX, "", pose, "world"))
    early = threading.Thread(target=spawn_early, daemon=True)
    deadline = time.time() + 120
    while time.time() < deadline and not first.is_set():
        snapshot = _gazebo_services(port)
        if "/gazebo/spawn_urdf_model" in snapshot[0] and early.ident is None:
            early.start()
        if "/mex_rb/joint_states" in snapshot[1] and s.services_when_advertised is None:
            s.services_when_advertised = snapshot[0]
        time.sleep(0.01)
    assert first.is_set(), "no joint_states within 120 s"
    early.join(60)
    sub.unregister()
    # the trajectory controller the action tests use, as ros_control loads one
    from controller_manager_msgs.srv import LoadController, SwitchController

    rospy.set_param("/mex_rb/arm_controller", ARM)
    base = "/mex_rb/controller_manager/"
    assert s.service(base + "load_controller", LoadController)("arm_controller").ok
    assert s.service(base + "switch_controller", SwitchController)(
        ["arm_controller"], ["l_elbow_position_controller", "l_shoulder_pitch_position_controller"],
        2, False, 0.0).ok
    yield s
    out.unregister()
    stop(s.proc)
    # the next module's simulator would read it as "controllers from the parameter server"
    rospy.delete_param("/mex_rb/arm_controller")


def test_gazebo_services_are_offered_before_the_robot_publishes(sim):
    """Gazebo offers its services before it spawns the robot (issue 24)."""
    expected = {f"/gazebo/{name}" for name in GAZEBO}
    assert sim.services_when_advertised is None or expected <= sim.services_when_advertised, \
        expected - sim.services_when_advertised
    assert expected <= sim.services_at_first_states, expected - sim.services_at_first_states
    # a spawn sent the moment the service was listed waited for the world and succeeded
    [answer] = sim.early_spawn
    assert answer.success, answer.status_message
    from gazebo_msgs.srv import DeleteModel

    assert sim.service("/gazebo/delete_model", DeleteModel)("early_box").success


def _rosservice(sim: Sim, *args: str) -> str:
    out = subprocess.run(["rosservice", "call", *args], env=ros_env(sim.port), capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_a_joint_set_beyond_its_limit_is_clamped_with_a_warning(sim):
    """The finding: l_elbow at 100 rad answered success and the simulator died of NaN."""
    out = _rosservice(sim, "/gazebo/set_model_configuration", "{model_name: mex_rb, "
                      "urdf_param_name: '', joint_names: [l_elbow], joint_positions: [100.0]}")
    assert "success: True" in out and "l_elbow 100 -> 0" in out, out
    from sensor_msgs.msg import JointState

    from mexone.description.loader import load_model
    from mexone.robots import mex_one

    upper = load_model(mex_one.urdf_path()).joints["l_elbow"].limit.upper
    sim.assert_alive()
    msg = sim.rospy.wait_for_message("/mex_rb/joint_states", JointState, timeout=20)
    assert dict(zip(msg.name, msg.position, strict=True))["l_elbow"] == pytest.approx(upper, abs=0.1)
    assert sim.heard("set_model_configuration: clamped to the joint limits: l_elbow 100 ->")
    _rosservice(sim, "/gazebo/set_model_configuration", "{model_name: mex_rb, urdf_param_name: '', "
                "joint_names: [l_elbow], joint_positions: [0.0]}")


def test_a_joint_set_to_an_absurd_value_is_refused(sim):
    out = _rosservice(sim, "/gazebo/set_model_configuration", "{model_name: mex_rb, "
                      "urdf_param_name: '', joint_names: [l_knee], joint_positions: [1.0e+30]}")
    assert "success: False" in out and "l_knee position 1e+30 must be a finite number" in out, out
    out = _rosservice(sim, "/gazebo/set_model_configuration", "{model_name: mex_rb, "
                      "urdf_param_name: '', joint_names: [l_knee, l_knee], joint_positions: [0.1, 0.2]}")
    assert "success: False" in out and "more than once" in out, out
    sim.assert_alive()


def test_spawn_far_away_is_refused(sim):
    from gazebo_msgs.srv import SpawnModel
    from geometry_msgs.msg import Pose

    pose = Pose()
    pose.position.x, pose.orientation.w = 1e300, 1.0
    answer = sim.service("/gazebo/spawn_urdf_model", SpawnModel)("far", BOX, "", pose, "world")
    assert not answer.success
    assert answer.status_message.startswith("initial_pose.position.x 1e+300 must be"), answer.status_message
    pose.position.x, pose.orientation.x = 0.0, math.nan
    answer = sim.service("/gazebo/spawn_sdf_model", SpawnModel)("nan", BOX, "", pose, "world")
    assert not answer.success and "not finite" in answer.status_message
    sim.assert_alive()


def test_switch_controller_refuses_an_unknown_strictness_and_a_nan_timeout(sim):
    from controller_manager_msgs.srv import SwitchController

    switch = sim.service("/mex_rb/controller_manager/switch_controller", SwitchController)
    assert not switch([], ["neck_yaw_position_controller"], 99, False, 0.0).ok
    assert not switch([], ["neck_yaw_position_controller"], 2, False, math.nan).ok
    assert not switch([], ["neck_yaw_position_controller"], 2, False, -1.0).ok
    assert sim.heard("strictness 99 must be BEST_EFFORT (1) or STRICT (2)")
    assert sim.heard("timeout NaN must be")
    from controller_manager_msgs.srv import ListControllers

    listed = sim.service("/mex_rb/controller_manager/list_controllers", ListControllers)().controller
    assert {c.name: c.state for c in listed}["neck_yaw_position_controller"] == "running"


def _goal(rospy, times, positions, velocities=None):
    from control_msgs.msg import FollowJointTrajectoryGoal
    from trajectory_msgs.msg import JointTrajectoryPoint

    goal = FollowJointTrajectoryGoal()
    goal.trajectory.joint_names = ["l_elbow", "l_shoulder_pitch"]
    goal.trajectory.points = [JointTrajectoryPoint(positions=list(p), velocities=list(v or []),
                                                   time_from_start=rospy.Duration(t))
                              for t, p, v in zip(times, positions, velocities or [None] * len(times),
                                                 strict=True)]
    return goal


def test_trajectory_goals_with_bad_times_or_positions_are_rejected(sim):
    """ros_controllers rejects times that do not strictly increase (INVALID_GOAL, its words);
    a negative time, a 1e30 position and velocities of the wrong length are refused the same way."""
    import actionlib
    from control_msgs.msg import FollowJointTrajectoryAction, FollowJointTrajectoryResult

    from mexone.control.controllers.trajectory import NOT_INCREASING

    rospy = sim.rospy
    client = actionlib.SimpleActionClient("/mex_rb/arm_controller/follow_joint_trajectory",
                                          FollowJointTrajectoryAction)
    assert client.wait_for_server(rospy.Duration(30))
    cases = [(_goal(rospy, [2.0, 1.0], [[0.1, 0.1], [0.2, 0.2]]), NOT_INCREASING),
             (_goal(rospy, [1.0, 1.0], [[0.1, 0.1], [0.2, 0.2]]), NOT_INCREASING),
             (_goal(rospy, [-1.0], [[0.1, 0.1]]), "time_from_start -1 s is negative"),
             (_goal(rospy, [1.0], [[1e30, 0.1]]), "position of l_elbow 1e+30 must be"),
             (_goal(rospy, [1.0], [[0.1, 0.1]], [[0.0]]), "has 1 velocities for 2 joints")]
    for goal, why in cases:
        client.send_goal(goal)
        assert client.wait_for_result(rospy.Duration(30))
        assert client.get_state() == actionlib.GoalStatus.REJECTED, why
        result = client.get_result()
        assert result.error_code == FollowJointTrajectoryResult.INVALID_GOAL
        assert why in result.error_string, result.error_string
    assert sim.heard("follow_joint_trajectory: goal rejected")
    client.send_goal(_goal(rospy, [0.5, 1.0], [[-0.2, -0.1], [-0.3, -0.2]]))  # a good one still works
    assert client.wait_for_result(rospy.Duration(60))
    assert client.get_state() == actionlib.GoalStatus.SUCCEEDED
    sim.assert_alive()


def test_a_malformed_trajectory_on_the_command_topic_is_dropped_with_a_warning(sim):
    """A point with fewer positions than joints raised IndexError in the simulation thread."""
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    rospy = sim.rospy
    pub = rospy.Publisher("/mex_rb/arm_controller/command", JointTrajectory, queue_size=10)
    deadline = time.time() + 30
    while pub.get_num_connections() == 0 and time.time() < deadline:
        time.sleep(0.05)
    msg = JointTrajectory(joint_names=["l_elbow", "l_shoulder_pitch"],
                          points=[JointTrajectoryPoint(positions=[0.3], time_from_start=rospy.Duration(1))])
    pub.publish(msg)
    assert sim.heard("has 1 positions for 2 joints")
    pub.unregister()
    sim.assert_alive()


def test_a_divergence_caused_by_a_service_call_resets_the_world_and_the_simulation_goes_on(sim):
    """A push inside the force range that still flings a 0.2 kg forearm beyond physics: the
    world is reset with a warning naming the call (not 'controller gains'), and the run goes on."""
    from gazebo_msgs.srv import ApplyBodyWrench
    from geometry_msgs.msg import Point, Wrench

    rospy = sim.rospy
    push = sim.service("/gazebo/apply_body_wrench", ApplyBodyWrench)
    wrench = Wrench()
    wrench.force.x = wrench.force.y = 9e5
    answer = push("mex_rb::l_forearm", "world", Point(), wrench, rospy.Time(0), rospy.Duration(0.2))
    assert answer.success, answer.status_message
    [warning] = sim.heard("the world was reset", timeout=60)
    assert "likely cause: the outside input /gazebo/apply_body_wrench (mex_rb::l_forearm" in warning
    assert "gains" not in warning
    sim.assert_alive()


# ----- in-process: the same handlers, one example per call -------------------------------------
class Harness:
    """A lab of its own in this process with the bridge's real GazeboNode, ControllerManagerNode
    and trajectory interfaces on it (under /fuzz_gazebo and /fuzz_rb): this thread is the
    simulation thread, so a call is a function call."""

    def __init__(self, rospy):
        from mexone.control.config import parse_control_config
        from mexone.lab import Lab
        from mexone.ros1.bridge import Ros1Bridge
        from mexone.ros1.controller_manager import ControllerManagerNode
        from mexone.ros1.gazebo import GazeboNode

        self.rospy = rospy
        self.lab = lab = Lab.create()
        bridge = Ros1Bridge.__new__(Ros1Bridge)  # the real call() and post(), without a node
        bridge.rospy, bridge.lab, bridge.gazebo_ns = rospy, lab, "/fuzz_gazebo"
        bridge.ready = threading.Event()
        bridge.ready.set()
        bridge._direct, bridge._owner = True, threading.current_thread()
        self.gazebo = GazeboNode(bridge)
        self.gazebo.attach()
        lab.sim.recover_outside = True  # as the bridge sets it
        manager = lab.manager
        import yaml

        manager.define(parse_control_config(yaml.safe_dump({"mex_rb": {"arm_controller": ARM}}))
                       .controllers["arm_controller"])
        manager.load("arm_controller")
        manager.switch(start=["arm_controller"], stop=["l_elbow_position_controller",
                                                       "l_shoulder_pitch_position_controller"])
        self.cm = ControllerManagerNode(bridge, manager, "/fuzz_rb")
        self.trajectory = self.cm.trajectories["arm_controller"]
        self.running = {n for n, c in manager.controllers.items() if c.running}
        from mexone.bus.msgs import JointState

        self.states: list = []  # what joint_state_controller publishes, as the bridge would see it
        lab.bus.subscribe("/mex_rb/joint_states", JointState, self.states.append, node="hostile test")

    def settle(self, seconds: float = 0.03) -> None:
        """Run the simulation on (its work queue too), then check it is alive and finite."""
        sim = self.lab.sim
        sim.target_rtf, sim.paused = None, False  # as fast as it goes
        published = len(self.states)
        sim.run(seconds)
        assert np.isfinite(sim.data.qpos).all() and np.isfinite(sim.data.qvel).all()
        assert len(self.states) > published, "joint_states stopped"
        assert np.isfinite(self.states[-1].position).all() and np.isfinite(self.states[-1].velocity).all()

    def restore(self) -> None:
        """The controllers that ran at the start run again, and only those."""
        manager = self.lab.manager
        running = {n for n, c in manager.controllers.items() if c.running}
        manager.switch(start=sorted(self.running - running), stop=sorted(running - self.running),
                       strictness=1)

    def close(self) -> None:
        for service in self.gazebo.services:
            service.shutdown()
        self.cm.shutdown()


@pytest.fixture(scope="module")
def harness(ros_master):
    rospy, _ = ros_master
    h = Harness(rospy)
    yield h
    h.close()


NUMBER = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                   st.sampled_from([0.0, 1.0, -1.0, 100.0, 1e4, 1e30, -1e30, 1e300, math.nan,
                                    math.inf, -math.inf, 5e-324]))
SMALL = st.floats(-2.0, 2.0)
NAMES = ["mex_rb", "mex_rb::l_forearm", "l_forearm", "pelvis", "l_elbow", "l_knee", "ground_plane",
         "", "world", "nope", "mex_rb::nope", "::", "a/b"]
NAME = st.sampled_from(NAMES)
JOINTS = ["l_elbow", "l_knee", "neck_yaw", "r_hip_pitch", "nope", ""]
INT32 = st.integers(-2**31, 2**31 - 1)


@st.composite
def fields(draw, n: int, valid=SMALL, size=None):
    """n numbers: all valid (a third of the examples), one of them hostile (a third), or any
    mix: so the handlers' success paths are exercised as well as their refusals. `size`: a
    strategy for a wrong length instead of n, sometimes."""
    if size is not None and draw(st.integers(0, 3)) == 0:
        n = draw(size)
    mode = draw(st.sampled_from(["valid", "one", "mix"]))
    values = [draw(valid) for _ in range(n)]
    if mode == "one" and n:
        values[draw(st.integers(0, n - 1))] = draw(NUMBER)
    elif mode == "mix":
        values = [draw(st.one_of(valid, NUMBER)) for _ in range(n)]
    return values


def mostly(valid: list, other: list):
    """One of `valid` four times in five, else one of `other`."""
    return st.sampled_from(valid * 4 * len(other) + other * len(valid))


def _point(x, y, z):
    from geometry_msgs.msg import Point

    return Point(x, y, z)


def _pose(values):
    from geometry_msgs.msg import Pose

    pose = Pose()
    (pose.position.x, pose.position.y, pose.position.z, pose.orientation.w, pose.orientation.x,
     pose.orientation.y, pose.orientation.z) = values
    return pose


def _twist(values):
    from geometry_msgs.msg import Twist

    twist = Twist()
    (twist.linear.x, twist.linear.y, twist.linear.z, twist.angular.x, twist.angular.y,
     twist.angular.z) = values
    return twist


def _answered(response) -> None:
    """A refusal says why in one line; a success says ok or what was clamped."""
    assert isinstance(response.status_message, str) and "\n" not in response.status_message
    assert response.success or response.status_message
    event("accepted" if response.success else "refused: " + response.status_message[:50])


@pytest.mark.fuzz
@fuzz(60)
@given(model=mostly(["mex_rb"], NAMES), data=st.data(),
       joints=st.lists(mostly(["l_elbow", "l_knee", "neck_yaw", "r_hip_pitch"], JOINTS), max_size=4))
def test_fuzz_set_model_configuration(harness, model, data, joints):
    from gazebo_msgs.srv import SetModelConfigurationRequest

    values = data.draw(fields(len(joints), st.floats(-3.0, 3.0), st.integers(0, 5)))

    answer = harness.gazebo._set_configuration(SetModelConfigurationRequest(model, "", joints, values))
    _answered(answer)
    if answer.success:
        assert len(joints) == len(values) and all(abs(v) <= 1e4 for v in values)
    harness.settle()


@pytest.mark.fuzz
@fuzz(60)
@given(name=mostly([None], NAMES), pose=fields(7), twist=fields(6),
       frame=mostly(["", "world"], NAMES), link=st.booleans())
def test_fuzz_set_model_and_link_state(harness, name, pose, twist, frame, link):
    from gazebo_msgs.msg import LinkState, ModelState
    from gazebo_msgs.srv import SetLinkStateRequest, SetModelStateRequest

    model = name if name is not None else ("mex_rb::pelvis" if link else "mex_rb")

    if link:
        answer = harness.gazebo._set_link_state(SetLinkStateRequest(
            LinkState(model, _pose(pose), _twist(twist), frame)))
    else:
        answer = harness.gazebo._set_model_state(SetModelStateRequest(
            ModelState(model, _pose(pose), _twist(twist), frame)))
    _answered(answer)
    if answer.success:
        assert all(abs(v) <= 1e4 for v in pose[:3]) and all(abs(v) <= 500 for v in twist)
    harness.settle()
    harness.lab.sim.reset()


@pytest.mark.fuzz
@fuzz(60)
@given(body=mostly(["mex_rb::l_forearm", "pelvis", "l_hand"], NAMES),
       frame=st.sampled_from(["", "world", "pelvis", "nope"]),
       values=fields(9, st.floats(-50.0, 50.0)),
       start=st.tuples(st.integers(0, 2**31 - 1), st.integers(0, 999_999_999)),
       duration=st.tuples(INT32, st.integers(0, 999_999_999)), effort=st.one_of(SMALL, NUMBER),
       joint=mostly(["l_elbow", "neck_yaw"], JOINTS))
def test_fuzz_wrenches_and_efforts(harness, body, frame, values, start, duration, effort, joint):
    from gazebo_msgs.srv import (
        ApplyBodyWrenchRequest,
        ApplyJointEffortRequest,
        BodyRequestRequest,
        JointRequestRequest,
    )
    from geometry_msgs.msg import Wrench

    rospy = harness.rospy
    wrench = Wrench(_point(*values[:3]), _point(*values[3:6]))
    begin, length = rospy.Time(*start), rospy.Duration(*duration)
    _answered(harness.gazebo._apply_body_wrench(ApplyBodyWrenchRequest(
        body, frame, _point(*values[6:]), wrench, begin, length)))
    _answered(harness.gazebo._apply_joint_effort(ApplyJointEffortRequest(joint, effort, begin, length)))
    harness.settle()
    harness.gazebo._clear_body_wrenches(BodyRequestRequest(body))
    harness.gazebo._clear_joint_forces(JointRequestRequest(joint))
    harness.lab.sim.reset()


@pytest.mark.fuzz
@fuzz(40)
@given(step=st.one_of(st.floats(1e-5, 0.01), NUMBER), rate=st.one_of(st.floats(0, 5000), NUMBER),
       gravity=fields(3, st.floats(-30, 30)), iterations=INT32)
def test_fuzz_set_physics_properties(harness, step, rate, gravity, iterations):
    from gazebo_msgs.msg import ODEPhysics
    from gazebo_msgs.srv import GetPhysicsPropertiesRequest, SetPhysicsPropertiesRequest
    from geometry_msgs.msg import Vector3

    sim = harness.lab.sim
    before = (sim.timestep, tuple(sim.gravity))
    answer = harness.gazebo._set_physics(SetPhysicsPropertiesRequest(
        step, rate, Vector3(*gravity), ODEPhysics(sor_pgs_iters=iterations)))
    _answered(answer)
    if not answer.success:  # a refused change changes nothing
        assert (sim.timestep, tuple(sim.gravity)) == before
    now = harness.gazebo._get_physics(GetPhysicsPropertiesRequest())
    assert now.success and math.isfinite(now.time_step) and math.isfinite(now.max_update_rate)
    harness.settle()
    harness.gazebo._set_physics(SetPhysicsPropertiesRequest(0.001, 0.0, Vector3(0, 0, -9.81),
                                                            ODEPhysics(sor_pgs_iters=50)))
    sim.reset()


@pytest.mark.fuzz
@fuzz(20)
@given(name=mostly(["box", "box2"], ["", "mex_rb", "a/b"]), pose=fields(7, st.floats(-3.0, 3.0)),
       xml=mostly([BOX, ARM_BOT], ["", "<robot", "<robot name='x'/>"]),
       sdf=st.booleans(), namespace=st.sampled_from(["", "bot", "a b", "/../x", "mex_rb", "/fuzz_bot"]))
def test_fuzz_spawn_and_delete(harness, name, pose, xml, sdf, namespace):
    """A box, or a robot with a transmission (it gets a controller manager of its own)."""
    from gazebo_msgs.srv import DeleteModelRequest, SpawnModelRequest

    spawn = harness.gazebo._spawn(".sdf" if sdf else ".urdf")
    if sdf:
        xml = {BOX: SDF_BOX, ARM_BOT: SDF_BOX}.get(xml, xml)
    answer = spawn(SpawnModelRequest(name, xml, namespace, _pose(pose), "world"))
    _answered(answer)
    if answer.success:
        assert all(abs(v) <= 1e4 for v in pose[:3]), pose
    harness.settle()
    harness.gazebo._delete_model(DeleteModelRequest(name))
    assert not harness.lab.sim.models and not harness.gazebo.managers
    harness.lab.sim.reset()


@pytest.mark.fuzz
@fuzz(30)
@given(name=NAME, link=NAME, reference=NAME)
def test_fuzz_getters_never_fail_to_answer(harness, name, link, reference):
    from gazebo_msgs.srv import (
        GetLinkStateRequest,
        GetModelPropertiesRequest,
        GetModelStateRequest,
        GetWorldPropertiesRequest,
    )

    g = harness.gazebo
    for answer in (g._get_model_state(GetModelStateRequest(name, reference)),
                   g._get_link_state(GetLinkStateRequest(link, reference)),
                   g._model_properties(GetModelPropertiesRequest(name)),
                   g._world_properties(GetWorldPropertiesRequest())):
        _answered(answer)
        if hasattr(answer, "pose") and answer.success:
            assert np.isfinite([answer.pose.position.x, answer.pose.position.y,
                                answer.pose.position.z]).all()


CONTROLLERS = st.sampled_from(["neck_yaw_position_controller", "arm_controller", "nope", "",
                               "joint_state_controller", "l_elbow_position_controller"])


@pytest.mark.fuzz
@fuzz(50)
@given(start=st.lists(CONTROLLERS, max_size=3), stop=st.lists(CONTROLLERS, max_size=3),
       strictness=st.one_of(INT32, st.sampled_from([0, 1, 2, 99])), timeout=NUMBER,
       load=CONTROLLERS)
def test_fuzz_controller_manager_services(harness, start, stop, strictness, timeout, load):
    from controller_manager_msgs.srv import (
        ListControllersRequest,
        LoadControllerRequest,
        ReloadControllerLibrariesRequest,
        SwitchControllerRequest,
        UnloadControllerRequest,
    )

    cm = harness.cm
    ok = cm._switch(SwitchControllerRequest(start, stop, strictness, False, timeout)).ok
    if ok:
        assert strictness in (0, 1, 2) and 0 <= timeout <= 1e6
    cm._load(LoadControllerRequest(load))
    assert not cm._reload(ReloadControllerLibrariesRequest(False)).ok  # controllers are loaded
    assert cm._list(ListControllersRequest()).controller
    if load not in harness.lab.manager.controllers:
        assert not cm._unload(UnloadControllerRequest(load)).ok
    harness.restore()
    harness.settle()


@pytest.mark.fuzz
@fuzz(40)
@given(values=st.fixed_dictionaries({k: st.one_of(NUMBER, st.floats(0, 100))
                                     for k in ("p", "i", "d", "i_clamp_min", "i_clamp_max")}))
def test_fuzz_dynamic_reconfigure_gains(harness, values):
    server = harness.cm.extras["neck_yaw_position_controller"][0]
    manager = harness.lab.manager
    server.update_configuration(dict(values))
    [gains] = manager.controllers["neck_yaw_position_controller"].gains
    for key in ("p", "i", "d", "i_clamp_min", "i_clamp_max"):
        assert math.isfinite(getattr(gains, key)) and abs(getattr(gains, key)) <= 1e5
    harness.settle()


class _Handle:
    """actionlib's ServerGoalHandle as TrajectoryInterfaces uses it."""

    def __init__(self, goal):
        self.goal, self.status, self.result = goal, "pending", None

    def get_goal(self):
        return self.goal

    def set_accepted(self, _text=""):
        self.status = "accepted"

    def _end(self, status):
        def end(result=None, _text=""):
            self.status, self.result = status, result
        return end

    def __getattr__(self, name):
        ends = {"set_rejected": "rejected", "set_succeeded": "succeeded", "set_aborted": "aborted",
                "set_canceled": "canceled"}
        if name in ends:
            return self._end(ends[name])
        if name == "publish_feedback":
            return lambda _fb: None
        raise AttributeError(name)


def _valid(times, positions, velocities, names) -> bool:
    if sorted(names) != ["l_elbow", "l_shoulder_pitch"]:
        return True  # INVALID_JOINTS, checked apart
    return (all(t >= 0 for t in times) and all(b > a for a, b in zip(times, times[1:], strict=False))
            and all(len(p) == 2 and all(abs(x) <= 1e4 for x in p) for p in positions)
            and all(not v or (len(v) == 2 and all(abs(x) <= 1e4 for x in v)) for v in velocities))


@pytest.mark.fuzz
@fuzz(60)
@given(points=st.lists(st.tuples(st.integers(-3, 3).map(lambda k: k * 0.25),
                                 st.lists(st.one_of(SMALL, NUMBER), max_size=3),
                                 st.lists(st.one_of(SMALL, NUMBER), max_size=3)), max_size=4),
       names=st.sampled_from([["l_elbow", "l_shoulder_pitch"], ["l_shoulder_pitch", "l_elbow"],
                              ["l_elbow"], ["l_elbow", "l_elbow"], ["nope", "l_elbow"]]))
def test_fuzz_follow_joint_trajectory_goals(harness, points, names):
    from control_msgs.msg import FollowJointTrajectoryGoal
    from trajectory_msgs.msg import JointTrajectoryPoint

    rospy = harness.rospy
    goal = FollowJointTrajectoryGoal()
    goal.trajectory.joint_names = names
    goal.trajectory.points = [JointTrajectoryPoint(positions=p, velocities=v,
                                                   time_from_start=rospy.Duration(t))
                              for t, p, v in points]
    handle = _Handle(goal)
    harness.trajectory._goal(handle)
    harness.lab.sim.work.drain()
    times = [t for t, _, _ in points]
    good = bool(points) and _valid(times, [p for _, p, _ in points], [v for _, _, v in points], names)
    if sorted(names) != ["l_elbow", "l_shoulder_pitch"]:
        assert handle.status == "rejected" and handle.result.error_code == -2
    elif good:
        assert handle.status == "accepted", handle.result
    else:
        assert handle.status == "rejected" and handle.result.error_code == -1, handle.status
        assert handle.result.error_string
    harness.settle()
    harness.trajectory.controller.cancel(harness.lab.sim.time)


@pytest.mark.fuzz
@fuzz(60)
@given(points=st.lists(st.tuples(st.integers(-3, 3).map(lambda k: k * 0.25), fields(2, size=st.integers(0, 3)),
                                 fields(2, size=st.integers(0, 3))), max_size=3),
       names=st.sampled_from([["l_elbow", "l_shoulder_pitch"], ["l_elbow"], ["l_elbow", "l_elbow"]]),
       command=st.one_of(SMALL, NUMBER))
def test_fuzz_command_topics(harness, points, names, command):
    """What rostopic pub can send to the command topics, as the bridge relays it (converted, then
    published on the bus in the simulation thread): dropped with a warning or clamped, never a
    crash."""
    from std_msgs.msg import Float64
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    from mexone.ros1 import convert

    rospy = harness.rospy
    trajectory = JointTrajectory(joint_names=names, points=[
        JointTrajectoryPoint(positions=p, velocities=v, time_from_start=rospy.Duration(t))
        for t, p, v in points])
    bus = harness.lab.bus
    bus.publish("/mex_rb/arm_controller/command", convert.from_ros(trajectory))
    bus.publish("/mex_rb/neck_yaw_position_controller/command", convert.from_ros(Float64(command)))
    harness.settle()
    [neck] = harness.lab.manager.controllers["neck_yaw_position_controller"].setpoint
    assert -1.2 <= neck <= 1.2  # within its limits whatever was sent


def test_nan_and_huge_commands_on_a_topic_are_dropped_or_clamped(sim):
    for value in (".nan", "1.0e+300", "-.inf"):
        out = subprocess.run(["rostopic", "pub", "-1", "/mex_rb/neck_pitch_position_controller/command",
                              "std_msgs/Float64", f"data: {value}"], env=ros_env(sim.port),
                             capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stderr
    assert sim.heard("neck_pitch_position_controller: command (NaN) is not finite; ignored")
    assert sim.heard("clamped: neck_pitch 1e+300 -> 0.8")
    sim.assert_alive()
