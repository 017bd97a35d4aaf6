"""`eval "$(mexone ros-env)"` in a real shell gives ROS's own tools mexone's packages: rospack
finds mex_rb, rosmsg the message definitions, Debian's python3 their generated classes,
roslaunch the routine nodes (executable) of control.launch."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import mexone
from mexone.robots import mex_one
from mexone.ros1 import interfaces

pytestmark = pytest.mark.skipif(shutil.which("roslaunch") is None or shutil.which("rosmsg") is None,
                                reason="Debian ROS 1 is not installed (ros-core)")

MEXONE = f"{sys.executable} -m mexone"  # this checkout's mexone, as PYTHONPATH says


def _shell(script: str, **env: str) -> str:
    base = {k: v for k, v in os.environ.items() if k not in ("ROS_PACKAGE_PATH", "PYTHONPATH")}
    base["PYTHONPATH"] = str(Path(mexone.__file__).parents[1])  # this checkout's src/ only
    out = subprocess.run(["bash", "-c", script], env={**base, **env}, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_eval_appends_once_and_keeps_what_was_there(tmp_path):
    odd = tmp_path / "a b$c'd"  # quoting: spaces, $ and quotes survive eval
    odd.mkdir()
    script = (f'eval "$({MEXONE} ros-env)"; eval "$({MEXONE} ros-env)"; '
              'printf "%s\\n%s\\n" "$ROS_PACKAGE_PATH" "$PYTHONPATH"')
    ros_path, py_path = _shell(script, ROS_PACKAGE_PATH=f"{odd}:/usr/share:/usr/share",
                               PYTHONPATH=f"{Path(mexone.__file__).parents[1]}:").splitlines()
    robots = str(mex_one.package_dir().parent)
    # what was there stays as it was (even a duplicate, even an empty entry: the cwd)
    assert ros_path.split(":") == [str(odd), "/usr/share", "/usr/share", str(interfaces.SHARE), robots]
    assert py_path.split(":") == [str(Path(mexone.__file__).parents[1]), "", str(interfaces.generated())]
    # the tests' ros_env() builds the same paths (interfaces.environment)
    expected = interfaces.environment({"ROS_PACKAGE_PATH": f"{odd}:/usr/share:/usr/share"})
    assert ros_path == expected["ROS_PACKAGE_PATH"]


def test_ros_tools_find_mexones_packages_after_eval():
    script = (f'eval "$({MEXONE} ros-env)" && rospack find mex_rb && '
              'rosmsg md5 control_msgs/JointControllerState && '
              '/usr/bin/python3 -c "from gazebo_msgs.srv import SpawnModel; print(SpawnModel._md5sum)" && '
              'roslaunch --args /routine mex_rb control.launch routine:=arms_node.py')
    lines = _shell(script).splitlines()
    assert lines[0] == str(mex_one.package_dir())
    # the official definitions' md5sums (ros_control, gazebo_ros_pkgs; see test_interfaces.py)
    assert lines[1] == "987ad85e4756f3aef7f1e5e7fe0595d1"
    assert lines[2] == "9ed9c82c96abe1a00c3e8cdaeee24413"
    assert lines[3].endswith(f"{mex_one.package_dir()}/scripts/arms_node.py __name:=routine")
