"""A roscpp client built the ROS way against mexone's controller_manager_msgs: C++ headers made by
Debian's gencpp from mexone/ros1/share, compiled with g++ against Debian's roscpp, calling
switch_controller on a running `mexone sim --ros`. Interoperating at all proves the md5sums."""

from __future__ import annotations

import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mexone.ros1 import interfaces

sys.path.insert(0, str(Path(__file__).parent))
from test_bridge import ROSCORE, free_port, ros_env, start_mexone, start_roscore, stop  # noqa: E402

GEN_CPP = Path("/usr/lib/gencpp/gen_cpp.py")
TEMPLATES = Path("/usr/share/gencpp")

CLIENT = r"""
#include <ros/ros.h>
#include <controller_manager_msgs/SwitchController.h>
#include <controller_manager_msgs/ListControllers.h>

int main(int argc, char** argv) {
  ros::init(argc, argv, "cpp_switch_client");
  ros::NodeHandle n;
  auto sw = n.serviceClient<controller_manager_msgs::SwitchController>(
      "/mex_rb/controller_manager/switch_controller");
  auto ls = n.serviceClient<controller_manager_msgs::ListControllers>(
      "/mex_rb/controller_manager/list_controllers");
  if (!sw.waitForExistence(ros::Duration(60))) return 3;
  controller_manager_msgs::SwitchController call;
  call.request.stop_controllers.push_back("l_elbow_position_controller");
  call.request.strictness = controller_manager_msgs::SwitchController::Request::STRICT;
  if (!sw.call(call) || !call.response.ok) return 4;
  controller_manager_msgs::ListControllers list;
  if (!ls.call(list)) return 5;
  for (const auto& c : list.response.controller)
    if (c.name == "l_elbow_position_controller") std::cout << c.name << " " << c.state << std::endl;
  call.request.stop_controllers.clear();
  call.request.start_controllers.push_back("l_elbow_position_controller");
  return sw.call(call) && call.response.ok ? 0 : 6;
}
"""


def _generate_headers(out: Path) -> None:
    pkg = "controller_manager_msgs"
    share = interfaces.SHARE / pkg
    includes = [f"-I{pkg}:{share / 'msg'}", "-Istd_msgs:/usr/share/std_msgs/msg"]
    for source in sorted((share / "msg").glob("*.msg")) + sorted((share / "srv").glob("*.srv")):
        subprocess.run(["/usr/bin/python3", str(GEN_CPP), str(source), "-p", pkg,
                        "-o", str(out / pkg), "-e", str(TEMPLATES), *includes], check=True,
                       capture_output=True, timeout=60)


def test_a_compiled_roscpp_client_switches_controllers(tmp_path):
    if not (Path(ROSCORE).exists() and GEN_CPP.exists() and shutil.which("g++")
            and Path("/usr/include/ros/ros.h").exists()):
        pytest.skip("needs Debian's ros-core, python3-gencpp, libroscpp-dev and g++")
    include = tmp_path / "include"
    _generate_headers(include)
    assert (include / "controller_manager_msgs" / "SwitchController.h").exists()
    binary = tmp_path / "switch_client"
    subprocess.run(["g++", "-std=c++17", "-O0", "-o", str(binary), "-x", "c++", "-",
                    f"-I{include}", "-lroscpp", "-lrosconsole", "-lroscpp_serialization",
                    "-lrostime", "-lxmlrpcpp", "-lcpp_common", "-lboost_system"],
                   input=CLIENT, check=True, capture_output=True, text=True, timeout=300)
    port = free_port()
    core = start_roscore(port)
    sim = start_mexone(port)
    try:
        out = subprocess.run([str(binary)], env=ros_env(port), capture_output=True, text=True,
                             timeout=120)
        assert out.returncode == 0, (out.returncode, out.stderr[-2000:])
        assert "l_elbow_position_controller stopped" in out.stdout
        time.sleep(0.5)
        assert sim.poll() is None
    finally:
        stop(sim)
        stop(core)
