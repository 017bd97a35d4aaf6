"""A student's Python controller on ROS: listed by controller_manager, its declared parameters
served by dynamic_reconfigure at /<ns>/<controller> (what `dynparam` and rqt_reconfigure use),
each change checked by the same Param as the YAML (a NaN, which passes dynamic_reconfigure's own
min/max comparisons, is refused and the value kept)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_bridge import ros_env, stop  # noqa: E402

from mexone.control.skeleton import skeleton_files  # noqa: E402

pytestmark = pytest.mark.slow
NAME = "/mex_rb/my_pd_controller"


@pytest.fixture(scope="module")
def ros(ros_master, tmp_path_factory):
    rospy, port = ros_master
    folder = tmp_path_factory.mktemp("ros_ctl")
    for file, text in skeleton_files("my_pd").items():
        (folder / file).write_text(text)
    sim = subprocess.Popen([sys.executable, "-m", "mexone", "sim", "--ros", "--headless", "--rtf",
                            "1", "--controllers", str(folder / "controllers.yaml")],
                           env=ros_env(port), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True, start_new_session=True)
    from sensor_msgs.msg import JointState

    rospy.wait_for_message("/mex_rb/joint_states", JointState, timeout=60)
    yield rospy, port
    stop(sim)


def test_listed_and_its_params_reconfigured(ros):
    rospy, port = ros
    from controller_manager_msgs.srv import ListControllers
    from dynamic_reconfigure.client import Client

    rospy.wait_for_service("/mex_rb/controller_manager/list_controllers", timeout=30)
    listed = rospy.ServiceProxy("/mex_rb/controller_manager/list_controllers", ListControllers)()
    mine = next(c for c in listed.controller if c.name == "my_pd_controller")
    assert mine.type == "my_pd/MyPd" and mine.state == "running"
    assert mine.claimed_resources[0].hardware_interface == "hardware_interface::EffortJointInterface"
    client = Client(NAME, timeout=30)  # what dynparam and rqt_reconfigure use
    try:
        got = client.get_configuration(timeout=30)
        assert got["kp"] == 20.0 and got["kd"] == 1.0 and got["gravity_compensation"] is False
        assert client.update_configuration({"kp": 30.0})["kp"] == 30.0
        assert client.update_configuration({"kp": float("nan")})["kp"] == 30.0  # refused: kept
        assert client.update_configuration({"kd": 1e9})["kd"] == 1000.0  # its max, as declared
    finally:
        client.close()
