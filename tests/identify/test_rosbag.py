"""A .bag written by Debian's own `rosbag record` (not by mexone) of a `mexone sim --ros` run is
accepted by `mexone identify`: wall-clock bag times, sim-time header stamps, commands published
by a rospy node with no header at all."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "ros1"))
from test_bridge import ROSCORE, free_port, ros_env, start_mexone, start_roscore, stop  # noqa: E402

ROSBAG = "/usr/bin/rosbag"
NS = "/mex_rb"
COMMAND = f"{NS}/l_elbow_position_controller/command"
PUBLISHER = f"""
import math, time
from mexone.ros1.bridge import import_rospy
rospy = import_rospy()
from std_msgs.msg import Float64
rospy.init_node("elbow_exciter", disable_signals=True)
pub = rospy.Publisher("{COMMAND}", Float64, queue_size=10)
time.sleep(1.0)  # let rosbag and the simulator connect
start = time.monotonic()
while time.monotonic() - start < 8.0:
    t = time.monotonic() - start
    pub.publish(Float64(-0.6 + 0.4 * math.sin(2 * math.pi * 0.7 * t) * min(t, 1.0)))
    time.sleep(0.01)
"""


@pytest.mark.slow
def test_a_bag_from_debian_rosbag_record_is_accepted(tmp_path):
    if not (Path(ROSCORE).exists() and Path(ROSBAG).exists()):
        pytest.skip("Debian ROS 1 is not installed (ros-core, python3-rosbag)")
    port = free_port()
    env = ros_env(port)
    core = start_roscore(port)
    sim = bag_proc = None
    bag = tmp_path / "robot.bag"
    try:
        sim = start_mexone(port, "--duration", "60")
        deadline = time.time() + 60
        while time.time() < deadline:  # the simulator's topics are up
            out = subprocess.run(["rostopic", "list"], env=env, capture_output=True, text=True)
            if f"{NS}/joint_states" in out.stdout:
                break
            time.sleep(0.5)
        bag_proc = subprocess.Popen([ROSBAG, "record", "-O", str(bag), f"{NS}/joint_states",
                                     COMMAND, "/tf"], env=env, cwd=tmp_path,
                                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                    start_new_session=True)
        publisher = subprocess.run([sys.executable, "-c", PUBLISHER], env=env, timeout=60,
                                   capture_output=True, text=True)
        assert publisher.returncode == 0, publisher.stderr
        time.sleep(0.5)
    finally:
        if bag_proc is not None:
            stop(bag_proc, signal.SIGINT)
        if sim is not None:
            stop(sim)
        stop(core)
    assert bag.exists(), os.listdir(tmp_path)
    out = subprocess.run([sys.executable, "-m", "mexone", "identify", str(bag), "--joints",
                          "l_elbow", "--params", "damping", "--max-iterations", "3",
                          "-o", str(tmp_path / "out"), "--json"], capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert set(report["params"]["damping"]) == {"l_elbow"}
    # rosbag stamps what it receives with its own ROS time, from /clock: the commands' times
    # are off by up to ~0.2 s from when the simulator applied them (more under load), which the
    # fitted delay takes up
    assert report["rms_after"] < report["rms_before"], report
    assert abs(report["delay"]["robot.bag"]) <= 0.25
