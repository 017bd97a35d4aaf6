"""`mexone convert IN -o OUT`: between URDF, xacro, SDF (and MJCF once physics exists)."""

from __future__ import annotations

import argparse
from pathlib import Path

from mexone.cli import add_input_limit_option
from mexone.cli.common import controllers_arg
from mexone.control.autotune import auto_config, with_transmissions
from mexone.control.config import load_control_config
from mexone.control.hardware import bake_gains, build_actuators
from mexone.description.check import check_model
from mexone.description.convert import merge_massless, rebase_meshes
from mexone.description.loader import load_model
from mexone.description.sdf import write_sdf
from mexone.description.urdf import write_urdf
from mexone.errors import InputError
from mexone.files import check_output, write_text
from mexone.lab import AUTO
from mexone.physics.mjcf import write_mjcf
from mexone.physics.world import default_world

HELP = """\
Convert a robot description. The output format follows OUT's extension:
  .urdf   URDF with <gazebo> and <transmission> blocks (from SDF: the seed's chapter 3.3,
          link frames moved onto their joints, axes rotated into joint frames, SDF-only
          properties kept in <gazebo reference> blocks and <dynamics>)
  .sdf    SDF 1.6 model (link poses in the model frame)
  .xml    MJCF (MuJoCo XML) from the simulator's own compile path: the robot exactly as
  .mjcf   mexone simulates it, on the default world's ground, loadable by
          mujoco.MjModel.from_xml_path, with its controllers' actuators (--controllers) and
          mesh paths relative to OUT's folder
SDF has no massless link: massless links on fixed joints (IMU, camera frames) are merged into
their parents, as sdformat does, so the robot's mass is unchanged.
Input: .urdf, .urdf.xacro/.xacro (expanded with xacro), .sdf, a Gazebo model folder or MJCF.
What the output format cannot represent (closed loops, ball joints, several models) is an
error, never a silently different robot. An existing OUT is not replaced without --force."""

MJCF = (".xml", ".mjcf")
WRITERS = {".urdf": write_urdf, ".sdf": write_sdf}


def add_parser(sub) -> None:
    parser = sub.add_parser("convert", help="convert between URDF, xacro, SDF and MJCF",
                            description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("input", type=Path, help="model to read")
    parser.add_argument("-o", "--output", type=Path, required=True, metavar="OUT",
                        help="file to write; its extension picks the format")
    parser.add_argument("--controllers", type=controllers_arg, default=AUTO, metavar="YAML|auto",
                        help="MJCF only: whose gains the exported actuators carry (default auto: "
                             "gains from the robot's physics, as 'mexone controllers' writes them)")
    parser.add_argument("--force", action="store_true", help="overwrite OUT if it exists")
    add_input_limit_option(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out: Path = args.output
    suffix = out.suffix.lower()
    if suffix not in WRITERS and suffix not in MJCF:
        raise InputError(f"cannot write '{out.suffix or out.name}' files", file=out,
                         hint="name the output .urdf, .sdf or .xml (MJCF)")
    check_output(out, args.force)
    model = load_model(args.input)
    problems = [f for f in check_model(model) if f.severity == "error"]  # where the meshes are
    notes = []
    if suffix in MJCF:
        model, actuated = _with_actuators(model, args.controllers)
        text = write_mjcf(model, edits=actuated, out_dir=out.parent)
        notes.append(f"{2 * len(model.actuated_joints)} actuators: per joint a PID servo (ctrl: "
                     "q_ref, v_ref, effort) and its integral term (ctrl: q_ref)")
    else:
        if suffix == ".sdf":
            model, merged = merge_massless(model)
            if merged:
                notes.append(f"{len(merged)} massless link(s) ({', '.join(merged[:3])}"
                             f"{', ...' if len(merged) > 3 else ''}) merged into their parents: "
                             "SDF has no massless link")
        text = WRITERS[suffix](rebase_meshes(model, out.parent))
    write_text(out, text, args.force)
    if suffix == ".sdf" and model.transmissions:
        print(f"note: {len(model.transmissions)} <transmission> blocks are not part of SDF and "
              "were left out; keep the URDF as the source of truth for control")
    for note in notes:
        print(f"note: {note}")
    print(f"wrote {out}: {len(model.links)} links, {len(model.joints)} joints"
          + (f"; {len(problems)} lint error(s), run 'mexone check {args.input}'" if problems else ""))
    return 0


def _with_actuators(model, controllers) -> tuple:
    """The robot with transmissions where the controllers need them, and the spec edits that add
    the actuators with those controllers' gains."""
    if controllers == AUTO:
        model = with_transmissions(model)
        gains = {c.joints[0]: c.pid for c in auto_config(model, default_world().step).controllers.values()
                 if c.pid is not None}
    else:
        config = load_control_config(controllers)
        gains = {}
        for spec in config.controllers.values():
            if spec.controller_class.tracks_position:
                for joint in spec.joints:
                    pid = (spec.gains or {}).get(joint) or spec.pid or config.pid_gains.get(joint)
                    if pid is not None and model.transmission_for(joint) is not None:
                        gains[joint] = pid
    return model, [build_actuators, bake_gains(gains)]
