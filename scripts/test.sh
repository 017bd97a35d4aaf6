#!/usr/bin/env bash
# Install everything the test suite needs, then run it (lint + pytest).
#   bash scripts/test.sh [extra pytest arguments]
# Debian packages (the real check_urdf from urdfdom, Chromium for the GUI) are installed when missing, as root
# directly or through sudo; pip installs mexone in editable mode with its test extras.
set -euo pipefail
cd "$(dirname "$0")/.."

apt_packages=()
command -v check_urdf >/dev/null 2>&1 || apt_packages+=(liburdfdom-tools)
command -v cmake >/dev/null 2>&1 || apt_packages+=(cmake)  # building tf2_msgs for ROS 2
command -v chromium >/dev/null 2>&1 || apt_packages+=(chromium)  # the GUI's browser tests
command -v npm >/dev/null 2>&1 || apt_packages+=(nodejs npm)  # Foxglove's client, JupyterHub's proxy
dpkg -s python3-venv >/dev/null 2>&1 || apt_packages+=(python3-venv)  # the students' venv (tests/hub)
# ROS 1 from Debian: the real roscore, rostopic, robot_state_publisher, rospy and tf2 to test against
ros_packages=(ros-core python3-rospy python3-rostopic ros-robot-state-publisher python3-std-msgs
              python3-sensor-msgs python3-std-srvs python3-rosgraph-msgs python3-tf2-msgs
              python3-tf2-ros python3-trajectory-msgs python3-geometry-msgs
              python3-tf2-sensor-msgs python3-tf2-geometry-msgs
              python3-nav-msgs ros-nav-msgs  # a walk's planned paths (nav_msgs/Path)
              # ROS parity: genpy/gencpp and the definitions mexone's interfaces depend on,
              # actionlib, dynamic_reconfigure (dynparam), roscpp headers for the compiled client
              python3-genpy python3-genmsg python3-gencpp ros-std-msgs ros-geometry-msgs
              ros-trajectory-msgs ros-sensor-msgs ros-actionlib-msgs python3-actionlib
              python3-actionlib-msgs python3-dynamic-reconfigure python3-rosservice
              python3-rosbag python3-roslaunch libroscpp-dev libstd-msgs-dev g++
              rosbash)  # rosrun (dynparam, the README's commands)
dpkg -s "${ros_packages[@]}" >/dev/null 2>&1 || apt_packages+=("${ros_packages[@]}")
# the real rviz under a virtual X server (tests/ros1/test_rviz.py)
dpkg -s rviz xvfb xauth >/dev/null 2>&1 || apt_packages+=(rviz xvfb xauth)
# offscreen rendering for `mexone render`: EGL with Mesa's software driver
dpkg -s libegl1 libgl1-mesa-dri >/dev/null 2>&1 || apt_packages+=(libegl1 libgl1-mesa-dri)
if ((${#apt_packages[@]})); then
  sudo=""
  [ "$(id -u)" = 0 ] || sudo="sudo"
  echo "installing Debian packages: ${apt_packages[*]}"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${apt_packages[@]}" >/dev/null
fi

# the wheel of this checkout in a fresh venv (tests/wheelenv.py), for the tests that run what a
# user installs: built in the background while the rest of the set-up, ruff and mypy run (one
# core each at most), taken by the serial phase's session (which builds its own if this failed)
# (tests/hub/classroom.py takes its wheel too)
prebuilt="$(mktemp -d "${TMPDIR:-/tmp}/mexone-wheelenv.XXXXXX")"
python3 tests/wheelenv.py "$prebuilt" >"$prebuilt.log" 2>&1 &
prebuilding=$!
echo "$prebuilding" >"$prebuilt/pid"  # classroom.py stops waiting for a wheel if it ends without one
trap 'kill "$prebuilding" 2>/dev/null || true; rm -rf "$prebuilt" "$prebuilt.log"' EXIT
export MEXONE_TEST_PREBUILT="$prebuilt"
python3 -m pip install -q --disable-pip-version-check -e ".[test,docs]"  # docs: tests/test_docs*.py
# the teacher's pack: the shipped course's reference solutions, which the wheel leaves out (the
# exercise tests grade them); its own distribution, never installed by `pip install .`
python3 -m pip install -q --disable-pip-version-check --no-deps -e ./teacher
# ROS 2's wheels name their packages as ROS 1's (std_msgs, ...): a venv of their own for the
# --ros2 tests (tests/ros2), which start the simulator and their rclpy client with its python
[ -x .venv-ros2/bin/python ] || python3 -m venv --system-site-packages .venv-ros2
.venv-ros2/bin/python -m pip install -q --disable-pip-version-check -e ".[ros2,ros2-build]"
# tf2_msgs, control_msgs have no wheel: built from their official definitions with PyPI's
# rosidl tools (~20 s each, only when missing)
.venv-ros2/bin/python -m mexone.ros2.interfaces
export MEXONE_ROS2_PYTHON="$PWD/.venv-ros2/bin/python"
# Foxglove's WebSocket client (npm @foxglove/ws-protocol), which tests/foxglove_ws runs on node
npm install --prefix tests/foxglove_ws --no-audit --no-fund --silent
# A class on this machine (tests/hub, as root: a Unix user per student): JupyterHub's proxy from
# npm, and the students' venv of Debian's Python with mexone's wheel and deploy's Dockerfile's
# packages, outside this checkout (students may not enter where it is cloned)
npm install --prefix tests/hub --no-audit --no-fund --silent
[ "$(id -u)" != 0 ] || python3 tests/hub/classroom.py
python3 -m ruff check .
python3 -m mypy  # strict on the core layers (pyproject.toml's [tool.mypy])
# Two phases (tests/conftest.py's SHARES_THE_CPU): the tests that only compute, side by side on
# every core (pytest-xdist; a file's tests on one worker), then the ones that watch the wall clock
# (real-time pacing, browsers, ROS, signals) one at a time, with no neighbour to slow them. Both
# run even if the first fails; "no test selected" (exit 5, e.g. `test.sh tests/ros1`) is no failure.
wait "$prebuilding" || { echo "building the wheel's venv ahead failed (the tests build it):"; tail -20 "$prebuilt.log"; }
status=0
MEXONE_TEST_PHASE=parallel python3 -m pytest -n auto --dist loadfile "$@" || status=$?
[ "$status" != 5 ] || status=0
serial=0
# the serial phase's tests lean on the wall clock and on real tools (Chromium, rviz, roscore):
# one that fails is run once more (pytest-rerunfailures), and each rerun is named in the summary
# (-r fER); a test that fails twice fails the run. The parallel phase only computes: no reruns.
MEXONE_TEST_PHASE=serial python3 -m pytest --reruns 1 -r fER "$@" || serial=$?
[ "$serial" != 5 ] || serial=0
[ "$status" != 0 ] || status=$serial
exit "$status"
