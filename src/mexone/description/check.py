"""`mexone check`: the kinematic tree as check_urdf prints it, then a physics lint.

Each rule is a function yielding Findings; they catch what the seed found only by watching
Gazebo explode (its Figs. 4.6-4.8): misplaced centres of mass, overlarge inertias, misplaced
collisions and joints, missing meshes, meaningless limits.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mexone.description.findings import Finding
from mexone.description.meshes import geometry_bounds
from mexone.description.model import GazeboLink, Geometry, Inertial, Joint, Link, Mesh, Pose, RobotModel
from mexone.errors import MexoneError
from mexone.ranges import MASS, MOMENT, number_text

__all__ = ["check_model", "format_tree", "summary", "RULES", "implausible_inertial", "inertial_problem",
           "surface_problem", "mimic_problem", "UNSIMULATED_JOINTS", "MAX_LINK_MASS", "MAX_MOMENT",
           "MAX_DENSITY", "MAX_DEPTH"]

# Tolerances, each with its reason
_COM_TOL = 0.002  # m: COM this far outside every geometry box is outside the link
_INERTIA_SLACK = 1.5  # a moment above 1.5 m r^2 needs mass beyond the link's furthest corner
_MISMATCH_MIN = 0.01  # m: collision/visual centres may differ by this much however small
_MISMATCH_FRACTION = 0.25  # ...or by this fraction of the visual's diagonal
_JOINT_FAR_MIN = 0.02  # m
_JOINT_FAR_FRACTION = 0.2
# m: a moving joint this much further from its two parts than they are from each other is beside
# their junction (Mex-One's reconstructed joints sit within 0.025, Gazebo model-editor fixtures
# within 0.037; a frame moved 3 cm off a Mex-One shoulder or hip gives 0.06)
_JUNCTION_TOL = 0.045
_MM_EXTENT = 5.0  # m: a robot part whose mesh spans more than this is written in millimetres
_TINY_EXTENT = 0.002  # m: a scaled mesh smaller than this was probably scaled twice
_TINY_FRACTION = 0.01  # of the robot's mass: a link this light cannot change how it moves
_OVERLAP_ENOUGH = 0.5  # of the smaller box's volume: collision and visual share their place
# Beyond these a value is a typo or a wrong unit, not a robot; `mexone sim` refuses them too
MAX_LINK_MASS = MASS.high  # kg: a 100 t link (ranges.py is their home)
MAX_MOMENT = MOMENT.high  # kg m^2: 100 t at 3 m
MAX_DENSITY = 1e6  # kg/m^3 of the link's bounding box: 44x osmium
MAX_DEPTH = 1023  # links in a chain: MuJoCo nests at most 1023 bodies
UNSIMULATED_JOINTS = {
    "planar": "MuJoCo has no planar joint: build it from two prismatic joints and a revolute one",
    "floating": "only the root floats, by itself; join inner links with revolute, prismatic or "
                "fixed joints",
}


def implausible_inertial(inertial: Inertial) -> str | None:
    """A positive mass or a moment beyond what any robot link has (ranges.MASS, MOMENT), or None."""
    if inertial.mass > 0 and not MASS.contains(inertial.mass):
        side, bound = ("beyond", f"at most {MAX_LINK_MASS:.0e}") if not inertial.mass < MASS.low else \
            ("below", f"at least {MASS.low:.0e}")
        return (f"mass {number_text(inertial.mass)} kg is {side} any robot link's ({bound} kg): "
                "a typo or the wrong unit")
    if (largest := max(abs(v) for v in inertial.inertia)) > MAX_MOMENT:
        return (f"inertia {largest:.3g} kg m^2 is beyond any robot link's (at most "
                f"{MAX_MOMENT:.0e} kg m^2): a typo or the wrong unit")
    return None


def inertial_problem(inertial: Inertial) -> tuple[str, str] | None:
    """(rule code, message) of what makes an <inertial> impossible, or None: the one rule
    `mexone check` reports and the model editor refuses by."""
    if not inertial.mass > 0:
        return "mass-nonpositive", f"mass {number_text(inertial.mass)} kg: a body needs a positive mass"
    if not all(math.isfinite(v) for v in inertial.inertia):
        return "inertia-not-positive", "inertia is not finite: type six numbers"
    if (problem := implausible_inertial(inertial)) is not None:
        return "mass-implausible", problem
    moments = np.linalg.eigvalsh(inertial.tensor)
    if moments[0] <= 0:
        return ("inertia-not-positive", "inertia is not positive definite (principal moments "
                f"{', '.join(f'{m:.3g}' for m in moments)} kg m^2): every moment must be > 0; "
                "derive it from the link's shape and mass")
    if moments[0] + moments[1] < moments[2] * (1 - 1e-6):
        return ("inertia-triangle", f"principal moments {moments[0]:.3g} + {moments[1]:.3g} < "
                f"{moments[2]:.3g} break the triangle inequality: no real body has them")
    return None


def surface_problem(props: GazeboLink) -> str | None:
    """Why a link's <gazebo> contact values cannot be simulated, or None."""
    for name, value, positive, why in (
            ("mu1", props.mu1, False, "friction cannot be negative"),
            ("mu2", props.mu2, False, "friction cannot be negative"),
            ("kp", props.kp, True, "a contact without stiffness lets the link sink through"),
            ("kd", props.kd, False, "negative damping adds energy"),
            ("maxVel", props.max_vel, False, "a speed cannot be negative"),
            ("minDepth", props.min_depth, False, "a depth cannot be negative")):
        if value is not None and (value <= 0 if positive else value < 0):
            return f"<{name}> {value:g} must be {'> 0' if positive else '>= 0'}: {why}"
    return None


@dataclass(frozen=True)
class Box3:
    """An oriented box: a geometry's bounds placed in its link's frame."""

    pose: np.ndarray  # 4x4, geometry frame in link frame
    lower: np.ndarray
    upper: np.ndarray

    def corners(self) -> np.ndarray:
        pts = np.array([[x, y, z] for x in (self.lower[0], self.upper[0])
                        for y in (self.lower[1], self.upper[1])
                        for z in (self.lower[2], self.upper[2])])
        return pts @ self.pose[:3, :3].T + self.pose[:3, 3]

    def project(self, point: np.ndarray) -> np.ndarray:
        """The box's point nearest `point` (both in the link frame)."""
        local = self.pose[:3, :3].T @ (point - self.pose[:3, 3])
        return self.pose[:3, :3] @ np.clip(local, self.lower, self.upper) + self.pose[:3, 3]

    def distance(self, point: np.ndarray) -> float:
        """From `point` (link frame) to the box, 0 inside."""
        local = self.pose[:3, :3].T @ (point - self.pose[:3, 3])
        return float(np.linalg.norm(np.maximum(0, np.maximum(self.lower - local, local - self.upper))))

    def contains(self, point: np.ndarray, tol: float) -> bool:
        local = self.pose[:3, :3].T @ (point - self.pose[:3, 3])
        return bool(np.all(local >= self.lower - tol) and np.all(local <= self.upper + tol))


@dataclass
class _Context:
    model: RobotModel
    visual_boxes: dict[str, list[Box3]] = field(default_factory=dict)
    collision_boxes: dict[str, list[Box3]] = field(default_factory=dict)
    mesh_findings: list[Finding] = field(default_factory=list)

    def boxes(self, link: str) -> list[Box3]:
        return self.visual_boxes.get(link, []) + self.collision_boxes.get(link, [])


def _aabb(boxes: list[Box3]) -> tuple[np.ndarray, np.ndarray] | None:
    if not boxes:
        return None
    pts = np.vstack([b.corners() for b in boxes])
    return pts.min(axis=0), pts.max(axis=0)


def _element(kind: str, name: str) -> str:
    return f'{kind} "{name}"'


# ----- geometry gathering (and the mesh rules, which fall out of it) ---------------------------
def _gather(ctx: _Context) -> None:
    base = ctx.model.base_dir
    reported: set[str] = set()
    for link in ctx.model.links.values():
        for kind, items, store in (("visual", link.visuals, ctx.visual_boxes),
                                   ("collision", link.collisions, ctx.collision_boxes)):
            for item in items:
                box = _bounds(ctx, link, kind, item.geometry, item.origin, item.line, base, reported)
                if box is not None:
                    store.setdefault(link.name, []).append(box)


def _bounds(ctx: _Context, link: Link, kind: str, geometry: Geometry, origin: Pose,
            line: int | None, base: Path, reported: set[str]) -> Box3 | None:
    element = _element("link", link.name)
    try:
        lower, upper = geometry_bounds(geometry, base)
    except MexoneError as exc:
        if isinstance(geometry, Mesh) and geometry.filename not in reported:
            reported.add(geometry.filename)
            missing = "does not exist" in exc.what or "cannot find" in exc.what
            code = "mesh-missing" if missing else "mesh-unreadable"
            ctx.mesh_findings.append(Finding(code, "error", element,
                                             f"{kind} {exc.what} ({exc.hint})", line))
        return None
    if isinstance(geometry, Mesh) and geometry.filename not in reported:
        extent = float(np.max(upper - lower))
        scale = max(abs(s) for s in geometry.scale)
        if scale == 1.0 and extent > _MM_EXTENT:
            reported.add(geometry.filename)
            ctx.mesh_findings.append(Finding(
                "mesh-units", "error", element,
                f"{kind} mesh '{geometry.filename}' spans {extent:.0f} m at scale 1: it is written "
                'in millimetres; add scale="0.001 0.001 0.001" to the <mesh>', line))
        elif extent < _TINY_EXTENT:
            reported.add(geometry.filename)
            ctx.mesh_findings.append(Finding(
                "mesh-units", "warning", element,
                f"{kind} mesh '{geometry.filename}' spans only {extent * 1000:.2f} mm after scale "
                f"{scale:g}: is it already in metres? then drop the scale", line))
    return Box3(origin.matrix, lower, upper)


def _rule_meshes(ctx: _Context) -> Iterator[Finding]:
    yield from ctx.mesh_findings


# ----- inertial rules --------------------------------------------------------------------------
def _rule_inertial(ctx: _Context) -> Iterator[Finding]:
    moving_children = {j.child for j in ctx.model.joints.values() if j.type != "fixed"}
    floating_root = None if ctx.model.fixed_to_world else ctx.model.root
    for link in ctx.model.links.values():
        element = _element("link", link.name)
        inertial = link.inertial
        if inertial is None:
            if link.name in moving_children or link.name == floating_root:
                yield Finding("inertial-missing", "error", element,
                              "moves but has no <inertial>: Gazebo ignores the link and MuJoCo "
                              "refuses it; give it its mass and inertia", link.line)
            continue
        problem = inertial_problem(inertial)
        if problem is not None and problem[0] in ("mass-nonpositive", "mass-implausible"):
            yield Finding(problem[0], "error", element, problem[1], link.line)
            continue
        yield from _density(ctx, link)
        if problem is not None:
            yield Finding(problem[0], "error", element, problem[1], link.line)
            if problem[0] == "inertia-not-positive":
                continue
        moments = np.linalg.eigvalsh(inertial.tensor)
        yield from _inertia_size(ctx, link, moments)
        yield from _com_inside(ctx, link)


def _inertia_size(ctx: _Context, link: Link, moments: np.ndarray) -> Iterator[Finding]:
    """No moment can exceed m r^2 with r the distance from the COM to the furthest point."""
    inertial = link.inertial  # the caller checked it has one
    if inertial is None:
        return
    aabb = _aabb(ctx.boxes(link.name))
    if aabb is None:
        return
    com = np.asarray(inertial.origin.xyz)
    corners = np.array([[x, y, z] for x in (aabb[0][0], aabb[1][0]) for y in (aabb[0][1], aabb[1][1])
                        for z in (aabb[0][2], aabb[1][2])])
    reach = float(np.max(np.linalg.norm(corners - com, axis=1)))
    bound = inertial.mass * reach**2
    if moments[2] > _INERTIA_SLACK * bound:
        yield Finding("inertia-too-large", "error", _element("link", link.name),
                      f"largest moment {moments[2]:.3g} kg m^2 is {moments[2] / bound:.0f}x what "
                      f"{inertial.mass:g} kg within {reach:.3f} m can have: the link will spin "
                      "like a flywheel and explode (seed Fig. 4.7); check units and values",
                      link.line)


def _density(ctx: _Context, link: Link) -> Iterator[Finding]:
    inertial = link.inertial  # the caller checked it has one
    if inertial is None:
        return
    aabb = _aabb(ctx.boxes(link.name))
    if aabb is None:
        return
    volume = float(np.prod(np.maximum(aabb[1] - aabb[0], 1e-6)))
    if (density := inertial.mass / volume) > MAX_DENSITY:
        yield Finding("mass-implausible", "error", _element("link", link.name),
                      f"{inertial.mass:.3g} kg in {volume:.3g} m^3 of geometry is {density:.3g} "
                      "kg/m^3, over 40x the densest metal: check the mass's unit (kg) or the "
                      "geometry's scale", link.line)


def _com_inside(ctx: _Context, link: Link) -> Iterator[Finding]:
    inertial = link.inertial  # the caller checked it has one
    if inertial is None:
        return
    boxes = ctx.boxes(link.name)
    if not boxes:
        return
    com = np.asarray(inertial.origin.xyz)
    if not any(b.contains(com, _COM_TOL) for b in boxes):
        where = (f"centre of mass ({', '.join(f'{v:.3f}' for v in com)}) m lies outside the "
                 "link's geometry")
        if _tiny(ctx.model, link):  # a 1 g logo or sensor mount: harmless wherever its COM is
            yield Finding("com-outside", "info", _element("link", link.name),
                          f"{where}, but at {inertial.mass:.3g} kg (under "
                          f"{_TINY_FRACTION:.0%} of the robot) it cannot matter", link.line)
        else:
            yield Finding("com-outside", "error", _element("link", link.name),
                          f"{where}: check the <inertial> origin (seed Fig. 4.7)", link.line)


def _tiny(model: RobotModel, link: Link) -> bool:
    """A link too light to change how the robot moves (dummy links: logos, sensor mounts)."""
    return link.inertial is not None and link.inertial.mass < _TINY_FRACTION * model.mass


# ----- geometry placement rules ----------------------------------------------------------------
def _rule_collision_matches_visual(ctx: _Context) -> Iterator[Finding]:
    for name, visuals in ctx.visual_boxes.items():
        collisions = ctx.collision_boxes.get(name)
        if not collisions:
            continue
        v_box, c_box = _aabb(visuals), _aabb(collisions)
        if v_box is None or c_box is None:
            continue
        (v_lo, v_hi), (c_lo, c_hi) = v_box, c_box
        offset = float(np.linalg.norm((v_lo + v_hi) / 2 - (c_lo + c_hi) / 2))
        allowed = max(_MISMATCH_MIN, _MISMATCH_FRACTION * float(np.linalg.norm(v_hi - v_lo)))
        # a pad inside its fingertip, or a box around a torso, shares the visual's place
        if offset > allowed and _overlap(v_lo, v_hi, c_lo, c_hi) < _OVERLAP_ENOUGH:
            yield Finding("collision-misplaced", "warning", _element("link", name),
                          f"collision geometry is {offset:.3f} m from the visual geometry: the "
                          "robot will touch things where it looks empty (seed Fig. 4.6); check "
                          "the <collision> origin", ctx.model.links[name].line)


def _overlap(a_lo: np.ndarray, a_hi: np.ndarray, b_lo: np.ndarray, b_hi: np.ndarray) -> float:
    """Volume two boxes share, as a fraction of the smaller one (flat boxes count as 1 mm)."""
    def volume(lo: np.ndarray, hi: np.ndarray) -> float:
        return float(np.prod(np.maximum(hi - lo, 1e-3)))

    shared_lo, shared_hi = np.maximum(a_lo, b_lo), np.minimum(a_hi, b_hi)
    if np.any(shared_hi < shared_lo):
        return 0.0
    return volume(shared_lo, shared_hi) / min(volume(a_lo, a_hi), volume(b_lo, b_hi))


def _rule_joint_placement(ctx: _Context) -> Iterator[Finding]:
    for joint in ctx.model.joints.values():
        parent_box = _aabb(ctx.boxes(joint.parent))
        child_box = _aabb(ctx.boxes(joint.child))
        if parent_box is None or child_box is None:
            continue
        distances = []
        for link, aabb, point in ((joint.parent, parent_box, np.asarray(joint.origin.xyz)),
                                  (joint.child, child_box, np.zeros(3))):
            allowed = max(_JOINT_FAR_MIN, _JOINT_FAR_FRACTION * float(np.linalg.norm(aabb[1] - aabb[0])))
            # to the nearest of the link's boxes, not to a box around them all: an L-shaped
            # link's joint in the empty corner is off the part
            distances.append((min(b.distance(point) for b in ctx.boxes(link)), allowed))
        if all(d > allowed for d, allowed in distances):
            yield Finding("joint-misplaced", "warning", _element("joint", joint.name),
                          f"joint origin is {distances[0][0]:.3f} m from '{joint.parent}' and "
                          f"{distances[1][0]:.3f} m from '{joint.child}': the link will rotate "
                          "about a point outside the robot (seed Fig. 3.7); check the <origin>",
                          joint.line)
        elif joint.moving:
            detour = distances[0][0] + distances[1][0] - _gap(
                ctx.boxes(joint.parent), ctx.boxes(joint.child), joint.origin.matrix)
            if detour > _JUNCTION_TOL:
                yield Finding("joint-off-junction", "warning", _element("joint", joint.name),
                              f"joint origin is {detour:.3f} m beside where '{joint.parent}' and "
                              f"'{joint.child}' meet: the pivot is not where the parts join (the "
                              "seed's well-centred joint); move it onto the hole or face they share",
                              joint.line)


def _gap(parent: list[Box3], child: list[Box3], child_frame: np.ndarray) -> float:
    """Shortest distance between the two links' boxes (child boxes placed by child_frame in the
    parent's frame): alternating projections, which converge to it for convex sets."""
    best = np.inf
    for a in parent:
        for b in child:
            pose = child_frame @ b.pose
            x = pose[:3, 3]
            for _ in range(30):
                p = a.project(x)
                local = pose[:3, :3].T @ (p - pose[:3, 3])
                x = pose[:3, :3] @ np.clip(local, b.lower, b.upper) + pose[:3, 3]
            best = min(best, float(np.linalg.norm(p - x)))
    return best


# ----- joints, names, tree ---------------------------------------------------------------------
def _from_sdf(model: RobotModel) -> bool:
    """SDF writes -1 for 'no effort or velocity limit'; URDF has no such convention."""
    source = model.source
    return source is not None and (source.suffix.lower() in (".sdf", ".world") or source.is_dir())


def _from_mjcf(model: RobotModel) -> bool:
    return model.source is not None and model.source.suffix.lower() in (".xml", ".mjcf")


def _rule_joint_values(ctx: _Context) -> Iterator[Finding]:
    actuated = {j.name for j in ctx.model.actuated_joints}
    sdf = _from_sdf(ctx.model)
    for joint in ctx.model.joints.values():
        element = _element("joint", joint.name)
        lim = joint.limit
        if joint.type in ("revolute", "prismatic") and lim and lim.lower > lim.upper:
            yield Finding("limit-range", "error", element,
                          f"lower limit {lim.lower:g} > upper limit {lim.upper:g}: swap them",
                          joint.line)
        if joint.name in actuated and lim is not None:
            if lim.effort <= 0:
                yield Finding("effort-limit", "error", element,
                              f"effort limit {lim.effort:g} on an actuated joint: SDF reads a "
                              "negative limit as 'unlimited', ros_control clamps every command to "
                              "it (the motor then does nothing or the wrong thing); set the "
                              "motor's peak torque in N m", joint.line)
            if lim.velocity <= 0 and not _from_mjcf(ctx.model):  # MJCF has no velocity limit
                yield Finding("velocity-limit", "error", element,
                              f"velocity limit {lim.velocity:g} on an actuated joint: a simulator "
                              "either ignores it or holds the joint still; set the motor's top "
                              "speed in rad/s", joint.line)
        elif joint.moving and lim is not None and not _from_mjcf(ctx.model):  # MJCF: no limits
            yield from _passive_limits(joint, element, sdf)
        stated = [joint.dynamics, ctx.model.gazebo_joints.get(joint.name, joint.dynamics)]
        for dyn in dict.fromkeys(stated):
            if dyn.damping < 0 or dyn.friction < 0:
                yield Finding("dynamics-negative", "error", element,
                              f"damping {dyn.damping:g} / friction {dyn.friction:g}: negative "
                              "values add energy and make the simulation diverge", joint.line)


def _passive_limits(joint: Joint, element: str, sdf: bool) -> Iterator[Finding]:
    """Limits of a joint without transmission: nothing drives it, but Gazebo still reads them."""
    limit = joint.limit
    if limit is None:
        return
    for code, what, value, unit in (("effort-limit", "effort", limit.effort, "N m or N"),
                                    ("velocity-limit", "velocity", limit.velocity,
                                     "rad/s or m/s")):
        if value < 0 and not sdf:
            yield Finding(code, "error", element,
                          f"{what} limit {value:g}: URDF limits are magnitudes (Gazebo reads a "
                          f"negative one as 'none', ros_control as nonsense); write the real "
                          f"{what} in {unit}", joint.line)
        elif value == 0:
            yield Finding(code, "warning", element,
                          f"{what} limit 0 on a joint without transmission says nothing may ever "
                          f"drive it (Gazebo clamps to it); write the real {what} in {unit}",
                          joint.line)


def _rule_joint_types(ctx: _Context) -> Iterator[Finding]:
    for joint in ctx.model.joints.values():
        if (why := UNSIMULATED_JOINTS.get(joint.type)) is not None:
            yield Finding("joint-unsupported", "error", _element("joint", joint.name),
                          f"is {joint.type}, which mexone sim refuses: {why}", joint.line)


def _rule_mimic(ctx: _Context) -> Iterator[Finding]:
    """<mimic> becomes a MuJoCo equality constraint; say so, and what cannot be one."""
    joints = ctx.model.joints
    for joint in joints.values():
        mimic = joint.mimic
        if mimic is None:
            continue
        element = _element("joint", joint.name)
        if (problem := mimic_problem(ctx.model, joint)) is not None:
            yield Finding("mimic-invalid", "error", element, problem, mimic.line or joint.line)
            continue
        yield Finding("mimic", "info", element,
                      f"follows '{mimic.joint}' (x {mimic.multiplier:g} + {mimic.offset:g}) through a "
                      "MuJoCo equality constraint; Gazebo 7 ignored <mimic> without a plugin",
                      mimic.line or joint.line)
        if ctx.model.transmission_for(joint.name) is not None:
            yield Finding("mimic-actuated", "warning", element,
                          f"has a <transmission> but follows '{mimic.joint}': its motor fights the "
                          "constraint; drive the joint it mimics instead", joint.line)


def mimic_problem(model: RobotModel, joint: Joint) -> str | None:
    """Why a joint's <mimic> cannot be simulated, or None."""
    mimic, joints = joint.mimic, model.joints
    if mimic is None:
        return None
    if not joint.moving:
        return f"is {joint.type} and cannot mimic anything"
    if mimic.joint not in joints:
        return f"mimics joint '{mimic.joint}', which does not exist"
    if not joints[mimic.joint].moving:
        return f"mimics joint '{mimic.joint}', which is {joints[mimic.joint].type}"
    seen, current = {joint.name}, joints[mimic.joint]
    while current.mimic is not None and current.mimic.joint in joints:
        if current.name in seen:
            return f"mimics '{mimic.joint}', whose <mimic> chain leads back to it"
        seen.add(current.name)
        current = joints[current.mimic.joint]
    return None


def _rule_surfaces(ctx: _Context) -> Iterator[Finding]:
    for name, props in ctx.model.gazebo_links.items():
        if (problem := surface_problem(props)) is not None:
            yield Finding("surface-negative", "error", f'<gazebo reference="{name}">', problem,
                          props.line)


def _rule_names(ctx: _Context) -> Iterator[Finding]:
    model = ctx.model
    if model.name != model.name.lower():
        yield Finding("name-capitals", "warning", f'robot "{model.name}"',
                      "robot names with capitals break ROS launch (seed 3.3.1); use lower case",
                      None)
    capitals = [item for table in (model.links, model.joints) for name, item in table.items()
                if name != name.lower()]
    if capitals:  # style, not physics: one line however many
        names = ", ".join(item.name for item in capitals[:3]) + (", ..." if len(capitals) > 3 else "")
        yield Finding("name-capitals", "info", f"{len(capitals)} links and joints",
                      f"have capitals ({names}); ROS names are lower_case_with_underscores, "
                      "though tf and ros_control accept these", capitals[0].line)
    yield from model.reader_findings


def _rule_tree(ctx: _Context) -> Iterator[Finding]:
    model = ctx.model
    roots = model.roots
    if len(roots) > 1:
        yield Finding("multiple-roots", "error", f'robot "{model.name}"',
                      f"{len(roots)} root links ({', '.join(roots)}): connect them with joints so "
                      "one link is the root", None)
    parents: dict[str, str] = {}
    for joint in model.joints.values():
        if joint.child in parents:
            yield Finding("loop", "error", _element("joint", joint.name),
                          f"link '{joint.child}' is already the child of joint "
                          f"'{parents[joint.child]}': URDF trees cannot close loops", joint.line)
        parents.setdefault(joint.child, joint.name)
    if model.depth > MAX_DEPTH:
        yield Finding("tree-too-deep", "error", f'robot "{model.name}"',
                      f"a chain of {model.depth} links: MuJoCo nests at most {MAX_DEPTH} bodies, so "
                      "mexone sim refuses it; weld links together with fewer, longer ones", None)
    reachable = {name for root in roots for name in model.walk(root)}
    if unreached := set(model.links) - reachable:
        yield Finding("loop", "error", f'robot "{model.name}"',
                      f"links {', '.join(sorted(unreached))} form a cycle with no root", None)


def _rule_transmissions(ctx: _Context) -> Iterator[Finding]:
    model = ctx.model
    for tx in model.transmissions:
        element = f'transmission "{tx.name}"'
        if tx.joint not in model.joints:
            yield Finding("transmission-unknown-joint", "error", element,
                          f"names joint '{tx.joint}', which does not exist", tx.line)
        elif not model.joints[tx.joint].moving:
            yield Finding("transmission-fixed-joint", "warning", element,
                          f"drives joint '{tx.joint}', which is {model.joints[tx.joint].type}",
                          tx.line)
        if tx.mechanical_reduction == 0:
            yield Finding("transmission-reduction", "error", element,
                          "mechanicalReduction 0 transmits no torque; use 1 for a direct drive",
                          tx.line)


RULES: tuple[Callable[[_Context], Iterator[Finding]], ...] = (
    _rule_tree,
    _rule_names,
    _rule_meshes,
    _rule_inertial,
    _rule_collision_matches_visual,
    _rule_joint_placement,
    _rule_joint_values,
    _rule_joint_types,
    _rule_mimic,
    _rule_surfaces,
    _rule_transmissions,
)


def check_model(model: RobotModel) -> list[Finding]:
    """Every model rule's findings (the controller rules are mexone.control.lint's)."""
    ctx = _Context(model)
    _gather(ctx)
    return [finding for rule in RULES for finding in rule(ctx)]


# ----- reports ---------------------------------------------------------------------------------
def format_tree(model: RobotModel) -> str:
    """The tree exactly as urdfdom's check_urdf prints it (children sorted by joint name)."""
    lines = [f"robot name is: {model.name}",
             "---------- Successfully Parsed XML ---------------"]
    children = {name: sorted(joints, key=lambda j: j.name)
                for name, joints in model.child_joints.items()}
    root = model.root
    lines.append(f"root Link: {root} has {len(children.get(root, []))} child(ren)")
    seen = {root}
    # iterative depth first (a 1000-link chain is deeper than Python's recursion limit)
    stack = [(iter(enumerate(children.get(root, []), start=1)), 2)]
    while stack:
        entries, level = stack[-1]
        for i, joint in entries:
            if joint.child in seen:
                continue
            seen.add(joint.child)
            lines.append("  " * level + f"child({i}):  {joint.child}")
            stack.append((iter(enumerate(children.get(joint.child, []), start=1)), level + 2))
            break
        else:
            stack.pop()
    return "\n".join(lines)


def summary(model: RobotModel, findings: list[Finding]) -> dict[str, Any]:
    return {
        "robot": model.name,
        "root": model.root,
        "links": len(model.links),
        "joints": len(model.joints),
        "actuated": len(model.actuated_joints),
        "mass": round(model.mass, 6),
        "findings": [f.as_dict(str(model.source) if model.source else None) for f in findings],
    }
