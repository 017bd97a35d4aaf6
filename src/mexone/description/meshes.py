"""Finding and loading the mesh files a model names (package://, model://, file://, paths).

MuJoCo's own URDF importer cannot resolve ``package://``; ROS finds packages through
``package.xml`` files on ROS_PACKAGE_PATH, Gazebo finds ``model://`` through GAZEBO_MODEL_PATH.
We do the same, and also look upward from the model file, which is where a student's
catkin package or Gazebo model folder usually is.
"""

from __future__ import annotations

import os
import re
from functools import lru_cache
from pathlib import Path

import numpy as np

from mexone.description.model import Box, Cylinder, Geometry, Mesh, Sphere
from mexone.errors import ModelError

__all__ = ["resolve_mesh", "load_mesh", "geometry_bounds"]
_PKG_NAME = re.compile(rb"<name>\s*([^<\s]+)\s*</name>")


def _package_name(folder: Path) -> str | None:
    manifest = folder / "package.xml"
    if not manifest.is_file():
        return None
    found = _PKG_NAME.search(manifest.read_bytes())
    return found.group(1).decode() if found else None


def _search_roots(base_dir: Path, env: str) -> list[Path]:
    roots = [base_dir, *base_dir.parents]
    roots += [Path(p) for p in os.environ.get(env, "").split(os.pathsep) if p]
    return roots


def _find_package(name: str, base_dir: Path) -> Path | None:
    for folder in _search_roots(base_dir, "ROS_PACKAGE_PATH"):
        if _package_name(folder) == name or (folder.name == name and folder.is_dir()):
            return folder
        candidate = folder / name
        if candidate.is_dir():
            return candidate
    return None


def _find_model(name: str, base_dir: Path) -> Path | None:
    for folder in _search_roots(base_dir, "GAZEBO_MODEL_PATH"):
        if folder.name == name and (folder / "model.config").is_file():
            return folder
        if (folder / name / "model.config").is_file():
            return folder / name
    return None


def resolve_mesh(filename: str, base_dir: Path) -> Path:
    """The file a mesh reference means; raises ModelError naming what was searched."""
    for scheme, finder, env in (("package://", _find_package, "ROS_PACKAGE_PATH"),
                                ("model://", _find_model, "GAZEBO_MODEL_PATH")):
        if filename.startswith(scheme):
            name, _, rest = filename[len(scheme):].partition("/")
            folder = finder(name, base_dir)
            if folder is None:
                raise ModelError(f"mesh '{filename}': cannot find '{name}'",
                                 hint=f"put the model inside that package/model folder or add its "
                                      f"parent to {env}")
            return folder / rest
    if filename.startswith("file://"):
        return Path(filename[len("file://"):])
    path = Path(filename)
    return path if path.is_absolute() else base_dir / path


@lru_cache(maxsize=256)
def _load(path: str, mtime: float):
    import trimesh  # slow to import; only meshes need it

    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for bad files
        raise ModelError(f"mesh '{path}' is unreadable: {exc}",
                         hint="export it again as binary STL, OBJ or DAE") from None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise ModelError(f"mesh '{path}' holds no triangles", hint="export it again as STL or OBJ")
    return loaded


def load_mesh(path: Path):
    """The trimesh.Trimesh in the file's own units (cached; reloaded if the file changes)."""
    if not path.is_file():
        raise ModelError(f"mesh file '{path}' does not exist", hint="check the filename and path")
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
