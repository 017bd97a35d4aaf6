"""mexone as a node in a real ROS 1 graph: Debian's roscore, rostopic, robot_state_publisher,
rospy and tf2_ros against `mexone sim --ros`."""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import time
import xmlrpc.client
from pathlib import Path

import mujoco
import numpy as np
import pytest

from helpers import wait_until
from mexone.robots import mex_one

ROSCORE = "/usr/bin/roscore"
RSP = "/usr/lib/robot_state_publisher/robot_state_publisher"
SCRIPTS = mex_one.package_dir() / "scripts"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def ros_env(port: int) -> dict:
    """The environment of a ROS user after `eval "$(mexone ros-env)"` (the spawner, the message
    packages and mex_rb found; tests/cli/test_ros_env.py holds the command to this function)."""
    from mexone.ros1 import interfaces

    return interfaces.environment(dict(
        os.environ, ROS_MASTER_URI=f"http://127.0.0.1:{port}", ROS_HOSTNAME="127.0.0.1",
        ROS_LOG_DIR=str(Path("/tmp") / f"mexone-roslog-{port}")))


class _Timeout(xmlrpc.client.Transport):
    """An XML-RPC transport whose calls give up after 5 s (the standard one waits for ever)."""

    def make_connection(self, host):
        connection = super().make_connection(host)
        connection.timeout = 5.0
        return connection


def master_ready(port: int) -> bool:
    """The master on `port` answers and roscore's /rosout node has joined it (subscribes to
    /rosout): what a fixed second's wait after the port opened stood for."""
    master = xmlrpc.client.ServerProxy(f"http://127.0.0.1:{port}/", transport=_Timeout())
    try:
        code, _, (_, subscribers, _) = master.getSystemState("/mexone_test_start")
    except (OSError, xmlrpc.client.Error, ValueError):
        return False
    return code == 1 and any(topic == "/rosout" and "/rosout" in nodes
                             for topic, nodes in subscribers)


def start_roscore(port: int) -> subprocess.Popen:
    proc = subprocess.Popen([ROSCORE, "-p", str(port)], env=ros_env(port),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    deadline = time.time() + 30
    while time.time() < deadline and proc.poll() is None:
        if master_ready(port):
            return proc
        time.sleep(0.1)  # polling a master that is not up yet: nothing to wait on
    stop(proc)
    raise RuntimeError("roscore did not start")


def stop(proc: subprocess.Popen, sig=signal.SIGINT) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, sig)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)


def start_mexone(port: int, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "mexone", "sim", "--ros", "--headless",
                             "--rtf", "1", *extra], env=ros_env(port), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)


@pytest.fixture(scope="module")
def ros(ros_master):
    rospy, port = ros_master
    sim = start_mexone(port)
    from sensor_msgs.msg import JointState

    rospy.wait_for_message("/mex_rb/joint_states", JointState, timeout=60)
    yield rospy, port, sim
    stop(sim)


def joint_states(rospy, timeout=5.0):
    from sensor_msgs.msg import JointState

    msg = rospy.wait_for_message("/mex_rb/joint_states", JointState, timeout=timeout)
    return msg, dict(zip(msg.name, msg.position, strict=True))


def test_rostopic_pub_moves_the_joint_within_2s_of_sim_time(ros):
    rospy, port, _ = ros
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64

    topic = "/mex_rb/waist_yaw_position_controller/command"
    heard: list[float] = []  # the sim time the command arrived at (this process: /clock)
    reached: list[float] = []  # the stamp of the first joint state at the command, after it

    def state(msg) -> None:
        if heard and not reached and abs(dict(zip(msg.name, msg.position, strict=True))
                                         ["waist_yaw"] - 0.5) < 0.01:
            reached.append(msg.header.stamp.to_sec())

    start, _ = joint_states(rospy)
    subs = [rospy.Subscriber(topic, Float64, lambda _: heard.append(rospy.get_time())),
            rospy.Subscriber("/mex_rb/joint_states", JointState, state)]
    try:
        out = subprocess.run(["rostopic", "pub", "-1", topic, "std_msgs/Float64", "data: 0.5"],
                             env=ros_env(port), capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stderr
        assert wait_until(lambda: heard, timeout=30), "the command never arrived"
        assert wait_until(lambda: reached, timeout=30), "the joint never reached the command"
    finally:
        for sub in subs:
            sub.unregister()
    print(f"reached {reached[0] - heard[0]:.2f} s of sim time after the command arrived, "
          f"{reached[0] - start.header.stamp.to_sec():.2f} s after rostopic started")
    # counted from the command's arrival, not from rostopic's start (Python and rospy's imports:
    # seconds of wall time, so of sim time at --rtf 1, more on a slower or stalled machine)
    assert reached[0] - heard[0] < 2.0
    # settled exactly, read back by a rospy subscriber
    _, q = joint_states(rospy)
    assert q["waist_yaw"] == pytest.approx(0.5, abs=0.01)


def test_a_rospy_sweep_node_follows_sim_time(ros):
    rospy, port, _ = ros
    from std_msgs.msg import Float64

    topic = "/mex_rb/l_shoulder_pitch_position_controller/command"
    heard: list[tuple[float, float]] = []
    sub = rospy.Subscriber(topic, Float64, lambda m: heard.append((rospy.get_time(), m.data)))
    node = subprocess.Popen(["/usr/bin/python3", str(SCRIPTS / "joint_steps_node.py")],
                            env=ros_env(port), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.time() + 60
        while len(heard) < 25 and time.time() < deadline:
            time.sleep(0.2)
        _, q = joint_states(rospy)
    finally:
        stop(node)
        sub.unregister()
    steps = np.diff([t for t, _ in heard[2:25]])  # this process runs on sim time (conftest)
    assert np.median(steps) == pytest.approx(0.1, abs=0.005)  # Rate(10) in sim time
    assert min(v for _, v in heard) < -1.0 and q["l_shoulder_pitch"] < -0.5


def test_robot_state_publisher_tf_matches_the_simulator(ros):
    rospy, port, _ = ros
    import tf2_ros
    from sensor_msgs.msg import JointState
    from std_srvs.srv import Empty

    rsp = subprocess.Popen([RSP, "joint_states:=/mex_rb/joint_states"], env=ros_env(port),
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                           start_new_session=True)
    latest: list = []
    sub = rospy.Subscriber("/mex_rb/joint_states", JointState, latest.append)
    try:
        buffer = tf2_ros.Buffer()
        tf2_ros.TransformListener(buffer)
        time.sleep(3.0)
        rospy.ServiceProxy("/gazebo/pause_physics", Empty)()
        time.sleep(1.0)  # the robot stands still; the last joint state is the frozen one
        q = dict(zip(latest[-1].name, latest[-1].position, strict=True))
        frames = {}
        for link in ("l_foot", "r_foot", "head", "l_forearm"):
            tf = buffer.lookup_transform("world", link, rospy.Time(0), rospy.Duration(10.0))
            frames[link] = tf.transform
        base = buffer.lookup_transform("world", "pelvis", rospy.Time(0), rospy.Duration(10.0))
    finally:
        sub.unregister()
        rospy.ServiceProxy("/gazebo/unpause_physics", Empty)()
        stop(rsp)
    # the simulator's own kinematics for the same joint angles and base pose
    from mexone.physics import Simulation

    sim = Simulation(mex_one.urdf_path())
    tr, rot = base.transform.translation, base.transform.rotation
    sim.data.qpos[:7] = [tr.x, tr.y, tr.z, rot.w, rot.x, rot.y, rot.z]
    sim.set_joint_positions(q)
    mujoco.mj_kinematics(sim.model, sim.data)
    assert len(frames) == 4
    for link, transform in frames.items():
        pos, _ = sim.link_pose(link)
        t = transform.translation
        assert np.linalg.norm(pos - [t.x, t.y, t.z]) < 1e-3, link


def test_gazebo_services_pause_unpause_reset(ros):
    rospy, port, _ = ros
    from rosgraph_msgs.msg import Clock
    from std_srvs.srv import Empty

    clocks: list[float] = []
    sub = rospy.Subscriber("/clock", Clock, lambda m: clocks.append(m.clock.to_sec()))
    try:
        time.sleep(1.0)
        rospy.ServiceProxy("/gazebo/pause_physics", Empty)()
        time.sleep(0.5)
        frozen = clocks[-1]
        time.sleep(1.0)
        assert clocks[-1] == frozen  # /clock stopped
        rospy.ServiceProxy("/gazebo/unpause_physics", Empty)()
        time.sleep(1.0)
        assert clocks[-1] > frozen + 0.5
        subprocess.run(["rostopic", "pub", "-1", "/mex_rb/neck_yaw_position_controller/command",
                        "std_msgs/Float64", "data: 0.8"], env=ros_env(port), timeout=60,
                       capture_output=True)
        time.sleep(2.0)
        rospy.ServiceProxy("/gazebo/reset_simulation", Empty)()
        time.sleep(0.5)
        _, q = joint_states(rospy)
        assert abs(q["neck_yaw"]) < 0.02 and max(abs(v) for v in q.values()) < 0.02
    finally:
        sub.unregister()


def test_killing_roscore_keeps_the_simulator_and_its_recording(tmp_path):
    if not Path(ROSCORE).exists():
        pytest.skip("Debian ROS 1 is not installed")
    port = free_port()
    core = start_roscore(port)
    bag = tmp_path / "through.mcap"
    sim = start_mexone(port, "--record", str(bag))
    try:
        for line in sim.stderr:  # on the graph (joining takes seconds on a busy machine)
            if "is on ROS at" in line:
                break
        time.sleep(5.0)
        stop(core)  # the master goes away mid-run
        time.sleep(3.0)
        assert sim.poll() is None, sim.stderr.read()
    finally:
        stop(sim)
    assert sim.returncode == 130  # Ctrl-C ends it as every verb: 128 + SIGINT, the bag closed
    err = sim.stderr.read()
    assert "master" in err and "is gone" in err and "Traceback" not in err
    gone = float(re.search(r"is gone at sim time ([0-9.]+) s", err).group(1))
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        last = max(stamp for _, stamp, _ in reader.messages()) * 1e-9
    assert counts["/mex_rb/joint_states"] > 200 and last > gone + 1.0  # recorded past the kill


def test_without_ros_the_error_says_what_to_install():
    code = ("import mexone.ros1.bridge as r, sys; r._DEBIAN_SITE = '/nonexistent'; "
            "sys.modules.pop('rospy', None); sys.path[:] = [p for p in sys.path "
            "if 'dist-packages' not in p]; r.import_rospy()")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert "ROS 1 (rospy) is not installed" in out.stderr
    assert "apt-get install ros-core python3-rospy" in out.stderr


def _subscribers(port: int, topic: str) -> list[str]:
    from mexone.ros1.bridge import import_rospy

    import_rospy()  # puts Debian's ROS packages (rosgraph among them) on the path
    import rosgraph

    master = rosgraph.Master("/mexone_test_probe", master_uri=f"http://127.0.0.1:{port}")
    _, subs, _ = master.getSystemState()
    return next((nodes for name, nodes in subs if name == topic), [])


def test_controllers_come_from_the_parameter_server_after_rosparam_load(tmp_path):
    """The seed's flow: `rosparam load` the YAML, then the simulator reads it from there; as
    ros_control does, they load stopped (alternatives for one joint no longer end the sim) and
    the spawner starts the ones it names."""
    port = free_port()
    core = start_roscore(port)
    yaml_file = tmp_path / "configuration.yaml"
    yaml_file.write_text("""mex_rb:
  joint_state_controller: {type: joint_state_controller/JointStateController, publish_rate: 50}
  waist_yaw_position_controller:
    type: effort_controllers/JointPositionController
    joint: waist_yaw
    pid: {p: 150.0, d: 1.5}
  waist_yaw_effort_controller: {type: effort_controllers/JointEffortController, joint: waist_yaw}
""")
    subprocess.run(["rosparam", "load", str(yaml_file)], env=ros_env(port), check=True, timeout=60)
    sim = start_mexone(port)
    topic = "/mex_rb/waist_yaw_position_controller/command"
    try:
        out = subprocess.run(["rosservice", "call", "--wait", "/mex_rb/controller_manager/list_controllers"],
                             env=ros_env(port), capture_output=True, text=True, timeout=90)
        assert out.stdout.count('state: "stopped"') == 3, out.stdout + out.stderr
        assert _subscribers(port, topic) == []
        switch = subprocess.run(
            ["rosservice", "call", "/mex_rb/controller_manager/switch_controller",
             "{start_controllers: [joint_state_controller, waist_yaw_position_controller], "
             "stop_controllers: [], strictness: 2}"], env=ros_env(port), capture_output=True,
            text=True, timeout=60)
        assert "ok: True" in switch.stdout, switch.stdout + switch.stderr
        deadline = time.time() + 30
        while time.time() < deadline and not _subscribers(port, topic):
            time.sleep(0.2)
        assert _subscribers(port, topic) == ["/mexone"]
        assert _subscribers(port, "/mex_rb/l_elbow_position_controller/command") == []
        use_sim_time = subprocess.run(["rosparam", "get", "/use_sim_time"], env=ros_env(port),
                                      capture_output=True, text=True, timeout=60)
        assert use_sim_time.stdout.strip() == "true"  # set by the simulator, as gazebo_ros' launch
        assert sim.poll() is None
    finally:
        stop(sim)
        stop(core)


def test_the_seed_launch_files(tmp_path):
    """roslaunch model.launch (the simulator) and control.launch (parameters, the spawner,
    robot_state_publisher, the arms routine's node), as the seed's chapters 3 and 4 ran them:
    both shoulders, both elbows and the neck reach the routine's 30 degrees."""
    port = free_port()
    core = start_roscore(port)
    env = ros_env(port)  # mex_rb found as `mexone ros-env` puts it on ROS_PACKAGE_PATH
    model = subprocess.Popen(["roslaunch", "--wait", "mex_rb", "model.launch", "headless:=true"],
                             env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                             start_new_session=True)
    control = None
    try:
        deadline = time.time() + 90  # as in the seed: the model first, then the control files
        while time.time() < deadline and not _subscribers(port, "/mex_rb/waist_yaw_position_controller/command"):
            time.sleep(0.5)
        control = subprocess.Popen(["roslaunch", "--wait", "mex_rb", "control.launch",
                                    "routine:=arms_node.py"], env=env,
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                   start_new_session=True)
        code = ("import rospy, sys; from sensor_msgs.msg import JointState; "
                "rospy.init_node('probe'); import time; t = time.time()\n"
                "while time.time() - t < 90:\n"
                "    m = rospy.wait_for_message('/mex_rb/joint_states', JointState, timeout=60)\n"
                "    q = dict(zip(m.name, m.position))\n"
                "    if q['l_shoulder_pitch'] < -0.45 and q['r_elbow'] < -0.45 and q['neck_yaw'] > 0.45:\n"
                "        print('moved'); sys.exit(0)\n"
                "sys.exit(1)")
        probe = subprocess.run(["/usr/bin/python3", "-c", code], env=env, capture_output=True,
                               text=True, timeout=150)
        assert probe.returncode == 0 and "moved" in probe.stdout, probe.stderr[-2000:]
        assert _subscribers(port, "/mex_rb/joint_states")  # robot_state_publisher listens
    finally:
        if control is not None:
            stop(control)
        stop(model)
        stop(core)
