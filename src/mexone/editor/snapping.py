"""Where a joint frame can snap on a part: face centres, edge midpoints and hole axes -- the
seed's "well-centred" joint, found instead of eyeballed.

A hole axis is a closed loop of a flat face's boundary that is a circle (every vertex the same
distance from the loop's centre): a bore, a pin, a shaft's end. Its axis is the face's normal.

Magnetic snapping (the editor's joint gizmo, dropped): the nearest candidate within SNAP_RADIUS
of the drop wins; further from all of them nothing snaps. A hole counts from the disc it bounds,
so a drop anywhere in a hole's mouth takes the hole, never a midpoint of its tessellated rim.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["Snap", "snap_points", "KINDS", "SNAP_RADIUS", "snap_distance", "nearest_snap"]

KINDS = ("hole axis", "face centre", "edge midpoint")
_ROUND = 0.03  # a loop is a circle when its radii differ by less than 3% of their mean
_MIN_LOOP = 8  # vertices: a hexagonal hole is not a bore
_SHARP = np.radians(30)  # an edge between faces meeting at more than this is an edge to snap to
_MAX_EACH = 200  # candidates per kind (a scanned mesh has thousands of tiny faces)
# A dropped gizmo snaps within 15 mm: about 15 px at the editor's default view (0.7 m away, a
# 700 px high page), the reach of an aimed drop; under half the 20 mm or more between the holes
# of hand-sized parts (a bore's two ends, a link's two joints), so a drop picks one hole, and a
# drop a part's width away from every candidate stays free.
SNAP_RADIUS = 0.015


@dataclass(frozen=True)
class Snap:
    kind: str  # one of KINDS
    point: tuple[float, float, float]  # in the mesh's frame, metres
    axis: tuple[float, float, float]  # unit: the hole's axis, the face's normal, the edge's direction
    size: float  # the hole's radius, the face's area or the edge's length (ranks candidates)

    @property
    def label(self) -> str:
        x, y, z = (v * 1000 for v in self.point)
        what = {"hole axis": f"r {self.size * 1000:.1f} mm", "face centre": f"{self.size * 1e6:.0f} mm2",
                "edge midpoint": f"{self.size * 1000:.1f} mm long"}[self.kind]
        return f"{self.kind} ({x:.1f}, {y:.1f}, {z:.1f}) mm, {what}"


def _loops(edges: np.ndarray) -> list[list[int]]:
    """Closed vertex loops from a set of boundary edges (each vertex on two edges)."""
    neighbours: dict[int, list[int]] = {}
    for a, b in edges:
        neighbours.setdefault(int(a), []).append(int(b))
        neighbours.setdefault(int(b), []).append(int(a))
    seen: set[int] = set()
    loops = []
    for start in neighbours:
        if start in seen or len(neighbours[start]) != 2:
            continue
        loop, prev, here = [start], None, start
        seen.add(start)
        while True:
            options = [n for n in neighbours[here] if n != prev]
            if not options or len(neighbours[here]) != 2:
                loop = []
                break
            prev, here = here, options[0]
            if here == start:
                break
            if here in seen:
                loop = []
                break
            seen.add(here)
            loop.append(here)
        if len(loop) >= _MIN_LOOP:
            loops.append(loop)
    return loops


def _holes(mesh) -> list[Snap]:
    out = []
    for normal, boundary in zip(mesh.facets_normal, mesh.facets_boundary, strict=True):
        for loop in _loops(boundary):
            pts = mesh.vertices[loop]
            centre = pts.mean(axis=0)
            radii = np.linalg.norm(pts - centre, axis=1)
            if radii.mean() > 0 and radii.std() < _ROUND * radii.mean():
                out.append(Snap("hole axis", tuple(float(v) for v in centre),
                                tuple(float(v) for v in normal), float(radii.mean())))
    return out


def _faces(mesh) -> list[Snap]:
    out = []
    for facet, normal in zip(mesh.facets, mesh.facets_normal, strict=True):
        tri_area = mesh.area_faces[facet]
        centre = (mesh.triangles_center[facet] * tri_area[:, None]).sum(axis=0) / tri_area.sum()
        out.append(Snap("face centre", tuple(float(v) for v in centre),
                        tuple(float(v) for v in normal), float(tri_area.sum())))
    return out


def _edges(mesh) -> list[Snap]:
    sharp = mesh.face_adjacency_angles > _SHARP
    edges = mesh.face_adjacency_edges[sharp]
    a, b = mesh.vertices[edges[:, 0]], mesh.vertices[edges[:, 1]]
    lengths = np.linalg.norm(b - a, axis=1)
    out = []
    for p, q, length in zip(a, b, lengths, strict=True):
        if length > 0:
            out.append(Snap("edge midpoint", tuple(float(v) for v in (p + q) / 2),
                            tuple(float(v) for v in (q - p) / length), float(length)))
    return out


def snap_points(mesh, kinds=KINDS) -> list[Snap]:
    """Candidates on `mesh` (metres, its own frame), largest first within each kind, holes
    first; coincident holes (the two ends of one bore) kept once per end."""
    mesh = mesh.copy()
    mesh.merge_vertices()  # STL repeats each corner per triangle: faces must share them
    out: list[Snap] = []
    for kind, find in (("hole axis", _holes), ("face centre", _faces), ("edge midpoint", _edges)):
        if kind in kinds:
            found = sorted(find(mesh), key=lambda s: -s.size)[:_MAX_EACH]
            out += found
    return out


def snap_distance(snap: Snap, point, axis, at) -> float:
    """How far `at` is from the candidate at (point, axis) (all in one frame): from a hole, the
    distance to the disc of its mouth; from any other candidate, to its point."""
    d = np.asarray(at, dtype=float) - np.asarray(point, dtype=float)
    if snap.kind != "hole axis":
        return float(np.linalg.norm(d))
    n = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    along = float(d @ n)
    across = float(np.linalg.norm(d - along * n))
    return float(np.hypot(along, max(0.0, across - snap.size)))


def nearest_snap(candidates: Sequence[tuple[Snap, np.ndarray, np.ndarray]], at,
                 radius: float = SNAP_RADIUS) -> int | None:
    """Index of the candidate (snap, point, axis) nearest `at` within `radius`, else None; on a
    tie the earlier wins (snap_points lists holes first)."""
    best, best_distance = None, math.inf
    for i, (snap, point, axis) in enumerate(candidates):
        distance = snap_distance(snap, point, axis, at)
        if distance <= radius and distance < best_distance:
            best, best_distance = i, distance
    return best
