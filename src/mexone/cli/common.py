"""Options and assembly shared by the verbs that simulate (sim, run, and later record/render)."""

from __future__ import annotations

import argparse
import ipaddress
import math
import socket
import sys
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import yaml

from mexone import ranges, yamlio
from mexone.cli import add_input_limit_option
from mexone.errors import InputError
from mexone.inputs import read_input_text
from mexone.lab import AUTO, Lab
from mexone.physics import CompileOptions, Spawn
from mexone.physics.world import default_world, read_world
from mexone.ranges import Range

__all__ = ["add_model_options", "lab_from_args", "options_from_args", "recording",
           "add_record_options", "positive", "Number", "DURATION", "host", "check_can_serve",
           "folder", "controllers_arg", "joint_pose_from_args", "add_joint_pose_options"]


@dataclass(frozen=True)
class Number:
    """argparse type: every number on the command line is checked here, at the edge, so NaN,
    infinity or a value out of range is one line naming the flag, not a NaN in MuJoCo later."""

    low: float | None = None
    high: float | None = None
    low_open: bool = False  # low itself is not allowed
    integer: bool = False
    hint: str = ""

    @classmethod
    def of(cls, valid: Range, hint: str | None = None) -> Number:
        """The argparse type of a quantity whose one range lives in ranges.py."""
        return cls(valid.low, valid.high, valid.low_open, valid.integer,
                   valid.why if hint is None else hint)

    def describe(self) -> str:
        def text(value: float) -> str:
            return str(int(value)) if self.integer else f"{value:g}"

        bounds = []
        if self.low is not None:
            bounds.append(f"{'>' if self.low_open else '>='} {text(self.low)}")
        if self.high is not None:
            bounds.append(f"<= {text(self.high)}")
        kind = "an integer" if self.integer else "a finite number"
        return " ".join([kind, " and ".join(bounds)]).strip()

    def __call__(self, text: str) -> float | int:
        try:
            value = int(text) if self.integer else float(text)
        except ValueError:
            what = "an integer" if self.integer else "a number"
            raise argparse.ArgumentTypeError(f"'{text}' is not {what}") from None
        low_fails = self.low is not None and (value <= self.low if self.low_open else value < self.low)
        if not math.isfinite(value) or low_fails or (self.high is not None and value > self.high):
            hint = f"; {self.hint}" if self.hint else ""
            raise argparse.ArgumentTypeError(f"{text} must be {self.describe()}{hint}")
        return value


positive = Number(0.0, low_open=True)  # rates, frames per second
DURATION = Number.of(ranges.DURATION, "s of sim time")  # from one 1 ms step to "until Ctrl-C"
POSITION = Number.of(ranges.POSITION, "metres")
JOINT_VALUE = Number.of(ranges.JOINT_VALUE, "radians or metres")
ANGLE = Number.of(ranges.ANGLE, "radians, within +-2 pi (1.5708 is 90 degrees)")
RTF = Number.of(ranges.RTF, "0 runs as fast as possible")
PORT = Number.of(ranges.PORT, "0 picks a free port")


def host(text: str) -> str:
    """argparse type: an IP address or a host name that resolves (checked before viser starts,
    whose server thread otherwise dies with a traceback and leaves the process hanging)."""
    try:
        return str(ipaddress.ip_address(text))
    except ValueError:
        pass
    if not text or text.replace(".", "").isdigit() or text.startswith("-"):
        raise argparse.ArgumentTypeError(f"'{text}' is not an IP address or host name")
    try:
        socket.getaddrinfo(text, None)
    except (OSError, UnicodeError):
        raise argparse.ArgumentTypeError(f"'{text}' is not an IP address or a host name "
                                         "that resolves") from None
    return text


def folder(text: str) -> Path:
    """argparse type: a folder that exists."""
    path = Path(text)
    if not path.is_dir():
        raise argparse.ArgumentTypeError(f"'{text}' is not a folder")
    return path


def check_can_serve(address: str) -> None:
    """Refuse an address this machine does not have (e.g. 8.8.8.8) before the GUI starts."""
    try:
        infos = socket.getaddrinfo(address, 0, type=socket.SOCK_STREAM)
        family, _, _, _, sockaddr = infos[0]
        with socket.socket(family, socket.SOCK_STREAM) as probe:
            probe.bind(sockaddr)
    except OSError as exc:
        raise InputError(f"cannot serve the GUI on --host {address}: {exc.strerror or exc}",
                         hint="use 127.0.0.1 (this machine), 0.0.0.0 (every network) or an "
                              "address of this machine") from None


def add_record_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--record", type=Path, metavar="BAG",
                   help="record every topic to BAG: .mcap (rosbag2/ROS 2) or .bag (ROS 1)")
    p.add_argument("--force", action="store_true", help="overwrite output files that exist")


@contextmanager
def recording(lab: Lab, path: Path | None, force: bool):
    """Record while the body runs; the bag is closed (valid) however the body ends."""
    if path is None:
        yield None
        return
    from mexone.record.bag import BagRecorder

    recorder = None
    try:
        recorder = BagRecorder(lab, path, force)
        yield recorder
    finally:
        if recorder is not None:
            recorder.close()
            total = sum(recorder.counts.values())
            print(f"mexone: recorded {total} messages on {len(recorder.counts)} topics to {path}",
                  file=sys.stderr)


def add_model_options(p: argparse.ArgumentParser, model_positional: bool = False) -> None:
    if not model_positional:
        p.add_argument("--model", type=Path,
                       help="URDF, .urdf.xacro, SDF or MJCF robot (default: the built-in Mex-One)")
    p.add_argument("--controllers", type=controllers_arg, metavar="YAML|auto",
                   help="ros_control controller YAML (default: the built-in robot's own), or "
                        "'auto': a position controller on every moving joint, gains from the "
                        "robot's physics (see 'mexone controllers')")
    p.add_argument("--no-controllers", action="store_true",
                   help="no controllers: the joints are free (the seed's fall test)")
    p.add_argument("--world", type=Path, help="SDF .world file (default: ground plane, sun, 1 ms)")
    add_input_limit_option(p)
    p.add_argument("--no-self-collide", action="store_true",
                   help="turn self-collision off for every link (the seed's Fig. 4.8)")
    p.add_argument("--fixed-base", action="store_true",
                   help="weld the robot's root where it spawns (a robot on a stand)")
    pose = p.add_argument_group("spawn pose (as gazebo_ros spawn_model; z is the height of the "
                                "robot's lowest point, so 0 stands it on the ground)")
    for flag, name, kind in (("-x", "x", POSITION), ("-y", "y", POSITION), ("-z", "z", POSITION),
                             ("-R", "roll", ANGLE), ("-P", "pitch", ANGLE), ("-Y", "yaw", ANGLE)):
        pose.add_argument(flag, dest=name, type=kind, default=0.0, metavar=name.upper())
    add_joint_pose_options(pose)


def add_joint_pose_options(p) -> None:
    """-J JOINT VALUE (spawn_model's) and --pose YAML: initial joint positions."""
    p.add_argument("-J", dest="joint_positions", nargs=2, action="append", default=[],
                   metavar=("JOINT", "VALUE"),
                   help="initial position of a joint (rad or m; repeatable), held by the "
                        "controllers from t = 0")
    p.add_argument("--pose", type=Path, metavar="YAML",
                   help="initial joint positions from a YAML mapping 'joint: value' (-J wins)")


def controllers_arg(text: str) -> Path | str:
    """argparse type of --controllers: the word auto, or a YAML file."""
    return AUTO if text == AUTO else Path(text)


def joint_pose_from_args(args: argparse.Namespace) -> tuple[tuple[str, float], ...]:
    """--pose's positions, then -J's, checked as numbers here (names: when the robot compiles)."""
    pose: dict[str, float] = {}
    if getattr(args, "pose", None) is not None:
        pose.update(read_pose(args.pose))
    for name, text in getattr(args, "joint_positions", []):
        try:
            pose[name] = JOINT_VALUE(text)
        except argparse.ArgumentTypeError as exc:
            raise InputError(f"-J {name} {text}: {exc}") from None
    return tuple(pose.items())


def read_pose(path: Path) -> dict[str, float]:
    """A YAML mapping joint -> position (rad or m), each value checked with its line."""
    root = yamlio.compose(read_input_text(path), path)
    if not isinstance(root, yaml.MappingNode):
        raise InputError("a pose file must map joint names to positions", file=path,
                         line=root.start_mark.line + 1 if root is not None else None,
                         hint="e.g. 'l_knee: 0.4' on each line")
    pose = {}
    for key, node in root.value:
        value = yamlio.construct(node)
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise InputError(f"position of '{key.value}' is '{node.value}', not a finite number",
                             file=path, line=node.start_mark.line + 1, hint="radians or metres")
        pose[str(key.value)] = float(value)
    return pose


def options_from_args(args: argparse.Namespace) -> CompileOptions:
    return CompileOptions(self_collision=False if args.no_self_collide else None,
                          fixed_base=args.fixed_base)


def lab_from_args(args: argparse.Namespace, target_rtf: float | None = None,
                  options: CompileOptions | None = None) -> Lab:
    controllers = False if args.no_controllers else args.controllers
    lab = Lab.create(
        model=args.model,
        controllers=controllers,
        world=read_world(args.world) if args.world else default_world(),
        spawn=Spawn((args.x, args.y, args.z), (args.roll, args.pitch, args.yaw),
                    joints=joint_pose_from_args(args)),
        options=options or options_from_args(args),
        target_rtf=target_rtf,
        namespace=getattr(args, "namespace", None),  # sim --namespace
        start=getattr(args, "start_controllers", None),  # None: every one that does not clash
    )
    if lab.manager is None and not args.no_controllers:
        print(f"mexone: {lab.no_controllers}", file=sys.stderr)
    return lab
