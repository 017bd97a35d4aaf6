"""Mass properties from a part's mesh at a given mass (uniform density), and collision shapes
fitted to it: what the seed typed in from CAD, computed instead."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mexone.description.model import Box, Collision, Cylinder, Inertial, Mesh, Pose, Sphere
from mexone.errors import InputError
from mexone.ranges import MASS

__all__ = ["MassProperties", "mass_properties", "fit_collisions", "solid_of", "SHAPES"]

SHAPES = ("mesh", "convex hull", "box", "cylinder", "capsule", "sphere")


@dataclass(frozen=True)
class MassProperties:
    inertial: Inertial  # COM and inertia about it, in the link frame
    principal_moments: tuple[float, float, float]  # kg m^2
    principal_axes: tuple[tuple[float, float, float], ...]  # unit vectors, link frame
    from_hull: bool  # the mesh is not a closed solid: its convex hull's volume was used


def solid_of(mesh, what: str = "the part") -> tuple[object, bool]:
    """(the mesh if it encloses a volume, else its convex hull; whether the hull was used), or
    an InputError for a flat, one-triangle or collinear part: an open or inverted mesh has no
    meaningful volume and the hull is the closest solid, but a flat part has none at all."""
    if mesh.is_watertight and mesh.volume > 0:
        return mesh, False
    try:
        hull = mesh.convex_hull  # Qhull: fails on fewer than 4 points off one plane
        volume = float(hull.volume)
    except Exception:  # noqa: BLE001 - Qhull and trimesh raise many types for degenerate input
        hull, volume = None, 0.0
    scale = float(np.max(mesh.extents)) if len(mesh.vertices) else 0.0
    if hull is None or not np.isfinite(volume) or volume <= 1e-12 * scale**3:
        raise InputError(f"{what} is flat: it encloses no volume to compute a mass or inertia from",
                         hint="export the solid part, not a sketch or a surface")
    return hull, True


def mass_properties(mesh, mass: float, origin: np.ndarray) -> MassProperties:
    """`mesh` in metres in its geometry frame, placed in the link by `origin` (4x4)."""
    mass = MASS.check(mass, "mass", hint="type the part's mass in kg")
    solid, hull = solid_of(mesh)
    solid = solid.copy()
    solid.density = mass / solid.volume
    rot = origin[:3, :3]
    com = origin[:3, :3] @ solid.center_mass + origin[:3, 3]
    tensor = rot @ solid.moment_inertia @ rot.T  # about the COM, axes of the link frame
    tensor = (tensor + tensor.T) / 2
    moments, vectors = np.linalg.eigh(tensor)
    inertia = (tensor[0, 0], tensor[0, 1], tensor[0, 2], tensor[1, 1], tensor[1, 2], tensor[2, 2])
    return MassProperties(
        Inertial(float(mass), tuple(float(v) for v in inertia), Pose(tuple(float(v) for v in com))),
        tuple(float(m) for m in moments), tuple(tuple(float(x) for x in v) for v in vectors.T), hull)


def fit_collisions(mesh, shape: str, origin: np.ndarray, mesh_ref: Mesh | None = None,
                   hull_ref: Mesh | None = None) -> list[Collision]:
    """Collision elements (link frame) of `shape` fitted around `mesh` (metres, placed by
    `origin`). A capsule is a cylinder and two spheres (URDF and SDF 1.6 have no capsule)."""
    def placed(local: np.ndarray) -> Pose:
        return Pose.from_matrix(origin @ local)

    if shape == "mesh":
        return [Collision(mesh_ref, Pose.from_matrix(origin))]
    if shape == "convex hull":
        return [Collision(hull_ref, Pose.from_matrix(origin))]
    if shape == "box":
        obb = mesh.bounding_box_oriented
        return [Collision(Box(tuple(float(v) for v in obb.primitive.extents)),
                          placed(obb.primitive.transform))]
    if shape == "sphere":
        ball = mesh.bounding_sphere
        return [Collision(Sphere(float(ball.primitive.radius)),
                          placed(ball.primitive.transform))]
    if shape in ("cylinder", "capsule"):
        cyl = mesh.bounding_cylinder
        radius, height = float(cyl.primitive.radius), float(cyl.primitive.height)
        frame = cyl.primitive.transform
        if shape == "cylinder":
            return [Collision(Cylinder(radius, height), placed(frame))]
        length = max(height - 2 * radius, 1e-4)  # the caps' centres, inside the cylinder's ends
        out = [Collision(Cylinder(radius, length), placed(frame), name="capsule_body")]
        for sign, label in ((1, "capsule_top"), (-1, "capsule_bottom")):
            end = frame.copy()
            end[:3, 3] = frame[:3, 3] + sign * frame[:3, 2] * length / 2
            out.append(Collision(Sphere(radius), placed(end), name=label))
        return out
    raise InputError(f"unknown collision shape {repr(shape)[:80]}", hint=f"one of: {', '.join(SHAPES)}")
