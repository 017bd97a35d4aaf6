"""`mexone controllers ROBOT -o controllers.yaml`: controllers with gains from the robot's physics,
written as a ros_control YAML and a transmissions xacro a student edits from there."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from mexone.cli import add_input_limit_option
from mexone.cli.common import add_joint_pose_options, joint_pose_from_args
from mexone.control.autotune import controllers_yaml, transmissions_xacro, tune
from mexone.control.skeleton import class_name, skeleton_files
from mexone.description.loader import load_model
from mexone.description.packages import package_name
from mexone.errors import InputError
from mexone.files import check_output, write_text
from mexone.lab import robot_namespace
from mexone.physics.compile import Spawn, initial_positions
from mexone.physics.world import default_world, read_world
from mexone.walking.skeletons import PARTS as WALKING_PARTS
from mexone.walking.skeletons import walking_skeleton_files

HELP = """\
Write ros_control controllers for a robot that has none: one
effort_controllers/JointPositionController per moving joint (joints a <mimic> drives follow
their leader) and a joint_state_controller, as `mexone sim --controllers auto` runs them.

Gains come from physics, in the standing pose (-J / --pose, else every joint at 0): for each
joint the inertia it moves about its axis (the links beyond it, or for a leg the rest of the
robot it lifts), a bandwidth w that the time step (w dt <= 0.1) and the effort limit (an error
of 0.1 rad saturates it) allow, and p = I w^2, d = 2 I w (critically damped). A comment above
each controller says how its gains were derived.

Also writes the <transmission> blocks ros_control needs (and the gazebo_ros_control plugin if
the robot has none) as a xacro to include from the robot's own: OUT's name with
_transmissions.xacro, or --transmissions. Existing files are not replaced without --force.

`mexone controllers new NAME [DIR]` writes your own controller instead: DIR/<name>.py, a
commented PythonController holding Mex-One's left arm, and DIR/controllers.yaml running it
beside the shipped controllers (DIR defaults to NAME; see docs/controllers.md). With --part
footsteps, com_planner, estimator or whole_body: a part of the walking stack instead, and the
stack's YAML with that part replaced by it (docs/walking-stack.md)."""


class _RenamedKind(argparse.Action):
    """`--kind` was renamed `--part` (a walking part is not a controller's kind)."""

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        print("mexone controllers: --kind is renamed --part; the old name goes in the next release",
              file=sys.stderr)
        setattr(namespace, self.dest, values)


def add_parser(sub) -> None:
    p = sub.add_parser("controllers", help="write controllers with gains from the robot's physics",
                       description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", type=Path, help="URDF, .urdf.xacro, SDF or MJCF robot; or 'new'")
    p.add_argument("new_args", nargs="*", metavar="NAME [DIR]",
                   help="after 'new': the controller's name and the folder to write it in")
    p.add_argument("-o", "--output", type=Path, metavar="YAML",
                   help="controller YAML to write (required unless 'new')")
    p.add_argument("--transmissions", type=Path, metavar="XACRO",
                   help="where the transmissions go (default: next to YAML, "
                        "<name>_transmissions.xacro)")
    p.add_argument("--world", type=Path, help="SDF .world whose time step the gains are for "
                                              "(default: 1 ms)")
    p.add_argument("--fixed-base", action="store_true",
                   help="the robot is welded where it spawns: no joint lifts the rest of it")
    p.add_argument("--part", default="arm", choices=("arm", *WALKING_PARTS),
                   help="after 'new': what to write: arm (a PD on the left arm, default) or a part "
                        "of the walking stack, in walking.yaml (docs/walking-stack.md)")
    p.add_argument("--kind", dest="part", choices=("arm", *WALKING_PARTS), action=_RenamedKind,
                   help=argparse.SUPPRESS)  # renamed --part: works, and says so, for one release
    p.add_argument("--force", action="store_true", help="overwrite files that exist")
    add_joint_pose_options(p)
    add_input_limit_option(p)
    p.set_defaults(run=run)


def include_name(path: Path) -> str:
    """How a xacro includes `path`: `$(find pkg)/...` from the ROS package it is in (the nearest
    folder above with a package.xml), else its absolute path."""
    path = path.resolve()
    for folder in path.parents:
        if (name := package_name(folder)) is not None:
            return f"$(find {name})/{path.relative_to(folder).as_posix()}"
    return str(path)


def run(args: argparse.Namespace) -> int:
    if str(args.model) == "new" and not args.model.is_file():
        return _new(args)
    if args.new_args:
        raise InputError(f"unexpected argument '{args.new_args[0]}'",
                         hint="mexone controllers ROBOT -o YAML, or mexone controllers new NAME [DIR]")
    if args.output is None:
        raise InputError("no output given", hint="mexone controllers ROBOT -o controllers.yaml")
    out: Path = args.output
    if out.suffix.lower() not in (".yaml", ".yml"):
        raise InputError(f"'{out}' is not a .yaml file", hint="name the output controllers.yaml")
    xacro = args.transmissions or out.with_name(f"{out.stem}_transmissions.xacro")
    check_output(out, args.force)
    check_output(xacro, args.force)
    robot = load_model(args.model)
    world = read_world(args.world) if args.world else default_world()
    pose = initial_positions(robot, Spawn(joints=joint_pose_from_args(args)))
    floating = not (robot.fixed_to_world or args.fixed_base)
    tunings = tune(robot, world.step, pose, floating)
    if not tunings:
        raise InputError(f"'{robot.name}' has no moving joint to control", file=args.model)
    namespace = robot_namespace(robot)
    write_text(out, controllers_yaml(robot, world.step, namespace, pose, floating,
                                     source=args.model.name), args.force)
    write_text(xacro, transmissions_xacro(robot, namespace, out.name, include_name(xacro)),
               args.force)
    print(f"wrote {out}: {len(tunings)} position controllers and a joint_state_controller")
    print(f"wrote {xacro}: include it from {args.model.name} for ros_control's <transmission>s")
    sag = max(tunings, key=lambda t: t.sag)
    print(f"standing, the largest steady error is {sag.sag:.2g} at '{sag.joint}'")
    return 0


def _new(args: argparse.Namespace) -> int:
    """`mexone controllers new NAME [DIR]`: a skeleton controller and its YAML, runnable as
    written; nothing is overwritten without --force (a refusal writes nothing)."""
    if not args.new_args or len(args.new_args) > 2:
        raise InputError("usage: mexone controllers new NAME [DIR]",
                         hint="e.g. mexone controllers new my_controller")
    name = args.new_args[0]
    files = skeleton_files(name) if args.part == "arm" else walking_skeleton_files(name, args.part)
    folder = Path(args.new_args[1]) if len(args.new_args) > 1 else Path(class_name(name)[0])
    if folder.exists() and not folder.is_dir():
        raise InputError("is a file, not a folder", file=folder, hint="name a folder")
    paths = [folder / file for file in files]
    if folder.is_dir():
        for path in paths:
            check_output(path, args.force)
    folder.mkdir(parents=True, exist_ok=True)
    for path, text in zip(paths, files.values(), strict=True):
        write_text(path, text, args.force)
    yaml_path = paths[1]
    print(f"wrote {paths[0]}: the controller (edit update())")
    print(f"wrote {yaml_path}: " + ("Mex-One's controllers with the left arm driven by it"
                                    if args.part == "arm" else
                                    f"Mex-One's walking stack with its {args.part} replaced by it"))
    print(f"run it: mexone sim --controllers {yaml_path}")
    return 0
