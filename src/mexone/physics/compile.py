"""RobotModel + World -> MuJoCo (MjSpec -> MjModel), the way Gazebo 7 would simulate the URDF.

MuJoCo's own URDF importer drops ``<gazebo>`` and ``<transmission>``, welds the root to the
world and cannot resolve ``package://``; this module owns all of that. The mapping of every
Gazebo property we honour is in ``GAZEBO_MAPPING`` (printed by ``mexone sim --explain``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import mujoco
import numpy as np

from mexone.description.check import (
    MAX_DEPTH,
    UNSIMULATED_JOINTS,
    implausible_inertial,
    mimic_problem,
    surface_problem,
)
from mexone.description.kinematics import link_frames_at, with_mimics
from mexone.description.materials import display_rgba
from mexone.description.meshes import geometry_bounds, load_mesh, resolve_mesh
from mexone.description.model import Box, Cylinder, GazeboLink, Geometry, Joint, Mesh, RobotModel, Sphere
from mexone.description.transforms import rpy_to_matrix
from mexone.errors import InputError, MexoneError, ModelError, UnsupportedError
from mexone.physics.world import World, default_world
from mexone.ranges import number_text

_log = logging.getLogger("mexone.physics")

__all__ = ["Spawn", "CompileOptions", "Compiled", "compile_model", "SpecEdit", "GAZEBO_MAPPING",
           "initial_positions",
           "GROUP_VISUAL", "GROUP_COLLISION", "lowest_point", "collision_bits"]

GROUP_VISUAL = 1  # MuJoCo geom groups: the viewer's toggles for visual and collision geometry
GROUP_COLLISION = 3

# contype/conaffinity bits: a contact happens if (type1 & aff2) or (type2 & aff1)
_SELF = 2  # links with selfCollide: touch every link of the robot
_PLAIN = 4  # links without: touch only selfCollide links (and the ground, through <pair>s)

# Gazebo (SDF/ODE) defaults where a URDF is silent
_GAZEBO_MU = 1.0
_GAZEBO_KP = 1e12
_GAZEBO_KD = 1.0
_DMAX = 0.95  # MuJoCo's default solimp[1]: the impedance a settled contact reaches
_MIN_STEPS_PER_TIMECONST = 4  # stiffer contacts chatter: a sliding box hops and slides 25% fast
_SPAWN_TOLERANCE = 0.001  # m a spawn may start inside the ground (soft contacts settle it)
# Newton's cost per iteration grows as nv^3: a 900-link chain lying on the ground took 2 s a step;
# CG takes 0.2 s there and the same as Newton on Mex-One-sized robots (DECISIONS.md)
_LARGE_NV = 100
_CONTACTS_PER_GEOM = 4  # a box on a plane touches at its 4 corners
SPAWN_KEY = "spawn"
_MJ_STL_MAX_FACES = 200_000  # MuJoCo's own STL reader refuses more (and ASCII STL)

#: how Gazebo's physics settings map to MuJoCo's: (Gazebo, MuJoCo, how) per setting
GAZEBO_MAPPING: tuple[tuple[str, str, str], ...] = (
    ("<gazebo> mu1, mu2", "pair/geom friction[0:2]",
     "min-combined as ODE does: explicit <pair>s with the ground; between links, geom "
     "priority ordered so the lower friction wins"),
    ("<gazebo> kp, kd", "solref = (timeconst, dampratio)",
     "ODE's kp (N/m) as stiffness of the robot's mass, k = kp/m: timeconst = "
     "1/(dmax*zeta*sqrt(k)); zeta = max(1, kd/(2 sqrt(kp m))): ODE contacts are inelastic, so "
     "at least critically damped; timeconst >= 4 steps (stiffer contacts chatter). Pair kp "
     "in series 1/(1/kp1+1/kp2), kd summed, as ODE combines them"),
    ("<gazebo> selfCollide", "contype/conaffinity bits",
     "links collide with each other when either has selfCollide (as Gazebo's ODE spaces); "
     "never across a joint (exclude pairs, lumping fixed joints as Gazebo does)"),
    ("<gazebo> maxVel, minDepth", "(none)",
     "no MuJoCo equivalent: correction speed follows from solref; ignored"),
    ("<dynamics damping> / <gazebo> axis/dynamics/damping", "joint damping",
     "viscous, integrated implicitly (implicitfast)"),
    ("<dynamics friction> / <gazebo> axis/dynamics/friction", "joint frictionloss", "Coulomb"),
    ("<dynamics armature> (as Genesis and Pinocchio read it)", "joint armature",
     "rotor inertia reflected through the gearbox; Gazebo 7 has none"),
    ("<limit lower upper>", "joint range (limited)", "continuous joints unlimited"),
    ("<limit effort>", "joint actuatorfrcrange, motor forcerange = effort / mechanicalReduction",
     "the joint's total actuator torque never exceeds it; <= 0 means unlimited, as SDF reads -1"),
    ("<transmission> mechanicalReduction", "actuator gear",
     "joint effort = gear * actuator effort; joint-space commands are unchanged"),
    ("<transmission> + ros_control PID", "native PID actuator + integral actuator",
     "P and D (implicit) in the motor, the I term with control_toolbox's clamps in a second "
     "actuator; built by the control layer (control/hardware.py)"),
    ("collision <mesh>", "mesh geom", "MuJoCo collides with the mesh's convex hull"),
    ("root link", "free joint", "unless the URDF welds it to a 'world' link"),
    ("<mimic joint multiplier offset>", "joint equality constraint (polycoef offset, multiplier)",
     "Gazebo 7 ignored <mimic> without a plugin"),
    ("spawn inside the ground", "lifted onto it, with a warning",
     "Gazebo shoots such a robot into the air"),
    ("world <physics> max_step_size, ode/solver/iters", "option timestep, iterations", ""),
    ("Coulomb friction (ODE: pyramid, exact stiction)", "elliptic cone, impratio 10",
     "MuJoCo's soft friction creeps under static load unless impratio is raised"),
)


@dataclass(frozen=True)
class Spawn:
    """Where the robot appears, as spawn_model's -x -y -z -R -P -Y. With on_ground, z is measured
    from the robot's lowest collision point at home, so z = 0 stands it on the ground."""

    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    on_ground: bool = True
    # initial joint positions (spawn_model -J): the pose a reset returns to, others at 0
    joints: tuple[tuple[str, float], ...] = ()


@dataclass(frozen=True)
class CompileOptions:
    self_collision: bool | None = None  # None: as each link's <gazebo selfCollide> says
    visuals: bool = True  # visual meshes as geoms (rendering, MJCF export); no physics effect
    integrator: str = "implicitfast"  # implicit in velocity: joint damping never destabilises
    armature: float = 0.0  # kg m^2 added to every moving joint (rotor inertia); Gazebo has none
    fixed_base: bool = False  # weld the root to the world where it spawns (a robot on a stand)


@dataclass
class Compiled:
    """The MuJoCo model plus the name maps the other layers need."""

    spec: mujoco.MjSpec
    model: mujoco.MjModel
    robot: RobotModel
    world: World
    spawn: Spawn
    joints: list[str]  # moving joints, in URDF order
    qpos_adr: np.ndarray
    dof_adr: np.ndarray
    bodies: dict[str, int] = field(default_factory=dict)  # link -> body id
    free: bool = True  # the root has a free joint
    spawn_key: int | None = None  # keyframe of the initial joint positions, if any were given

    @cached_property
    def root_body(self) -> int:
        """Cached: sensors ask at every message, and the robot is fixed once compiled."""
        return self.bodies[self.robot.base_link]


def _quat(rotation: np.ndarray) -> np.ndarray:
    out = np.zeros(4)
    mujoco.mju_mat2Quat(out, np.ascontiguousarray(rotation).ravel())
    return out


def _set_pose(element: mujoco.MjsBody | mujoco.MjsGeom | mujoco.MjsSite, matrix: np.ndarray) -> None:
    element.pos = matrix[:3, 3]
    element.quat = _quat(matrix[:3, :3])


def lowest_point(robot: RobotModel, rotation: np.ndarray | None = None,
                 positions: dict[str, float] | None = None) -> float:
    """Lowest z of any collision geometry at home (or with these joint positions), in the root's
    frame turned by rotation (the spawn's roll, pitch and yaw), for standing spawns."""
    lowest = np.inf
    turn = np.eye(4)
    if rotation is not None:
        turn[:3, :3] = rotation
    for name, frame in link_frames_at(robot, positions).items():
        for col in robot.links[name].collisions:
            lower, upper = geometry_bounds(col.geometry, robot.base_dir)
            corners = np.array([[x, y, z, 1.0] for x in (lower[0], upper[0])
                                for y in (lower[1], upper[1]) for z in (lower[2], upper[2])])
            if isinstance(col.geometry, Cylinder | Sphere):  # round: the box corners overshoot
                corners = _round_extremes(col.geometry)
            points = (turn @ frame @ col.origin.matrix @ corners.T)[2]
            lowest = min(lowest, float(points.min()))
    return 0.0 if lowest == np.inf else lowest


def _round_extremes(geometry: Cylinder | Sphere) -> np.ndarray:
    """Points that bound a cylinder or sphere well enough: rims sampled every 7.5 degrees."""
    angles = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    if isinstance(geometry, Sphere):
        r = geometry.radius
        ring = [[r * np.cos(a) * np.cos(b), r * np.sin(a) * np.cos(b), r * np.sin(b), 1.0]
                for a in angles for b in np.linspace(-np.pi / 2, np.pi / 2, 25)]
        return np.array(ring)
    r, h = geometry.radius, geometry.length / 2
    return np.array([[r * np.cos(a), r * np.sin(a), z, 1.0] for a in angles for z in (-h, h)])


def _contact_solref(kp: float, kd: float, mass: float, step: float) -> tuple[float, float]:
    k = kp / mass
    zeta = max(1.0, kd / (2.0 * np.sqrt(kp * mass)))
    return max(_MIN_STEPS_PER_TIMECONST * step, 1.0 / (_DMAX * zeta * np.sqrt(k))), zeta


def _surface(props: GazeboLink) -> tuple[float, float, float, float]:
    """(mu1, mu2, kp, kd) of a link, Gazebo's defaults where its <gazebo> block is silent."""
    mu1 = props.mu1 if props.mu1 is not None else _GAZEBO_MU
    mu2 = props.mu2 if props.mu2 is not None else mu1
    kp = props.kp if props.kp is not None else _GAZEBO_KP
    kd = props.kd if props.kd is not None else _GAZEBO_KD
    return mu1, mu2, kp, kd


def _lumps(robot: RobotModel) -> dict[str, str]:
    """Each link's lump: links joined by fixed joints move as one body, as Gazebo merges them."""
    lump = {name: name for name in robot.links}
    for name in robot.walk():
        for joint in robot.child_joints.get(name, []):
            if joint.type == "fixed":
                lump[joint.child] = lump[name]
    return lump


SpecEdit = Callable[[mujoco.MjSpec, RobotModel], None]


def compile_model(robot: RobotModel, world: World | None = None, spawn: Spawn = Spawn(),
                  options: CompileOptions = CompileOptions(), edits: Sequence[SpecEdit] = ()
                  ) -> Compiled:
    """The robot and world as a plain MuJoCo model (no actuators); `edits` change the MjSpec
    before it compiles (the control layer adds its actuators that way, as mjlab's configs do)."""
    world = world or default_world()
    _refuse_what_we_cannot_build(robot, options.fixed_base)
    if not np.isfinite([*spawn.xyz, *spawn.rpy]).all():
        raise InputError(f"spawn pose ({', '.join(number_text(v) for v in (*spawn.xyz, *spawn.rpy))}) "
                         "is not finite", hint="give finite numbers")
    spec = mujoco.MjSpec()
    spec.modelname = robot.name
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.compiler.autolimits = False
    spec.compiler.degree = False  # URDF angles are radians; MJCF's default is degrees
    spec.option.timestep = world.step
    spec.option.gravity = world.gravity
    spec.option.iterations = max(world.iterations, 1)
    spec.option.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{options.integrator.upper()}")
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC  # true Coulomb cone...
    spec.option.impratio = 10.0  # ...with stiff friction: a robot standing still does not creep
    spec.visual.global_.offwidth = 1920
    spec.visual.global_.offheight = 1080

    _add_world(spec, world)
    robot_mass = robot.mass or 1.0  # a welded massless root with massless links: nothing moves

    placement = _placement(robot, world, spawn)

    bodies: dict[str, mujoco.MjsBody] = {}
    free = not (robot.fixed_to_world or options.fixed_base)
    geoms_by_link: dict[str, list[str]] = {}
    for name in robot.walk():
        if name == "world":
            continue
        joint = robot.parent_joint.get(name)
        if joint is None:  # the root: floating unless welded
            body = spec.worldbody.add_body(name=name)
            _set_pose(body, placement)
            if free:
                body.add_freejoint(name=f"{name}_free")
        elif joint.parent == "world":
            body = spec.worldbody.add_body(name=name)
            _set_pose(body, placement @ joint.origin.matrix)
            _add_joint(body, robot, joint, options)
        else:
            body = bodies[joint.parent].add_body(name=name)
            _set_pose(body, joint.origin.matrix)
            _add_joint(body, robot, joint, options)
        bodies[name] = body
        _add_inertial(body, robot, name)
        geoms_by_link[name] = _add_geoms(spec, body, robot, name, options, world, robot_mass)

    _add_contact_rules(spec, robot, world, geoms_by_link, robot_mass)
    _add_mimics(spec, robot)
    _size_for_large_models(spec, robot, sum(len(g) for g in geoms_by_link.values()))
    keyed = _add_spawn_key(spec, robot, spawn)
    for edit in edits:
        edit(spec, robot)
    _no_second_factorisation(spec)
    try:
        model = spec.compile()
    except ValueError as exc:
        raise ModelError(f"MuJoCo cannot build '{robot.name}': {' '.join(str(exc).split())}",
                         file=robot.source, hint="run 'mexone check' on the model") from None

    joints = [j.name for j in robot.moving_joints]
    ids = [model.joint(j).id for j in joints]
    spawn_key = _fill_spawn_key(spec, model, robot, spawn) if keyed else None
    return Compiled(
        spec=spec, model=model, robot=robot, world=world, spawn=spawn, joints=joints,
        qpos_adr=np.array([model.jnt_qposadr[i] for i in ids], dtype=int),
        dof_adr=np.array([model.jnt_dofadr[i] for i in ids], dtype=int),
        bodies={name: model.body(name).id for name in bodies},
        free=free,
        spawn_key=spawn_key,
    )


def _placement(robot: RobotModel, world: World, spawn: Spawn) -> np.ndarray:
    """The root's world pose. A robot welded to the world stands where its URDF puts it; any
    other on its lowest point (on_ground) or at spawn.xyz, but never inside the ground: ODE and
    MuJoCo alike push such a robot out at tens of m/s."""
    rotation = rpy_to_matrix(spawn.rpy)
    placement = np.eye(4)
    placement[:3, :3] = rotation
    placement[:3, 3] = spawn.xyz
    if robot.fixed_to_world:
        return placement
    lowest = lowest_point(robot, rotation, initial_positions(robot, spawn))
    if spawn.on_ground:
        placement[2, 3] -= lowest
    if world.ground is not None and any(link.collisions for link in robot.links.values()):
        depth = world.ground.z - (placement[2, 3] + lowest)
        if depth > _SPAWN_TOLERANCE:
            placement[2, 3] += depth
            _log.warning(f"spawn z {spawn.xyz[2]:g} puts '{robot.name}' {depth:.3f} m inside the ground; "
                         f"lifted so its lowest point is on the ground (it would be shot into the air)")
    return placement


def initial_positions(robot: RobotModel, spawn: Spawn) -> dict[str, float]:
    """spawn.joints checked against the robot, with <mimic> followers placed too."""
    given = dict(spawn.joints)
    for name, value in given.items():
        joint = robot.joints.get(name)
        if joint is None or not joint.moving:
            moving = ", ".join(j.name for j in robot.moving_joints) or "none"
            raise InputError(f"initial position for '{name}', which is not a moving joint of "
                             f"'{robot.name}'", hint=f"moving joints: {moving}")
        if not np.isfinite(value):
            raise InputError(f"initial position {number_text(value)} of '{name}' is not finite")
        limit = joint.limit
        if joint.type in ("revolute", "prismatic") and limit is not None and not (
                limit.lower - 1e-9 <= value <= limit.upper + 1e-9):
            raise InputError(f"initial position {value:g} of '{name}' is outside its limits "
                             f"[{limit.lower:g}, {limit.upper:g}]",
                             hint="give a value within the joint's <limit>")
    return with_mimics(robot, given)


def _add_spawn_key(spec: mujoco.MjSpec, robot: RobotModel, spawn: Spawn) -> bool:
    """A keyframe 'spawn' for initial joint positions (MuJoCo's qpos0 is each joint's zero, so
    the pose cannot go there); Simulation.reset starts from it. Filled in by _fill_spawn_key."""
    if not initial_positions(robot, spawn):
        return False
    spec.add_key(name=SPAWN_KEY)  # unset values default to qpos0
    return True


def _fill_spawn_key(spec: mujoco.MjSpec, model: mujoco.MjModel, robot: RobotModel,
                    spawn: Spawn) -> int:
    key = model.key(SPAWN_KEY).id
    for name, value in initial_positions(robot, spawn).items():
        model.key_qpos[key, model.jnt_qposadr[model.joint(name).id]] = value
    spec.key(SPAWN_KEY).qpos = model.key_qpos[key].copy()  # the exported MJCF has it too
    return key


def _refuse_what_we_cannot_build(robot: RobotModel, fixed_base: bool) -> None:
    if len(robot.roots) != 1:
        raise ModelError(f"'{robot.name}' has {len(robot.roots)} root links "
                         f"({', '.join(robot.roots)})", file=robot.source,
                         hint="connect them with joints; 'mexone check' shows the tree")
    children = [j.child for j in robot.joints.values()]
    if len(children) != len(set(children)):
        raise ModelError(f"'{robot.name}' has a closed loop", file=robot.source,
                         hint="URDF trees cannot close loops; 'mexone check' names the joint")
    if robot.depth > MAX_DEPTH:
        raise UnsupportedError(f"'{robot.name}' has a chain of {robot.depth} links; MuJoCo nests at "
                               f"most {MAX_DEPTH} bodies", file=robot.source,
                               hint="weld links together with fewer, longer ones")
    for joint in robot.joints.values():
        if joint.type in UNSIMULATED_JOINTS:
            raise UnsupportedError(f"joint '{joint.name}' is {joint.type}, which mexone does not "
                                   "simulate", file=robot.source, line=joint.line,
                                   hint=UNSIMULATED_JOINTS[joint.type])
        link = robot.links[joint.child]
        if joint.moving and (link.inertial is None or link.inertial.mass <= 0):
            raise ModelError(f"link '{link.name}' moves (joint '{joint.name}') but has no mass",
                             file=robot.source, line=link.line,
                             hint="give it an <inertial> with mass > 0")
        if joint.mimic is not None and (problem := mimic_problem(robot, joint)) is not None:
            raise ModelError(f"joint '{joint.name}' {problem}", file=robot.source,
                             line=joint.mimic.line or joint.line,
                             hint="'mexone check' lists every such joint")
    for link in robot.links.values():
        if link.inertial is not None and (problem := implausible_inertial(link.inertial)) is not None:
            raise ModelError(f"link '{link.name}': {problem}", file=robot.source, line=link.line,
                             hint="'mexone check' lists every implausible link")
    for name, props in robot.gazebo_links.items():
        if (problem := surface_problem(props)) is not None:
            raise ModelError(f"link '{name}': {problem}", file=robot.source, line=props.line,
                             hint="'mexone check' lists every such value")
    root = robot.links[robot.root]
    if not (robot.fixed_to_world or fixed_base) and (root.inertial is None or root.inertial.mass <= 0):
        raise ModelError(f"floating root link '{root.name}' has no mass", file=robot.source,
                         line=root.line, hint="give it an <inertial> or weld it to a 'world' link")


def _add_world(spec: mujoco.MjSpec, world: World) -> None:
    light = spec.worldbody.add_light(name="sun")
    light.type = mujoco.mjtLightType.mjLIGHT_DIRECTIONAL
    light.dir = world.sun_direction
    light.pos = (0, 0, 10)
    light.castshadow = True
    if world.ground is None:
        return
    texture = spec.add_texture(name="ground_checker", type=mujoco.mjtTexture.mjTEXTURE_2D,
                               builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER, width=256, height=256,
                               rgb1=(0.42, 0.44, 0.47), rgb2=(0.36, 0.38, 0.41))
    material = spec.add_material(name="ground", texrepeat=(20, 20), reflectance=0.05)
    material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = texture.name
    plane = spec.worldbody.add_geom(name="ground_plane", type=mujoco.mjtGeom.mjGEOM_PLANE,
                                    size=(0, 0, 0.05), material="ground")
    plane.pos = (0, 0, world.ground.z)
    plane.contype = 0  # contacts with the ground come from explicit <pair>s
    plane.conaffinity = 0
    _add_blocks(spec, world)


def _add_blocks(spec: mujoco.MjSpec, world: World) -> None:
    """The world's static boxes (terrain), in geom group 0 with the ground: every robot link
    touches them; the robot's surface (friction, contact stiffness) wins the pair, as against the
    ground (priority)."""
    for i, block in enumerate(world.blocks):
        geom = spec.worldbody.add_geom(name=f"world/{block.name}/{i}", type=mujoco.mjtGeom.mjGEOM_BOX,
                                       size=np.asarray(block.size) / 2, pos=block.xyz,
                                       rgba=(0.55, 0.52, 0.48, 1.0))
        matrix = rpy_to_matrix(block.rpy)
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, matrix.ravel())
        geom.quat = quat
        geom.contype = geom.conaffinity = _SELF | _PLAIN
        geom.friction = (block.mu, 0.005, 0.0001)
        geom.priority = 0
        geom.solmix = 0.0


def _add_joint(body: mujoco.MjsBody, robot: RobotModel, joint: Joint, options: CompileOptions) -> None:
    if not joint.moving:
        return
    kind = mujoco.mjtJoint.mjJNT_SLIDE if joint.type == "prismatic" else mujoco.mjtJoint.mjJNT_HINGE
    mj = body.add_joint(name=joint.name, type=kind, axis=joint.axis)
    if joint.type in ("revolute", "prismatic") and joint.limit is not None:  # URDF requires one
        mj.limited = mujoco.mjtLimited.mjLIMITED_TRUE
        mj.range = (joint.limit.lower, joint.limit.upper)
    else:
        mj.limited = mujoco.mjtLimited.mjLIMITED_FALSE
    dyn = robot.joint_dynamics(joint.name)
    mj.damping = (dyn.damping, 0.0, 0.0)  # MuJoCo 4: polynomial damping, linear term first
    mj.frictionloss = dyn.friction
    mj.armature = dyn.armature + options.armature


def _add_inertial(body: mujoco.MjsBody, robot: RobotModel, name: str) -> None:
    inertial = robot.links[name].inertial
    if inertial is None:
        body.mass = 0.0
        return
    body.mass = inertial.mass
    rotation = inertial.origin.matrix[:3, :3]
    tensor = rotation @ inertial.tensor @ rotation.T
    body.ipos = inertial.origin.xyz
    body.fullinertia = (tensor[0, 0], tensor[1, 1], tensor[2, 2], tensor[0, 1], tensor[0, 2],
                        tensor[1, 2])
    body.explicitinertial = True


def _geom_shape(geom: mujoco.MjsGeom, geometry: Geometry, spec: mujoco.MjSpec, robot: RobotModel,
                mesh_name: str,
                line: int | None = None) -> None:
    match geometry:
        case Box(size):
            geom.type = mujoco.mjtGeom.mjGEOM_BOX
            geom.size = np.asarray(size) / 2
        case Cylinder(radius, length):
            geom.type = mujoco.mjtGeom.mjGEOM_CYLINDER
            geom.size = (radius, length / 2, 0)
        case Sphere(radius):
            geom.type = mujoco.mjtGeom.mjGEOM_SPHERE
            geom.size = (radius, 0, 0)
        case Mesh(filename, scale):
            geom.type = mujoco.mjtGeom.mjGEOM_MESH
            geom.meshname = _add_mesh(spec, robot, filename, scale, mesh_name, line)


def _add_mesh(spec: mujoco.MjSpec, robot: RobotModel, filename: str, scale: tuple[float, ...],
              name: str,
              line: int | None = None) -> str:
    try:
        path = resolve_mesh(filename, robot.base_dir)
    except MexoneError as exc:
        raise ModelError(f"{exc.what}", file=robot.source, line=line, hint=exc.hint) from None
    if not path.is_file():
        raise ModelError(f"mesh file '{path}' does not exist", file=robot.source, line=line,
                         hint="check the filename, or run 'mexone check'")
    mesh = spec.add_mesh(name=name)
    mesh.scale = scale
    if _mujoco_reads(path):
        mesh.file = str(path)
    else:  # .dae, ASCII or huge STL and the rest: through trimesh, as `mexone check` reads them
        try:
            loaded = load_mesh(path)
        except MexoneError as exc:
            raise ModelError(exc.what, file=robot.source, line=line, hint=exc.hint) from None
        mesh.uservert = np.asarray(loaded.vertices, dtype=np.float32).ravel()
        mesh.userface = np.asarray(loaded.faces, dtype=np.int32).ravel()
    return name


def _mujoco_reads(path: Path) -> bool:
    """MuJoCo reads OBJ and binary STL up to 200k faces itself (faster than trimesh)."""
    suffix = path.suffix.lower()
    if suffix in (".obj", ".msh"):
        return True
    if suffix != ".stl":
        return False
    with path.open("rb") as handle:
        header = handle.read(84)
    if len(header) < 84:
        return False
    faces = int.from_bytes(header[80:84], "little")
    return 0 < faces <= _MJ_STL_MAX_FACES and path.stat().st_size == 84 + 50 * faces


def _add_geoms(spec: mujoco.MjSpec, body: mujoco.MjsBody, robot: RobotModel, name: str,
               options: CompileOptions, world: World,
               robot_mass: float) -> list[str]:
    link = robot.links[name]
    props = robot.gazebo_links.get(name, GazeboLink())
    contype, conaffinity = collision_bits(robot, name, options.self_collision)
    mu1, _, kp, kd = _surface(props)
    collision_names = []
    for i, col in enumerate(link.collisions):
        geom = body.add_geom(name=f"{name}/collision/{i}")
        _geom_shape(geom, col.geometry, spec, robot, f"{name}/collision_mesh/{i}", col.line)
        _set_pose(geom, col.origin.matrix)
        geom.group = GROUP_COLLISION
        geom.contype, geom.conaffinity = contype, conaffinity
        geom.friction = (mu1, 0.005, 0.0001)
        geom.priority = _friction_priority(mu1)
        geom.solref = _contact_solref(kp, kd, robot_mass, world.step)
        geom.rgba = (0.8, 0.45, 0.2, 0.5)
        geom.density = 0.0
        collision_names.append(geom.name)
    if options.visuals:
        for i, vis in enumerate(link.visuals):
            geom = body.add_geom(name=f"{name}/visual/{i}")
            _geom_shape(geom, vis.geometry, spec, robot, f"{name}/visual_mesh/{i}", vis.line)
            _set_pose(geom, vis.origin.matrix)
            geom.group = GROUP_VISUAL
            geom.contype = geom.conaffinity = 0
            geom.density = 0.0
            geom.rgba = display_rgba(robot, name, vis)
    return collision_names


def collision_bits(robot: RobotModel, link: str, self_collision: bool | None) -> tuple[int, int]:
    """(contype, conaffinity) of a link's collision geoms: links collide with each other when
    either has selfCollide (as Gazebo's ODE spaces do); `self_collision` overrides every link."""
    props = robot.gazebo_links.get(link, GazeboLink())
    on = bool(props.self_collide) if self_collision is None else self_collision
    return (_SELF, _SELF | _PLAIN) if on else (_PLAIN, _SELF)


def _friction_priority(mu: float) -> int:
    """Higher priority for lower friction, so a pair uses the smaller mu (ODE's min rule)."""
    return int(np.clip(round(-np.log10(max(mu, 1e-6)) * 100), -1000, 1000)) + 1000


def _add_contact_rules(spec: mujoco.MjSpec, robot: RobotModel, world: World, geoms: dict[str, list[str]],
                       robot_mass: float) -> None:
    lump = _lumps(robot)
    # never across a joint: every link of the parent lump against every link of the child lump
    members: dict[str, list[str]] = {}
    for name, root in lump.items():
        if name != "world":
            members.setdefault(root, []).append(name)
    excluded: set[tuple[str, str]] = set()
    for group in members.values():  # links welded together
        for i, a in enumerate(group):
            for b in group[i + 1:]:
                excluded.add((a, b))
    for joint in robot.joints.values():
        if joint.type == "fixed" or joint.parent == "world":
            continue
        for a in members[lump[joint.parent]]:
            for b in members[lump[joint.child]]:
                excluded.add((a, b))
    for a, b in sorted(excluded):
        spec.add_exclude(bodyname1=a, bodyname2=b)
    if world.ground is None:
        return
    for name, names in geoms.items():
        mu1, mu2, kp, kd = _surface(robot.gazebo_links.get(name, GazeboLink()))
        # ODE combines a pair: springs in series, dampers summed (the ground has the defaults)
        kp, kd = 1.0 / (1.0 / kp + 1.0 / _GAZEBO_KP), kd + _GAZEBO_KD
        for geom in names:
            spec.add_pair(name=f"ground/{geom}", geomname1="ground_plane", geomname2=geom,
                          condim=3,
                          friction=(min(mu1, world.ground.mu1), min(mu2, world.ground.mu2),
                                    0.005, 0.0001, 0.0001),
                          solref=_contact_solref(kp, kd, robot_mass, world.step))


def _add_mimics(spec: mujoco.MjSpec, robot: RobotModel) -> None:
    """URDF <mimic>: q_follower = offset + multiplier * q_leader, a joint equality constraint."""
    for joint in robot.joints.values():
        if joint.mimic is None:
            continue
        spec.add_equality(type=mujoco.mjtEq.mjEQ_JOINT, name=f"mimic/{joint.name}",
                          objtype=mujoco.mjtObj.mjOBJ_JOINT, name1=joint.name, name2=joint.mimic.joint,
                          data=np.r_[joint.mimic.offset, joint.mimic.multiplier, np.zeros(10)])


def _no_second_factorisation(spec: mujoco.MjSpec) -> None:
    """Without actuators (or fluid) the only velocity-dependent force is joint damping, which
    MuJoCo's Euler also integrates implicitly: implicitfast and Euler compute the same step, but
    Euler reuses the mass matrix's factorisation when nothing is damped (a 900-link chain: 25 of
    61 ms a step were the second factorisation)."""
    if (spec.option.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST and not spec.actuators
            and spec.option.density == 0 and spec.option.viscosity == 0):
        spec.option.integrator = mujoco.mjtIntegrator.mjINT_EULER


def _size_for_large_models(spec: mujoco.MjSpec, robot: RobotModel, collision_geoms: int) -> None:
    """Big trees: CG instead of Newton, and an arena for every geom touching the ground at
    once (MuJoCo's own estimate ran out at 3600 contacts on 900 dofs and aborted the process)."""
    nv = 6 + sum(j.moving for j in robot.joints.values())
    if nv <= _LARGE_NV:
        return
    spec.option.solver = mujoco.mjtSolver.mjSOL_CG
    rows = _CONTACTS_PER_GEOM * 3 * collision_geoms + nv  # condim 3, plus joint limits
    needed = rows * nv * 9  # bytes: the solver's constraint Jacobian, measured
    if needed > 32 << 20:
        spec.memory = int(needed * 1.25) + (96 << 20)

