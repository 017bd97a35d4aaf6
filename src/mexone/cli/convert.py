"""`mexone convert IN -o OUT`: between URDF, xacro, SDF (and MJCF once physics exists)."""

from __future__ import annotations

import argparse
from pathlib import Path

from mexone.cli import add_input_limit_option
from mexone.description.check import check_model
from mexone.description.convert import rebase_meshes
from mexone.description.loader import load_model
from mexone.description.sdf import write_sdf
from mexone.description.urdf import write_urdf
from mexone.errors import InputError
from mexone.files import check_output, write_text
from mexone.physics.mjcf import write_mjcf

HELP = """\
Convert a robot description. The output format follows OUT's extension:
  .urdf   URDF with <gazebo> and <transmission> blocks (from SDF: the seed's chapter 3.3,
          link frames moved onto their joints, axes rotated into joint frames, SDF-only
          properties kept in <gazebo reference> blocks and <dynamics>)
  .sdf    SDF 1.6 model (link poses in the model frame)
  .xml    MJCF (MuJoCo XML) from the simulator's own compile path: the robot exactly as
  .mjcf   mexone simulates it, on the default world's ground, loadable by
          mujoco.MjModel.from_xml_path
Input: .urdf, .urdf.xacro/.xacro (expanded with xacro), .sdf or a Gazebo model folder.
What the output format cannot represent (closed loops, ball joints, several models) is an
error, never a silently different robot. An existing OUT is not replaced without --force."""

WRITERS = {".urdf": write_urdf, ".sdf": write_sdf, ".xml": write_mjcf, ".mjcf": write_mjcf}


def add_parser(sub) -> None:
    parser = sub.add_parser("convert", help="convert between URDF, xacro, SDF and MJCF",
                            description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("input", type=Path, help="model to read")
    parser.add_argument("-o", "--output", type=Path, required=True, metavar="OUT",
                        help="file to write; its extension picks the format")
    parser.add_argument("--force", action="store_true", help="overwrite OUT if it exists")
    add_input_limit_option(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out: Path = args.output
    writer = WRITERS.get(out.suffix.lower())
    if writer is None:
        raise InputError(f"cannot write '{out.suffix or out.name}' files", file=out,
                         hint="name the output .urdf, .sdf or .xml (MJCF)")
    check_output(out, args.force)
    model = rebase_meshes(load_model(args.input), out.parent)
    text = writer(model)
    write_text(out, text, args.force)
    if out.suffix.lower() == ".sdf" and model.transmissions:
        print(f"note: {len(model.transmissions)} <transmission> blocks are not part of SDF and "
              "were left out; keep the URDF as the source of truth for control")
    problems = [f for f in check_model(model) if f.severity == "error"]
    print(f"wrote {out}: {len(model.links)} links, {len(model.joints)} joints"
          + (f"; {len(problems)} lint error(s), run 'mexone check {out}'" if problems else ""))
    return 0
