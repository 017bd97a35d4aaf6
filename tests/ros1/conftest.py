"""One roscore and one in-process rospy node for the whole ROS 1 session: rospy initialises once
per process and keeps the master it first met, so modules cannot each bring their own master.
Tests that need a master of their own (killing it, a fresh parameter server) start one and
talk to it only through subprocesses."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_bridge import ROSCORE, free_port, ros_env, start_roscore, stop  # noqa: E402


@pytest.fixture(scope="session")
def ros_master():
    """(rospy, port) of the session's master, rospy initialised against it (sim time)."""
    if not Path(ROSCORE).exists():
        pytest.skip("Debian ROS 1 is not installed (ros-core, python3-rospy)")
    port = free_port()
    os.environ.update(ros_env(port))
    core = start_roscore(port)
    # as gazebo_ros' empty_world.launch: sim time for every node, this test process included
    subprocess.run(["rosparam", "set", "/use_sim_time", "true"], env=ros_env(port), check=True,
                   timeout=60, capture_output=True)
    from mexone.ros1.bridge import import_rospy

    rospy = import_rospy()
    deadline = time.time() + 60
    while time.time() < deadline and not rospy.core.is_initialized():
        try:
            rospy.init_node("mexone_test", disable_signals=True)
        except Exception:
            time.sleep(0.5)
    yield rospy, port
    stop(core)
