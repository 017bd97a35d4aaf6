"""read_mjcf(path): a MuJoCo MJCF robot (Unitree's own, the MuJoCo Menagerie) -> RobotModel.

MuJoCo parses and compiles the file (MjSpec: includes, defaults, frames, fromto, degrees), and
this module reads the compiled model at its reference pose, so every convention MJCF has is
MuJoCo's own. What URDF cannot say is mapped, or named in an info finding:

- a body's joint sits at the joint's position: the URDF link frame is there (one link per body);
  a body with several joints becomes a chain of links, the extra ones 1 mg;
- capsules become a cylinder and two spheres (the same solid); ellipsoids their bounding box;
- geoms that collide (contype or conaffinity) are collisions, the others visuals;
- each actuator on a joint is a <transmission>; its force or control range (times gear) is the
  joint's effort limit; MJCF has no velocity limit;
- joint equality constraints are <mimic>s; the root body's free joint makes a floating robot,
  none welds it to the world; bodies beside the robot (a floor, props) are left out.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from mexone.description.findings import Finding
from mexone.description.model import (
    Box,
    Collision,
    Cylinder,
    Dynamics,
    GazeboLink,
    Geometry,
    Inertial,
    Joint,
    Limit,
    Link,
    Mesh,
    Mimic,
    Pose,
    RobotModel,
    Sphere,
    Transmission,
    Visual,
)
from mexone.description.xmlio import XmlReader
from mexone.errors import InputError, UnsupportedError

__all__ = ["read_mjcf"]

_CHAIN_MASS = 1e-6  # kg of the extra links of a body with several joints
_FREE, _BALL, _SLIDE, _HINGE = (int(mujoco.mjtJoint.mjJNT_FREE), int(mujoco.mjtJoint.mjJNT_BALL),
                                int(mujoco.mjtJoint.mjJNT_SLIDE), int(mujoco.mjtJoint.mjJNT_HINGE))
_G = mujoco.mjtGeom


def _pose(pos: np.ndarray, quat: np.ndarray | tuple[float, ...]) -> np.ndarray:
    out = np.eye(4)
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, np.asarray(quat, dtype=float))
    out[:3, :3] = mat.reshape(3, 3)
    out[:3, 3] = pos
    return out


def _compile(path: Path) -> tuple[mujoco.MjSpec, mujoco.MjModel]:
    try:
        spec = mujoco.MjSpec.from_file(str(path))
        return spec, spec.compile()
    except ValueError as exc:  # MuJoCo's parser: "XML Error: ... line 12, column 3"
        text = " ".join(str(exc).split())
        line = None
        if "line " in text:
            digits = text.split("line ", 1)[1].split(",")[0].strip().rstrip(".")
            line = int(digits) if digits.isdigit() else None
        raise InputError(f"MuJoCo cannot read this MJCF: {text}", file=path, line=line,
                         hint="load it with mujoco.MjModel.from_xml_path to see the same") from None


_Lines = dict[tuple[str, str | None], int]  # (tag, name) -> source line


def _lines(path: Path) -> _Lines:
    """(tag, name) -> source line in the main file, for findings and errors."""
    xml = XmlReader(path)
    return {(el.tag, el.get("name")): el.sourceline for el in xml.root.iter()
            if isinstance(el.tag, str) and el.get("name")}


def _robot_root(model: mujoco.MjModel, findings: list[Finding]) -> int:
    top = [b for b in range(1, model.nbody) if model.body_parentid[b] == 0]
    free = [b for b in top if model.body_jntnum[b] and model.jnt_type[model.body_jntadr[b]] == _FREE]
    moving = [b for b in top if model.body_jntnum[b] or _has_moving_descendant(model, b)]
    chosen = free or moving or top
    if not chosen:
        raise InputError("the MJCF has no body: nothing to simulate")
    if len(chosen) > 1:
        names = ", ".join(model.body(b).name or f"body {b}" for b in chosen)
        raise UnsupportedError(f"the MJCF holds {len(chosen)} robots ({names})",
                               hint="mexone simulates one robot: keep one in the file")
    for b in top:
        if b != chosen[0]:
            findings.append(Finding("mjcf-ignored", "info", f'body "{model.body(b).name}"',
                                    "is not part of the robot (scenery); left out: the world "
                                    "comes from --world", None))
    return chosen[0]


def _has_moving_descendant(model: mujoco.MjModel, body: int) -> bool:
    return any(model.body_jntnum[b] and _ancestor(model, b, body) for b in range(model.nbody))


def _ancestor(model: mujoco.MjModel, body: int, ancestor: int) -> bool:
    while body > 0:
        if body == ancestor:
            return True
        body = model.body_parentid[body]
    return False


def read_mjcf(path: Path | str) -> RobotModel:
    path = Path(path)
    lines = _lines(path)  # vets the file as every reader does (size, entities, syntax)
    spec, model = _compile(path)
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    findings: list[Finding] = []
    root = _robot_root(model, findings)
    name = spec.modelname or path.stem
    robot = RobotModel(name=name.lower().replace(" ", "_"), links={}, joints={}, source=path,
                       reader_findings=findings)
    body_names = {b: model.body(b).name or f"body{b}" for b in range(model.nbody)}
    link_frame: dict[int, np.ndarray] = {}  # body -> world pose of its (last) link frame
    body_link: dict[int, str] = {}
    for b in range(root, model.nbody):
        if not _ancestor(model, b, root):
            continue
        world_body = _pose(data.xpos[b], data.xquat[b])
        joints = [model.body_jntadr[b] + k for k in range(model.body_jntnum[b])]
        parent_frame: np.ndarray | None = link_frame.get(model.body_parentid[b])
        parent_link: str | None = body_link.get(model.body_parentid[b])
        bname = body_names[b]
        free = b == root and joints and model.jnt_type[joints[0]] == _FREE
        if b == root and not free:  # welded where it stands, as URDF says with a 'world' link
            robot.links["world"] = Link("world")
            parent_frame, parent_link = np.eye(4), "world"
        moving = [j for j in joints if model.jnt_type[j] != _FREE]
        for j in moving:
            if model.jnt_type[j] == _BALL:
                jname = model.joint(j).name
                raise UnsupportedError(f"joint '{jname}' is a ball joint, which URDF cannot say",
                                       file=path, line=lines.get(("joint", jname)),
                                       hint="make it three hinge joints in a chain of bodies")
        if not moving:
            frame = world_body
            if parent_link is not None and parent_frame is not None:
                robot.joints[f"{bname}_fixed"] = Joint(
                    f"{bname}_fixed", "fixed", parent_link, bname,
                    Pose.from_matrix(np.linalg.inv(parent_frame) @ frame), line=lines.get(("body", bname)))
        for k, j in enumerate(moving):
            assert parent_link is not None and parent_frame is not None, "a hinge on a free root"
            frame = world_body @ _pose(model.jnt_pos[j], (1, 0, 0, 0))
            jname = model.joint(j).name or f"{bname}_joint{k}"
            child = bname if k == len(moving) - 1 else f"{bname}__{jname}"
            if child != bname:
                robot.links[child] = Link(child, Inertial(_CHAIN_MASS, (1e-9, 0, 0, 1e-9, 0, 1e-9)))
            robot.joints[jname] = _joint(model, j, jname, parent_link, child,
                                         Pose.from_matrix(np.linalg.inv(parent_frame) @ frame),
                                         lines.get(("joint", jname)))
            parent_frame, parent_link = frame, child
        link = Link(bname, _inertial(model, data, b, frame), line=lines.get(("body", bname)))
        _geoms(model, spec, data, b, frame, link, path, robot)
        robot.links[bname] = link
        link_frame[b], body_link[b] = frame, bname
    if len(robot.links) == 1 and "world" in robot.links:
        raise InputError("the MJCF robot has no body", file=path)
    _transmissions(model, robot, lines)
    _mimics(model, robot, findings, lines)
    armature = [model.joint(j).name for j in range(model.njnt) if model.dof_armature[model.jnt_dofadr[j]] > 0
                and model.joint(j).name in robot.joints]
    if armature:
        findings.append(Finding("mjcf-armature", "info", f'robot "{robot.name}"',
                                f"{len(armature)} joints have armature (rotor inertia), which URDF "
                                "has no place for: left out", None))
    # links in file order after the world, joints after their parents: as a URDF would list them
    robot.links = dict(sorted(robot.links.items(), key=lambda kv: kv[0] != "world"))
    return robot


def _joint(model: mujoco.MjModel, j: int, name: str, parent: str, child: str, origin: Pose,
           line: int | None) -> Joint:
    kind = model.jnt_type[j]
    limited = bool(model.jnt_limited[j])
    ref = model.qpos0[model.jnt_qposadr[j]]
    lower, upper = (model.jnt_range[j] - ref) if limited else (0.0, 0.0)
    jtype = ("prismatic" if kind == _SLIDE else "revolute") if limited else \
        ("continuous" if kind == _HINGE else "prismatic")
    if kind == _SLIDE and not limited:
        lower, upper = -1e3, 1e3  # URDF needs limits on a prismatic joint: a kilometre either way
    dof = model.jnt_dofadr[j]
    effort = float(max(abs(model.jnt_actfrcrange[j]))) if model.jnt_actfrclimited[j] else 0.0
    return Joint(name, jtype, parent, child, origin, tuple(float(v) for v in model.jnt_axis[j]),
                 Limit(float(lower), float(upper), effort, 0.0),
                 Dynamics(float(model.dof_damping[dof]), float(model.dof_frictionloss[dof])), line)


def _inertial(model: mujoco.MjModel, data: mujoco.MjData, b: int, frame: np.ndarray) -> Inertial | None:
    mass = float(model.body_mass[b])
    if mass <= 0:
        return None
    world = _pose(data.xipos[b], (1, 0, 0, 0))
    world[:3, :3] = data.ximat[b].reshape(3, 3)
    local = np.linalg.inv(frame) @ world
    ixx, iyy, izz = (float(v) for v in model.body_inertia[b])
    return Inertial(mass, (ixx, 0.0, 0.0, iyy, 0.0, izz), Pose.from_matrix(local))


def _mesh_file(spec: mujoco.MjSpec, path: Path, name: str) -> Path:
    mesh = spec.mesh(name)
    folder = path.parent / (spec.meshdir or "")
    return (folder / mesh.file).resolve()


def _geoms(model: mujoco.MjModel, spec: mujoco.MjSpec, data: mujoco.MjData, b: int, frame: np.ndarray,
           link: Link, path: Path,
           robot: RobotModel) -> None:
    inverse = np.linalg.inv(frame)
    visuals, collisions = [], []
    friction = None
    for g in range(model.ngeom):
        if model.geom_bodyid[g] != b:
            continue
        world = _pose(data.geom_xpos[g], (1, 0, 0, 0))
        world[:3, :3] = data.geom_xmat[g].reshape(3, 3)
        local = inverse @ world
        kind, size = model.geom_type[g], model.geom_size[g]
        shapes: list[tuple[Geometry, np.ndarray]] = []
        if kind == _G.mjGEOM_BOX:
            shapes = [(Box(tuple(float(2 * v) for v in size)), local)]
        elif kind == _G.mjGEOM_SPHERE:
            shapes = [(Sphere(float(size[0])), local)]
        elif kind == _G.mjGEOM_CYLINDER:
            shapes = [(Cylinder(float(size[0]), float(2 * size[1])), local)]
        elif kind == _G.mjGEOM_CAPSULE:
            r, h = float(size[0]), float(size[1])
            shapes = [(Cylinder(r, 2 * h), local)] + [
                (Sphere(r), local @ _pose(np.array([0.0, 0.0, s * h]), (1, 0, 0, 0))) for s in (-1, 1)]
        elif kind == _G.mjGEOM_ELLIPSOID:
            shapes = [(Box(tuple(float(2 * v) for v in size)), local)]
        elif kind == _G.mjGEOM_MESH:
            mesh = model.geom_dataid[g]
            mesh_name = model.mesh(mesh).name
            # the compiler moved the mesh to its centre of mass; undo that to use the file as is
            offset = _pose(model.mesh_pos[mesh], model.mesh_quat[mesh])
            scale = tuple(float(v) for v in spec.mesh(mesh_name).scale)
            shapes = [(Mesh(str(_mesh_file(spec, path, mesh_name)), scale),
                       local @ np.linalg.inv(offset))]
        else:
            continue  # planes, height fields: scenery
        collide = bool(model.geom_contype[g] or model.geom_conaffinity[g])
        rgba = model.mat_rgba[model.geom_matid[g]] if model.geom_matid[g] >= 0 else model.geom_rgba[g]
        for shape, pose in shapes:
            origin = Pose.from_matrix(pose)
            if collide:
                collisions.append(Collision(shape, origin, model.geom(g).name or None))
                friction = float(model.geom_friction[g][0])
            else:
                visuals.append(Visual(shape, origin, model.geom(g).name or None, None,
                                      tuple(float(c) for c in rgba)))
    if not visuals:  # drawn as MuJoCo draws it: by its collision geoms
        visuals = [Visual(c.geometry, c.origin, c.name) for c in collisions]
    link.visuals, link.collisions = visuals, collisions
    if friction is not None and friction != 1.0:
        robot.gazebo_links[link.name] = GazeboLink(mu1=friction, mu2=friction)


def _effort(model: mujoco.MjModel, a: int) -> float:
    gear = abs(float(model.actuator_gear[a][0])) or 1.0
    if model.actuator_forcelimited[a]:
        return float(max(abs(model.actuator_forcerange[a]))) * gear
    if model.actuator_ctrllimited[a] and model.actuator_gaintype[a] == mujoco.mjtGain.mjGAIN_FIXED \
            and model.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_NONE:
        return float(max(abs(model.actuator_ctrlrange[a]))) * gear * abs(model.actuator_gainprm[a][0])
    return 0.0


def _transmissions(model: mujoco.MjModel, robot: RobotModel, lines: _Lines) -> None:
    for a in range(model.nactuator):  # MuJoCo 4: nu counts control inputs (a PID has 3)
        if model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT:
            continue
        joint = model.joint(model.actuator_trnid[a][0]).name
        if joint not in robot.joints or robot.transmission_for(joint) is not None:
            continue
        name = model.actuator(a).name or f"{joint}_actuator"
        robot.transmissions.append(Transmission(f"{name}_tran", joint, actuator=name,
                                                line=lines.get(("motor", name))))
        current = robot.joints[joint]
        if (effort := _effort(model, a)) > 0 and current.limit is not None and not current.limit.effort:
            lim = current.limit
            current.limit = Limit(lim.lower, lim.upper, effort, lim.velocity)


def _mimics(model: mujoco.MjModel, robot: RobotModel, findings: list[Finding], lines: _Lines) -> None:
    for e in range(model.neq):
        ename = model.equality(e).name or f"equality {e}"
        if model.eq_type[e] == mujoco.mjtEq.mjEQ_JOINT and model.eq_obj2id[e] >= 0:
            follower, leader = model.joint(model.eq_obj1id[e]).name, model.joint(model.eq_obj2id[e]).name
            coef = model.eq_data[e]
            if follower in robot.joints and leader in robot.joints and not any(coef[2:5]):
                robot.joints[follower].mimic = Mimic(leader, float(coef[1]), float(coef[0]),
                                                     lines.get(("joint", ename)))
                continue
        findings.append(Finding("mjcf-ignored", "warning", f'equality "{ename}"',
                                "a constraint URDF cannot say (a closed loop or weld): left out", None))
