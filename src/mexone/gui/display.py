"""Display meshes: a robot's visual meshes simplified to a triangle budget for the browser.

A 30-link robot with full-resolution meshes sent ~35 MB over the websocket and drew nothing
for 20 s. The page only needs what a person sees: each mesh is decimated (quadric error, via
trimesh and fast-simplification) to its share of `TRIANGLE_BUDGET`, in proportion to its size
in triangles, and the result cached on disk by file content and target, so the second start is
instant. Physics, `check` and exports keep the full meshes (description/meshes.py). Meshes are
`Triangles` (arrays): trimesh is imported only to simplify, the first time a big robot is shown.
"""

from __future__ import annotations

import hashlib
import logging
import os
from pathlib import Path

import numpy as np

from mexone import files
from mexone.description.meshes import Triangles, read_triangles, resolve_mesh
from mexone.description.model import Mesh, RobotModel

__all__ = ["TRIANGLE_BUDGET", "display_budgets", "display_mesh", "cache_dir"]

TRIANGLE_BUDGET = 80_000  # per robot: ~3 MB to the page, first frame within a second or two
_MIN_FACES = 200  # no mesh is cut below this (a small part keeps its shape)
_log = logging.getLogger("mexone.gui")


def cache_dir() -> Path:
    """The simplified display meshes' folder in mexone's cache (`files.cache_dir`)."""
    return files.cache_dir("meshes")


def _uses(robot: RobotModel) -> dict[str, tuple[Path, int]]:
    """filename as written -> (file, how many visuals draw it)."""
    out: dict[str, tuple[Path, int]] = {}
    for link in robot.links.values():
        for vis in link.visuals:
            if isinstance(vis.geometry, Mesh):
                name = vis.geometry.filename
                path, uses = out.get(name, (None, 0))
                out[name] = (path or resolve_mesh(name, robot.base_dir), uses + 1)
    return out


def display_budgets(robot: RobotModel, budget: int = TRIANGLE_BUDGET) -> dict[str, int | None]:
    """Faces each visual mesh (by filename as written) may keep; None: keep them all. Every
    visual that draws a mesh counts: each is sent to the page."""
    uses = _uses(robot)
    faces = {name: len(read_triangles(path).faces) for name, (path, _) in uses.items()}
    total = sum(faces[name] * n for name, (_, n) in uses.items())
    if total <= budget:
        return dict.fromkeys(faces)
    share = budget / total
    return {name: None if n * share >= n else max(_MIN_FACES, int(n * share))
            for name, n in faces.items()}


def display_mesh(path: Path, faces: int | None) -> Triangles:
    """The mesh at path with at most `faces` triangles (cached on disk); the file's own if None
    or already small enough."""
    mesh = read_triangles(path)
    if faces is None or len(mesh.faces) <= faces:
        return mesh
    digest = hashlib.sha1(path.read_bytes()).hexdigest()[:20]
    cached = cache_dir() / f"{digest}-{faces}.npz"
    try:
        with np.load(cached) as stored:
            return Triangles(stored["vertices"].astype(np.float64), stored["faces"].astype(np.int64))
    except (OSError, KeyError, ValueError):
        pass
    try:
        import trimesh  # only here: its import costs ~65 MB (description/meshes.py)

        whole = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
        simplified = whole.simplify_quadric_decimation(face_count=faces)
        small = Triangles(np.asarray(simplified.vertices, np.float64),
                          np.asarray(simplified.faces, np.int64))
    except Exception as exc:  # noqa: BLE001 - a mesh the decimator cannot take is drawn whole
        _log.warning(f"could not simplify '{path}' for display ({exc}); drawing it whole")
        return mesh
    try:
        cached.parent.mkdir(parents=True, exist_ok=True)
        temporary = cached.with_suffix(f".{os.getpid()}.tmp.npz")
        np.savez(temporary, vertices=np.asarray(small.vertices, np.float32),
                 faces=np.asarray(small.faces, np.int32))
        os.replace(temporary, cached)
    except OSError:  # a read-only home: simplify again next time
        pass
    return small
