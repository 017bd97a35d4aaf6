"""Rewrite a RobotModel for another file: mesh references made valid from the new place."""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

from mexone.description.model import Mesh, RobotModel

__all__ = ["rebase_meshes"]

_SCHEMES = ("package://", "model://", "file://")


def rebase_meshes(model: RobotModel, out_dir: Path) -> RobotModel:
    """Relative mesh paths are relative to the model file; keep them pointing at the same
    files when the model is written into another folder. URIs and absolute paths stay."""

    def rebase(geometry):
        if not isinstance(geometry, Mesh) or geometry.filename.startswith(_SCHEMES) \
                or os.path.isabs(geometry.filename):
            return geometry
        target = (model.base_dir / geometry.filename).resolve()
        return replace(geometry, filename=os.path.relpath(target, out_dir.resolve()))

    for link in model.links.values():
        link.visuals = [replace(v, geometry=rebase(v.geometry)) for v in link.visuals]
        link.collisions = [replace(c, geometry=rebase(c.geometry)) for c in link.collisions]
    return model
