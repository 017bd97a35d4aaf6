"""The --ros options of `mexone sim` and `mexone run`: join the ROS 1 graph as gazebo_ros does."""

from __future__ import annotations

import argparse

from mexone.cli.common import PORT
from mexone.description.loader import load_model
from mexone.description.urdf import write_urdf
from mexone.errors import InputError
from mexone.lab import robot_namespace
from mexone.robots import mex_one
from mexone.ros1.bridge import DEFAULT_NODE, ROS_INSTALL

__all__ = ["add_ros_options", "connect_ros", "connect_bridges", "Bridges", "urdf_text"]


def add_ros_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--ros", action="store_true",
                   help="join the ROS 1 graph at ROS_MASTER_URI (topics, /clock, TF, /gazebo "
                        "services); needs Debian's ROS: " + ROS_INSTALL)
    p.add_argument("--ros2", action="store_true",
                   help="join the ROS 2 graph (ROS_DOMAIN_ID) as a node: /clock, "
                        "/robot_description, topics, ros2_control's command names, parameters, "
                        "std_srvs services; needs the ros2 extra (docs/ros2.md)")
    p.add_argument("--foxglove", nargs="?", type=PORT, const=8765, metavar="PORT",
                   help="serve every topic, the robot (URDF, meshes, TF) and sim time on the "
                        "Foxglove WebSocket protocol at ws://HOST:PORT (default 8765, on --host: "
                        "this machine only); needs the foxglove extra (docs/foxglove.md)")
    p.add_argument("--foxglove-origin", action="append", default=[], metavar="ORIGIN",
                   help="a web page's origin allowed to connect to --foxglove besides this "
                        "machine's pages (repeatable), e.g. Foxglove's web app: "
                        "--foxglove-origin https://app.foxglove.dev")
    p.add_argument("--name", default=DEFAULT_NODE, type=_ros_name,
                   help=f"ROS node name (default {DEFAULT_NODE}; its gazebo_ros services are under "
                        "/gazebo, another simulator's under /NAME): one per simulator on a master")
    p.add_argument("--namespace", "-robot_namespace", dest="namespace", type=_ros_name,
                   metavar="NS", help="the robot's ROS namespace (default: the controller YAML's, "
                                      "else the URDF's robotNamespace, else the robot's name)")


def connect_ros(args: argparse.Namespace):
    """Join the ROS graph; take the controllers from the parameter server if a `rosparam load`
    put them there and none were given on the command line (the seed's control.launch flow)."""
    from mexone.control.spec import ControlConfig
    from mexone.ros1.bridge import Ros1Bridge
    from mexone.ros1.params import config_from_param_server

    bridge = Ros1Bridge(args.name)
    if args.controllers is None and not args.no_controllers:
        robot = load_model(args.model or mex_one.urdf_path())
        ns = robot_namespace(robot, None, args.namespace).strip("/")  # no YAML given
        config = config_from_param_server(bridge.rospy, ns) if bridge.rospy.has_param(f"/{ns}") \
            else None
        if config is not None and config.controllers:
            # ros_control: loaded from the parameter server, started by the spawner
            args.controllers, args.start_controllers = config, []
        elif args.model is not None and robot.transmissions:
            # gazebo_ros_control: a controller manager with nothing loaded, for the spawner
            args.controllers = ControlConfig(ns, {}, config.pid_gains if config else {})
    return bridge


class Bridges:
    """The front ends a run joins (ROS 1, ROS 2): attached, pumped and shut down together."""

    def __init__(self, bridges: list) -> None:
        self.bridges = bridges

    def attach(self, lab, urdf: str) -> None:
        for bridge in self.bridges:
            bridge.attach(lab, urdf)

    def pump(self, sim=None) -> None:
        for bridge in self.bridges:
            bridge.pump()

    def shutdown(self) -> None:
        for bridge in reversed(self.bridges):
            bridge.shutdown()

    def notes(self) -> list[str]:
        """What a bridge could not offer (ROS 2's message packages with no wheel), each a line
        the CLI prints at start-up after where()'s."""
        return [note for b in self.bridges for note in (b.notes() if hasattr(b, "notes") else [])]

    def where(self) -> str:
        """Where the robot is now visible, for the line the CLI prints."""
        import os

        names = {"Ros1Bridge": f"ROS at {os.environ.get('ROS_MASTER_URI', '?')}",
                 "Ros2Bridge": f"ROS 2 (domain {os.environ.get('ROS_DOMAIN_ID', '0')})"}
        return " and ".join(b.where() if hasattr(b, "where") else names[type(b).__name__]
                            for b in self.bridges)


def connect_bridges(args: argparse.Namespace) -> Bridges | None:
    """The bridges the command line asks for (--ros, --ros2), connected; None for none."""
    from mexone.ros2 import check_not_both

    ros2 = getattr(args, "ros2", False)
    check_not_both(args.ros, ros2)
    bridges = []
    try:
        if args.ros:
            bridges.append(connect_ros(args))
        if ros2:
            from mexone.ros2 import Ros2Bridge

            bridges.append(Ros2Bridge(args.name))
        if getattr(args, "foxglove_origin", None) and getattr(args, "foxglove", None) is None:
            raise InputError("--foxglove-origin allows a web page to connect to --foxglove, "
                             "which is not on", hint="add --foxglove [PORT]")
        if getattr(args, "foxglove", None) is not None:
            from mexone.foxglove import FoxgloveBridge

            bridges.append(FoxgloveBridge(args.foxglove, getattr(args, "host", "127.0.0.1"),
                                          getattr(args, "foxglove_origin", ())))
    except BaseException:
        Bridges(bridges).shutdown()
        raise
    return Bridges(bridges) if bridges else None


def _ros_name(text: str) -> str:
    """argparse type: a ROS graph name (letters, digits, _ and /, not starting with a digit)."""
    import re

    name = text.strip("/")
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*", name):
        raise argparse.ArgumentTypeError(f"'{text}' is not a ROS name (letters, digits, _ and /, "
                                         "not starting with a digit)")
    return name


def urdf_text(args: argparse.Namespace, robot) -> str:
    """/robot_description: the user's URDF as written, else the model written as URDF."""
    path = args.model or mex_one.urdf_path()
    if str(path).endswith(".urdf"):
        return path.read_text()
    return write_urdf(robot)
