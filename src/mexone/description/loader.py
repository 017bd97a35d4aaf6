"""load_model(path): any supported robot file -> RobotModel, chosen by the file's name."""

from __future__ import annotations

from pathlib import Path

from mexone.description.mjcf import read_mjcf
from mexone.description.model import RobotModel
from mexone.description.sdf import read_sdf
from mexone.description.urdf import parse_urdf, read_urdf
from mexone.description.xacro_run import expand_xacro
from mexone.description.xmlio import XmlReader
from mexone.errors import InputError

__all__ = ["load_model", "model_format", "FORMATS"]

FORMATS = {"urdf": "URDF", "xacro": "URDF with xacro macros", "sdf": "SDF model (Gazebo)",
           "mjcf": "MJCF (MuJoCo XML)"}


def model_format(path: Path) -> str:
    """'urdf', 'xacro', 'sdf' or 'mjcf' from the file name; a Gazebo model folder means its
    model.sdf."""
    name = path.name.lower()
    if name.endswith(".xacro"):
        return "xacro"
    if name.endswith(".urdf"):
        return "urdf"
    if name.endswith((".sdf", ".world")) or path.is_dir():
        return "sdf"
    if name.endswith((".xml", ".mjcf")):
        return "mjcf"
    raise InputError(f"unknown model format '{path.suffix or path.name}'", file=path,
                     hint="expected .urdf, .urdf.xacro/.xacro, .sdf, a Gazebo model folder or "
                          "MJCF .xml")


def load_model(path: Path | str) -> RobotModel:
    path = Path(path)
    kind = model_format(path)
    if kind == "urdf":
        return read_urdf(path)
    if kind == "sdf":
        return read_sdf(path / "model.sdf" if path.is_dir() else path)
    if kind == "mjcf":
        return read_mjcf(path)
    return _read_xacro(path)


def _read_xacro(path: Path) -> RobotModel:
    XmlReader(path)  # vets the source (a regular file, entities refused, syntax errors with lines)
    expanded = expand_xacro(path)  # in a child process with a time limit
    # line numbers now refer to the expanded document; say so in every message
    return parse_urdf(XmlReader(path, data=expanded, label=f"{path} (after xacro)"), path)
