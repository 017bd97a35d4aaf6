"""MJCF export from the same compile path the simulator uses, so the XML is the simulated robot."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from lxml import etree

from mexone.description.model import RobotModel
from mexone.physics.compile import CompileOptions, Spawn, SpecEdit, compile_model
from mexone.physics.world import World

__all__ = ["write_mjcf"]


def write_mjcf(robot: RobotModel, world: World | None = None, spawn: Spawn = Spawn(),
               options: CompileOptions = CompileOptions(), edits: Sequence[SpecEdit] = (),
               out_dir: Path | None = None) -> str:
    """MuJoCo XML of robot + world; `edits` add what the simulator adds (the control layer's
    actuators). Mesh files are named relative to out_dir (where the XML goes), else absolute."""
    text = compile_model(robot, world, spawn, options, edits).spec.to_xml()
    if out_dir is None:
        return text
    # MjSpec.to_xml recompiles, so the files must still open from here: rewrite the XML instead
    root = etree.fromstring(text.encode())
    for mesh in root.iter("mesh"):
        if (file := mesh.get("file")) and os.path.isabs(file):
            mesh.set("file", os.path.relpath(file, Path(out_dir).resolve()))
    return etree.tostring(root, encoding="unicode") + "\n"
