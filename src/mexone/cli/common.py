"""Options and assembly shared by the verbs that simulate (sim, run, and later record/render)."""

from __future__ import annotations

import argparse
import sys
from contextlib import contextmanager
from pathlib import Path

from mexone.cli import add_input_limit_option
from mexone.lab import Lab
from mexone.physics import CompileOptions, Spawn
from mexone.physics.world import default_world, read_world

__all__ = ["add_model_options", "lab_from_args", "options_from_args", "recording",
           "add_record_options", "positive"]


def positive(text: str) -> float:
    """argparse type: a number > 0 (durations, rates)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"{text} must be a finite number > 0")
    return value


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

    recorder = BagRecorder(lab, path, force)
    try:
        yield recorder
    finally:
        recorder.close()
        total = sum(recorder.counts.values())
        print(f"mexone: recorded {total} messages on {len(recorder.counts)} topics to {path}",
              file=sys.stderr)


def add_model_options(p: argparse.ArgumentParser, model_positional: bool = False) -> None:
    if not model_positional:
        p.add_argument("--model", type=Path,
                       help="URDF, .urdf.xacro or SDF robot (default: the built-in Mex-One)")
    p.add_argument("--controllers", type=Path, metavar="YAML",
                   help="ros_control controller YAML (default: the built-in robot's own)")
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
    for flag, name in (("-x", "x"), ("-y", "y"), ("-z", "z"), ("-R", "roll"), ("-P", "pitch"),
                       ("-Y", "yaw")):
        pose.add_argument(flag, dest=name, type=float, default=0.0, metavar=name.upper())


def options_from_args(args: argparse.Namespace) -> CompileOptions:
    return CompileOptions(self_collision=False if args.no_self_collide else None,
                          fixed_base=args.fixed_base)


def lab_from_args(args: argparse.Namespace, target_rtf: float | None = None,
                  options: CompileOptions | None = None) -> Lab:
    controllers = False if args.no_controllers else args.controllers
    return Lab.create(
        model=args.model,
        controllers=controllers,
        world=read_world(args.world) if args.world else default_world(),
        spawn=Spawn((args.x, args.y, args.z), (args.roll, args.pitch, args.yaw)),
        options=options or options_from_args(args),
        target_rtf=target_rtf,
    )
