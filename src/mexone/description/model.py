"""RobotModel: the one in-memory description every reader produces and every layer consumes.

It holds what a URDF holds (links, joints, transmissions) plus the ``<gazebo>`` extensions the
seed relies on, with the source line of each element so findings and errors can point at it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mexone.description.findings import Finding
from mexone.description.transforms import make_transform, split_transform

if TYPE_CHECKING:
    from mexone.description.sensors import SensorSpec

__all__ = [
    "Pose",
    "Box",
    "Cylinder",
    "Sphere",
    "Mesh",
    "Geometry",
    "Inertial",
    "Visual",
    "Collision",
    "Link",
    "Limit",
    "Dynamics",
    "Mimic",
    "Joint",
    "Transmission",
    "GazeboLink",
    "RobotModel",
    "JOINT_TYPES",
    "INERTIA_KEYS",
    "MOVING_JOINT_TYPES",
]

INERTIA_KEYS = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
MOVING_JOINT_TYPES = ("revolute", "continuous", "prismatic")


@dataclass(frozen=True)
class Pose:
    xyz: tuple[float, ...] = (0.0, 0.0, 0.0)
    rpy: tuple[float, ...] = (0.0, 0.0, 0.0)

    @property
    def matrix(self) -> np.ndarray:
        return make_transform(self.xyz, self.rpy)

    @staticmethod
    def from_matrix(mat: np.ndarray) -> Pose:
        xyz, rpy = split_transform(mat)
        return Pose(tuple(float(v) for v in xyz), tuple(float(v) for v in rpy))

    def is_identity(self) -> bool:
        return not any(self.xyz) and not any(self.rpy)


@dataclass(frozen=True)
class Box:
    size: tuple[float, ...]

    def half_extents(self) -> np.ndarray:
        return np.asarray(self.size) / 2


@dataclass(frozen=True)
class Cylinder:
    """Axis along the geometry frame's z, as in URDF and SDF."""

    radius: float
    length: float

    def half_extents(self) -> np.ndarray:
        return np.array([self.radius, self.radius, self.length / 2])


@dataclass(frozen=True)
class Sphere:
    radius: float

    def half_extents(self) -> np.ndarray:
        return np.full(3, self.radius)


@dataclass(frozen=True)
class Mesh:
    filename: str  # as written in the file: package://, model://, file://, absolute or relative
    scale: tuple[float, ...] = (1.0, 1.0, 1.0)


Geometry = Box | Cylinder | Sphere | Mesh


@dataclass(frozen=True)
class Inertial:
    mass: float
    inertia: tuple[float, ...]  # ixx ixy ixz iyy iyz izz
    origin: Pose = Pose()

    @property
    def tensor(self) -> np.ndarray:
        """Inertia tensor about the COM, in the inertial frame."""
        ixx, ixy, ixz, iyy, iyz, izz = self.inertia
        return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


@dataclass(frozen=True)
class Visual:
    geometry: Geometry
    origin: Pose = Pose()
    name: str | None = None
    material: str | None = None
    rgba: tuple[float, ...] | None = None
    line: int | None = None


@dataclass(frozen=True)
class Collision:
    geometry: Geometry
    origin: Pose = Pose()
    name: str | None = None
    line: int | None = None


@dataclass
class Link:
    name: str
    inertial: Inertial | None = None
    visuals: list[Visual] = field(default_factory=list)
    collisions: list[Collision] = field(default_factory=list)
    line: int | None = None


@dataclass(frozen=True)
class Limit:
    lower: float = 0.0
    upper: float = 0.0
    effort: float = 0.0
    velocity: float = 0.0


@dataclass(frozen=True)
class Dynamics:
    damping: float = 0.0
    friction: float = 0.0
    armature: float = 0.0  # kg m^2 (rotor inertia through the gearbox): <dynamics armature="...">


@dataclass(frozen=True)
class Mimic:
    """URDF <mimic>: this joint's position = multiplier * joint's position + offset."""

    joint: str
    multiplier: float = 1.0
    offset: float = 0.0
    line: int | None = None


@dataclass
class Joint:
    name: str
    type: str
    parent: str
    child: str
    origin: Pose = Pose()
    axis: tuple[float, ...] = (1.0, 0.0, 0.0)
    limit: Limit | None = None
    dynamics: Dynamics = Dynamics()
    line: int | None = None
    mimic: Mimic | None = None

    @property
    def moving(self) -> bool:
        return self.type in MOVING_JOINT_TYPES


@dataclass(frozen=True)
class Transmission:
    name: str
    joint: str
    type: str = "transmission_interface/SimpleTransmission"
    hardware_interface: str = "hardware_interface/EffortJointInterface"
    actuator: str | None = None
    mechanical_reduction: float = 1.0
    line: int | None = None


@dataclass
class GazeboLink:
    """The ``<gazebo reference="link">`` properties Gazebo 7 reads (None: Gazebo's default)."""

    self_collide: bool | None = None
    mu1: float | None = None
    mu2: float | None = None
    kp: float | None = None
    kd: float | None = None
    max_vel: float | None = None
    min_depth: float | None = None
    material: str | None = None
    line: int | None = None


@dataclass
class RobotModel:
    name: str
    links: dict[str, Link]
    joints: dict[str, Joint]
    transmissions: list[Transmission] = field(default_factory=list)
    gazebo_links: dict[str, GazeboLink] = field(default_factory=dict)
    # joint dynamics given in <gazebo reference="joint"> (Listing 3.11); they override <dynamics>
    gazebo_joints: dict[str, Dynamics] = field(default_factory=dict)
    # gazebo_ros_control plugin's robotNamespace, e.g. "/mex_rb"; None if no plugin
    ros_namespace: str | None = None
    # sensors declared the Gazebo way (<gazebo><sensor>, gazebo_ros sensor plugins), in file order
    sensors: list[SensorSpec] = field(default_factory=list)
    source: Path | None = None
    # What the reader noticed but could still build (duplicated names, dangling references)
    reader_findings: list[Finding] = field(default_factory=list)

    # ----- tree -----------------------------------------------------------------------------
    @cached_property
    def child_joints(self) -> dict[str, list[Joint]]:
        """Joints leaving each link, in file order."""
        out: dict[str, list[Joint]] = {name: [] for name in self.links}
        for joint in self.joints.values():
            out.setdefault(joint.parent, []).append(joint)
        return out

    @cached_property
    def parent_joint(self) -> dict[str, Joint]:
        """The joint whose child is this link (the first one, if a loop gives it several)."""
        out: dict[str, Joint] = {}
        for joint in self.joints.values():
            out.setdefault(joint.child, joint)
        return out

    @property
    def roots(self) -> list[str]:
        return [name for name in self.links if name not in self.parent_joint]

    @property
    def root(self) -> str:
        roots = self.roots
        return roots[0] if roots else next(iter(self.links))

    @property
    def fixed_to_world(self) -> bool:
        """True when the URDF welds its root to a ``world`` link (the seed's Fig. 4.5)."""
        return self.root == "world"

    @property
    def base_link(self) -> str:
        """The first real body: the root, or the child of the world joint."""
        if self.fixed_to_world:
            return self.child_joints["world"][0].child
        return self.root

    def walk(self, start: str | None = None) -> list[str]:
        """Link names depth first from `start` (default: the root), children in file order; each
        link once: the subtree below `start`."""
        order: list[str] = []
        seen: set[str] = set()
        stack = [self.root if start is None else start]
        while stack:
            name = stack.pop()
            if name in seen:
                continue
            seen.add(name)
            order.append(name)
            stack.extend(j.child for j in reversed(self.child_joints.get(name, [])))
        return order

    @cached_property
    def depth(self) -> int:
        """Links on the longest path from the root (a 'world' link not counted)."""
        depths = {self.root: 0 if self.fixed_to_world else 1}
        for name in self.walk():
            for joint in self.child_joints.get(name, []):
                depths.setdefault(joint.child, depths[name] + 1)
        return max(depths.values(), default=0)

    @cached_property
    def link_frames(self) -> dict[str, np.ndarray]:
        """World transform of every link frame with all joints at zero (the home pose)."""
        frames = {self.root: np.eye(4)}
        for name in self.walk():
            for joint in self.child_joints.get(name, []):
                if joint.child not in frames:
                    frames[joint.child] = frames[name] @ joint.origin.matrix
        return frames

    # ----- actuation ------------------------------------------------------------------------
    @property
    def moving_joints(self) -> list[Joint]:
        return [j for j in self.joints.values() if j.moving]

    def transmission_for(self, joint: str) -> Transmission | None:
        return next((t for t in self.transmissions if t.joint == joint), None)

    @property
    def actuated_joints(self) -> list[Joint]:
        """Moving joints that have a transmission, in file order."""
        with_tx = {t.joint for t in self.transmissions}
        return [j for j in self.moving_joints if j.name in with_tx]

    def joint_dynamics(self, joint: str) -> Dynamics:
        """Gazebo reference dynamics win over URDF <dynamics>, as in gazebo's URDF parser."""
        return self.gazebo_joints.get(joint, self.joints[joint].dynamics)

    @property
    def mass(self) -> float:
        return sum(link.inertial.mass for link in self.links.values() if link.inertial)

    @property
    def base_dir(self) -> Path:
        return self.source.resolve().parent if self.source else Path.cwd()
