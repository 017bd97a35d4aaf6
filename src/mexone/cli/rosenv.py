"""`eval "$(mexone ros-env)"`: mexone's ROS 1 packages on ROS_PACKAGE_PATH and their Python on
PYTHONPATH, as `source devel/setup.bash` does for a catkin workspace: a pip install has no
src/ folder to point them at."""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from pathlib import Path

from mexone.ros1.interfaces import environment

__all__ = ["add_parser", "run", "exports"]

HELP = """\
Print the shell exports that let ROS 1 tools find mexone's packages wherever pip installed it:
ROS_PACKAGE_PATH gains the message packages (controller_manager_msgs, control_msgs,
gazebo_msgs), controller_manager with its spawner and the robot package mex_rb (roslaunch
mex_rb control.launch); PYTHONPATH gains the messages' Python (rostopic, rosservice, rospy
nodes); PATH gains the folder of this `mexone` command if it is not on PATH (an unactivated
venv), since roslaunch mex_rb model.launch starts `mexone sim --ros`. Existing entries stay
first; nothing is added twice, so running it again is harmless.

    eval "$(mexone ros-env)"        # in ~/.bashrc after ROS's own setup"""

KEYS = ("ROS_PACKAGE_PATH", "PYTHONPATH")


def add_parser(sub) -> None:
    p = sub.add_parser("ros-env", help="print the exports that put mexone's ROS packages on the paths",
                       description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.set_defaults(run=run)


def exports(env: dict[str, str] | None = None) -> str:
    """POSIX shell lines (sh, bash, zsh) exporting the paths with mexone's entries added."""
    new = environment(env)
    lines = [f"export {key}={shlex.quote(new[key])}\n" for key in KEYS]
    folder = _command_folder()
    path = new.get("PATH", "")
    if folder is not None and folder not in path.split(os.pathsep):  # appended: the system's
        lines.append(f"export PATH={shlex.quote(f'{path}{os.pathsep}{folder}')}\n")  # python3 first
    return "".join(lines)


def _command_folder() -> str | None:
    """The folder holding the `mexone` command that runs (a venv's bin/), if there is one."""
    for candidate in (Path(sys.argv[0]), Path(sys.executable).with_name("mexone")):
        if candidate.name == "mexone" and os.access(candidate, os.X_OK):
            return str(candidate.absolute().parent)
    return None


def run(args: argparse.Namespace) -> int:
    print(exports(), end="")
    return 0
