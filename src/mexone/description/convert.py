"""Rewrite a RobotModel for another file: mesh references made valid from the new place."""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

from mexone.description.model import Mesh, Pose, RobotModel

__all__ = ["rebase_meshes", "merge_massless"]

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


def merge_massless(model: RobotModel) -> tuple[RobotModel, list[str]]:
    """The model without its massless links on fixed joints (IMU and camera frames): their
    visuals, collisions and child joints move onto the parent, as sdformat's URDF reader merges
    them. For SDF, which has no massless link (a link without <inertial> weighs 1 kg there).
    Returns the new model and the merged links' names; the root stays."""
    links = {name: replace(link) for name, link in model.links.items()}
    joints = {name: replace(joint) for name, joint in model.joints.items()}
    merged: list[str] = []
    for name in reversed(model.walk()):  # leaves first, so chains of frames fold up
        joint = next((j for j in joints.values() if j.child == name), None)
        link = links[name]
        if joint is None or joint.type != "fixed" or link.inertial is not None \
                or joint.parent == "world" or name in model.gazebo_links:
            continue
        parent, offset = links[joint.parent], joint.origin.matrix
        parent.visuals = [*parent.visuals, *(replace(v, origin=Pose.from_matrix(offset @ v.origin.matrix))
                                             for v in link.visuals)]
        parent.collisions = [*parent.collisions, *(replace(
            c, origin=Pose.from_matrix(offset @ c.origin.matrix)) for c in link.collisions)]
        for child in joints.values():
            if child.parent == name:
                child.parent = joint.parent
                child.origin = Pose.from_matrix(offset @ child.origin.matrix)
        del joints[joint.name], links[name]
        merged.append(name)
    if not merged:
        return model, []
    return replace(model, links=links, joints=joints,
                   transmissions=[t for t in model.transmissions if t.joint in joints]), merged
