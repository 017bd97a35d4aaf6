"""`mexone example-robot DIR`: write mexone's sample robot package, a robot of your own to try
every verb on (the README's "Your own robot" follows it)."""

from __future__ import annotations

import argparse
from importlib.resources import as_file, files
from pathlib import Path

from mexone.errors import InputError, OutputExistsError
from mexone.files import check_output, usable, write_text

__all__ = ["add_parser", "run", "sample_files", "PACKAGE"]

PACKAGE = "biped_description"

HELP = f"""\
Write a small ROS robot package into DIR (created if missing): {PACKAGE}, a 4.7 kg biped
with 10 joints (hips, knees, ankles, shoulders, elbows; boxes only), laid out as a Gazebo
robot package is:

  package.xml, CMakeLists.txt     a catkin package named {PACKAGE}
  urdf/biped.urdf                 links, joints, <gazebo> friction and contact blocks
  urdf/biped.urdf.xacro           the URDF and the transmissions, included by $(find ...)
  config/controllers.yaml         position controllers, written by 'mexone controllers'
  config/controllers_transmissions.xacro   their <transmission>s
  config/standing.yaml            the standing pose (--pose)

Then, in DIR: mexone check urdf/biped.urdf.xacro --controllers config/controllers.yaml;
mexone sim urdf/biped.urdf.xacro --controllers config/controllers.yaml --pose
config/standing.yaml. Existing files are not replaced without --force (nothing is written
then)."""


def add_parser(sub) -> None:
    p = sub.add_parser("example-robot", help="write a sample robot package to try the verbs on",
                       description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("directory", type=Path, metavar="DIR", help="the package folder to write")
    p.add_argument("--force", action="store_true", help="replace files that exist")
    p.set_defaults(run=run)


def sample_files() -> dict[str, str]:
    """The package's files (relative path -> text), as shipped in mexone/robots/samples."""
    with as_file(files("mexone.robots") / "samples" / PACKAGE) as root:
        return {path.relative_to(root).as_posix(): path.read_text()
                for path in sorted(Path(root).rglob("*")) if path.is_file()}


def run(args: argparse.Namespace) -> int:
    folder = usable(args.directory)
    if folder.exists() and not folder.is_dir():
        raise InputError("is a file, not a folder", file=folder, hint="name a folder to write into")
    sample = sample_files()
    targets = {name: folder / name for name in sample}
    existing = [path for path in targets.values() if path.exists() or path.is_symlink()]
    if existing and not args.force:  # checked before anything is written: a refusal changes nothing
        raise OutputExistsError(f"already exists ({len(existing)} of the package's {len(sample)} "
                                "files are there); nothing was written", file=existing[0],
                                hint="pass --force to overwrite them, or pick another folder")
    for path in targets.values():
        path.parent.mkdir(parents=True, exist_ok=True)
        check_output(path, args.force)
    for name, text in sample.items():
        write_text(targets[name], text, args.force)
    print(f"wrote {folder}: the ROS package {PACKAGE} ({len(sample)} files); try, in it:\n"
          "  mexone check urdf/biped.urdf.xacro --controllers config/controllers.yaml\n"
          "  mexone sim urdf/biped.urdf.xacro --controllers config/controllers.yaml "
          "--pose config/standing.yaml")
    return 0
