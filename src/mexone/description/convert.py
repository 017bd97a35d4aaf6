"""Rewrite a RobotModel for another file: mesh references made valid from the new place."""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

from mexone.description.model import GazeboLink, Geometry, Mesh, Pose, RobotModel

__all__ = ["rebase_meshes", "merge_massless"]

_SCHEMES = ("package://", "model://", "file://")


def rebase_meshes(model: RobotModel, out_dir: Path) -> RobotModel:
    """Relative mesh paths are relative to the model file; keep them pointing at the same
    files when the model is written into another folder. URIs and absolute paths stay."""

    def rebase(geometry: Geometry) -> Geometry:
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
    A sensor on a merged link moves onto the parent at the same place (a frame it names as its
    frame_id stays a name, as sdformat lumps it). Returns the new model and the merged links'
    names; the root and links whose <gazebo> block sets properties of their own stay."""
    links = {name: replace(link) for name, link in model.links.items()}
    joints = {name: replace(joint) for name, joint in model.joints.items()}
    merged: list[str] = []
    sensors = list(model.sensors)
    for name in reversed(model.walk()):  # leaves first, so chains of frames fold up
        joint = next((j for j in joints.values() if j.child == name), None)
        link = links[name]
        if joint is None or joint.type != "fixed" or link.inertial is not None \
                or joint.parent == "world" or _has_properties(model, name):
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
        sensors = [replace(x, link=joint.parent, pose=Pose.from_matrix(offset @ x.pose.matrix))
                   if x.link == name else x for x in sensors]
    if not merged:
        return model, []
    return replace(model, links=links, joints=joints, sensors=sensors,
                   gazebo_links={k: v for k, v in model.gazebo_links.items() if k in links},
                   transmissions=[t for t in model.transmissions if t.joint in joints]), merged


def _has_properties(model: RobotModel, link: str) -> bool:
    """Whether the link's <gazebo> block says more than where a sensor sits (friction, colour):
    those would be lost in a merge."""
    props = model.gazebo_links.get(link)
    return props is not None and replace(props, line=None) != GazeboLink()
