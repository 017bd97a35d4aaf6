"""Finding and loading the mesh files a model names (package://, model://, file://, paths).

MuJoCo's own URDF importer cannot resolve ``package://``; ROS finds packages through
``package.xml`` files on ROS_PACKAGE_PATH, Gazebo finds ``model://`` through GAZEBO_MODEL_PATH.
We do the same, and also look upward from the model file, which is where a student's
catkin package or Gazebo model folder usually is.

STL (binary or ASCII), what robots ship, is read here with numpy into `Triangles`; other formats
(OBJ, DAE, ...) through trimesh. Importing trimesh costs a process ~65 MB (it brings scipy and
networkx): a student's lab, which only draws and bounds its meshes, would pay it for nothing
(docs/DECISIONS.md; 20 labs on one machine are 1.3 GB).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
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

__all__ = ["resolve_mesh", "load_mesh", "read_triangles", "Triangles", "geometry_bounds"]


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


@dataclass(frozen=True)
class Triangles:
    """A triangle mesh as arrays, in the file's own units: what drawing and bounds need."""

    vertices: np.ndarray  # (n, 3) float64
    faces: np.ndarray  # (m, 3) int64, indices into vertices

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3): the lower and upper corners of the axis-aligned box around the vertices."""
        return np.array([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    def scaled(self, scale: Sequence[float] | float) -> Triangles:
        """Scaled per axis; a mirroring scale reverses each face's winding (as trimesh does), so
        the outside stays outside."""
        factors = np.broadcast_to(np.asarray(scale, dtype=float), (3,))
        faces = self.faces[:, ::-1] if np.prod(factors) < 0 else self.faces
        return Triangles(self.vertices * factors, faces)


_STL_RECORD = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])


def _stl(data: bytes) -> Triangles | None:
    """A binary or ASCII STL's triangles, as trimesh reads them (three vertices per face, none
    merged); None if the bytes are neither (then trimesh says what is wrong)."""
    if len(data) >= 84:
        count = int(np.frombuffer(data, "<u4", 1, 80)[0])
        if len(data) == 84 + _STL_RECORD.itemsize * count:  # binary (even if it starts "solid")
            corners = np.frombuffer(data, _STL_RECORD, count, 84)["corners"]
            vertices = corners.reshape(-1, 3).astype(np.float64)
            return Triangles(vertices, np.arange(len(vertices), dtype=np.int64).reshape(-1, 3))
    if not data.lstrip().lower().startswith(b"solid"):
        return None
    words = data.lower().split()
    at = [i for i, word in enumerate(words) if word == b"vertex"]
    try:
        vertices = np.array([words[i + 1:i + 4] for i in at], dtype=np.float64).reshape(-1, 3)
    except ValueError:
        return None
    if len(vertices) == 0 or len(vertices) % 3:
        return None
    return Triangles(vertices, np.arange(len(vertices), dtype=np.int64).reshape(-1, 3))


@lru_cache(maxsize=256)
def _read(path: str, mtime: float) -> Triangles:
    if path.lower().endswith(".stl"):
        with open(path, "rb") as stream:
            found = _stl(stream.read())
        if found is not None and len(found.faces):
            return found
    mesh = _load(path, mtime)  # any other format, or an STL only trimesh can make sense of
    return Triangles(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64))


def read_triangles(path: Path) -> Triangles:
    """The mesh at path as `Triangles` (cached; reloaded if the file changes). STL without
    trimesh; the same vertices and faces as `load_mesh` gives."""
    _vet(path)
    return _read(str(path), path.stat().st_mtime)


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


def _vet(path: Path) -> None:
    if not path.exists():
        raise ModelError(f"mesh file '{path}' does not exist", hint="check the filename and path")
    try:
        vet_regular_file(path)
    except InputError as exc:  # a FIFO would block trimesh forever
        raise ModelError(f"mesh file '{path}' {exc.what}", hint=exc.hint) from None


def load_mesh(path: Path) -> trimesh.Trimesh:
    """The trimesh.Trimesh in the file's own units (cached; reloaded if the file changes): for
    editing. Drawing and bounds need only `read_triangles`, which spares importing trimesh."""
    _vet(path)
    return _load(str(path), path.stat().st_mtime)


def geometry_bounds(geometry: Geometry, base_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned (lower, upper) corners in the geometry's own frame, scaled, in metres."""
    match geometry:
        case Box() | Cylinder() | Sphere():
            half = geometry.half_extents()
            return -half, half
        case Mesh(filename, scale):
            mesh = read_triangles(resolve_mesh(filename, base_dir))
            corners = mesh.bounds * np.asarray(scale)
            return corners.min(axis=0), corners.max(axis=0)
    raise TypeError(geometry)
