"""Finding and loading the mesh files a model names (package://, model://, file://, paths).

MuJoCo's own URDF importer cannot resolve ``package://``; ROS finds packages through
``package.xml`` files on ROS_PACKAGE_PATH, Gazebo finds ``model://`` through GAZEBO_MODEL_PATH.
We do the same, and also look upward from the model file, which is where a student's
catkin package or Gazebo model folder usually is.
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mexone.description.model import Box, Cylinder, Geometry, Mesh, Sphere
from mexone.description.packages import require_package
from mexone.errors import InputError, ModelError
from mexone.inputs import vet_regular_file

if TYPE_CHECKING:
    import trimesh

__all__ = ["resolve_mesh", "load_mesh", "geometry_bounds"]


def _find_model(name: str, base_dir: Path) -> Path | None:
    roots = [base_dir, *base_dir.parents]
    roots += [Path(p) for p in os.environ.get("GAZEBO_MODEL_PATH", "").split(os.pathsep) if p]
    for folder in roots:
        if folder.name == name and (folder / "model.config").is_file():
            return folder
        if (folder / name / "model.config").is_file():
            return folder / name
    return None


def resolve_mesh(filename: str, base_dir: Path) -> Path:
    """The file a mesh reference means; raises ModelError naming what was searched."""
    if filename.startswith("package://"):
        name, _, rest = filename[len("package://"):].partition("/")
        return require_package(name, base_dir, f"mesh '{filename}'") / rest
    if filename.startswith("model://"):
        name, _, rest = filename[len("model://"):].partition("/")
        folder = _find_model(name, base_dir)
        if folder is None:
            raise ModelError(f"mesh '{filename}': cannot find model '{name}'",
                             hint="put the model inside that model folder or add its parent to "
                                  "GAZEBO_MODEL_PATH")
        return folder / rest
    if filename.startswith("file://"):
        return Path(filename[len("file://"):])
    path = Path(filename)
    return path if path.is_absolute() else base_dir / path


@lru_cache(maxsize=256)
def _load(path: str, mtime: float) -> trimesh.Trimesh:
    import trimesh  # slow to import; only meshes need it

    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for bad files
        raise ModelError(f"mesh '{path}' is unreadable: {exc}",
                         hint="export it again as binary STL, OBJ or DAE") from None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise ModelError(f"mesh '{path}' holds no triangles", hint="export it again as STL or OBJ")
    return loaded


def load_mesh(path: Path) -> trimesh.Trimesh:
    """The trimesh.Trimesh in the file's own units (cached; reloaded if the file changes)."""
    if not path.exists():
        raise ModelError(f"mesh file '{path}' does not exist", hint="check the filename and path")
    try:
        vet_regular_file(path)
    except InputError as exc:  # a FIFO would block trimesh forever
        raise ModelError(f"mesh file '{path}' {exc.what}", hint=exc.hint) from None
    return _load(str(path), path.stat().st_mtime)


def geometry_bounds(geometry: Geometry, base_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned (lower, upper) corners in the geometry's own frame, scaled, in metres."""
    match geometry:
        case Box() | Cylinder() | Sphere():
            half = geometry.half_extents()
            return -half, half
        case Mesh(filename, scale):
            mesh = load_mesh(resolve_mesh(filename, base_dir))
            corners = mesh.bounds * np.asarray(scale)
            return corners.min(axis=0), corners.max(axis=0)
    raise TypeError(geometry)
