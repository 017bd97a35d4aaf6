"""More models in a running world (gazebo_ros' spawn_urdf_model and delete_model): another
RobotModel compiled as the robot is, by compile_model, and attached to the world's MjSpec under a
prefix ("<name>/"), touching the ground and every robot link; MuJoCo recompiles the model and
carries the state over. The simulation's robot keeps its ids (new bodies come after it)."""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from mexone.description.model import RobotModel
from mexone.errors import InputError
from mexone.physics.compile import _PLAIN, _SELF, CompileOptions, Spawn, SpecEdit, compile_model
from mexone.physics.world import World

__all__ = ["attach_model", "detach_model", "carry_over", "TOUCH_ALL", "RUNTIME_ACTUATOR_FIELDS"]

TOUCH_ALL = _SELF | _PLAIN  # contype/conaffinity that meets both kinds of robot link (compile.collision_bits)
# The actuator fields a running simulation's model changes after it compiled: the controllers'
# gains and clamps, which control.hardware.SimHardware.write() sets (tests/control checks that
# it writes exactly these). Recompiling, and identification's replays, carry them over.
RUNTIME_ACTUATOR_FIELDS = ("actuator_biasprm", "actuator_gainprm", "actuator_forcerange",
                           "actuator_actrange", "actuator_actlimited")
_OPTION_FIELDS = ("timestep", "gravity", "iterations", "disableflags", "solver")


def attach_model(spec: mujoco.MjSpec, robot: RobotModel, name: str, world: World,
                 spawn: Spawn, edits: Sequence[SpecEdit] = (), touch_all: bool = True) -> str:
    """Add `robot` to `spec` as model `name`; returns the MuJoCo name of its root body.
    `touch_all`: its geoms meet every robot link (a free object), else they keep the collision
    bits its own <gazebo selfCollide> gives them (a second robot)."""
    prefix = f"{name}/"
    if any(b.name.startswith(prefix) for b in spec.bodies):
        raise InputError(f"a model named '{name}' already exists", hint="pick another name")
    child = compile_model(robot, world, spawn, CompileOptions(visuals=True), edits).spec
    if touch_all:
        for geom in child.geoms:  # free objects meet every robot link, whatever its selfCollide
            if geom.contype or geom.conaffinity:
                geom.contype = geom.conaffinity = TOUCH_ALL
    else:
        _own_collision_bits(spec, child)
    spec.attach(child, prefix=prefix, frame=spec.worldbody.add_frame())
    for pair in spec.pairs:  # the child's ground pairs: with the world's own ground plane
        if pair.name.startswith(prefix) and pair.geomname1 == prefix + "ground_plane":
            pair.geomname1 = "ground_plane"
    for kind, element in (("geom", "ground_plane"), ("light", "sun"), ("material", "ground"),
                          ("texture", "ground_checker")):
        found = getattr(spec, kind)(prefix + element)
        if found is not None:
            spec.delete(found)
    return prefix + robot.base_link


def _own_collision_bits(spec: mujoco.MjSpec, child: mujoco.MjSpec) -> None:
    """A second robot: its links keep their selfCollide rules among themselves on a bit pair of
    their own (compile.collision_bits' pair shifted), and meet every link already in the world."""
    used = 0
    for geom in spec.geoms:
        used |= geom.contype | geom.conaffinity
    shift = max(2, (used.bit_length() + 1) // 2 * 2 - 1)  # the next free pair of bits
    own_self, own_plain = 1 << shift, 1 << (shift + 1)
    if own_plain >= 1 << 31:
        raise InputError("too many robots in one world for MuJoCo's 32 collision bits")
    others = (own_self - 1) & ~1  # every bit below: the links of the robots already there
    for geom in child.geoms:
        if geom.contype == _SELF:  # touches every link of its robot
            geom.contype, geom.conaffinity = own_self, own_self | own_plain | others
        elif geom.contype == _PLAIN:  # touches its robot's selfCollide links
            geom.contype, geom.conaffinity = own_plain, own_self | others


def detach_model(spec: mujoco.MjSpec, name: str) -> None:
    prefix = f"{name}/"
    bodies = [b for b in spec.bodies if b.name.startswith(prefix) and b.parent.name == "world"]
    if not bodies:
        raise InputError(f"no model named '{name}' was spawned")
    for pair in [p for p in spec.pairs if p.name.startswith(prefix)]:
        spec.delete(pair)
    for exclude in [e for e in spec.excludes if e.name.startswith(prefix)
                    or e.bodyname1.startswith(prefix)]:
        spec.delete(exclude)
    for body in bodies:
        spec.delete(body)


def carry_over(old: mujoco.MjModel, new: mujoco.MjModel) -> None:
    """What the simulation changed on `old` at run time (PID gains, physics settings, collision
    bits) onto `new`: recompiling starts from the spec, which does not hold them."""
    same = [(a, mujoco.mj_name2id(new, mujoco.mjtObj.mjOBJ_ACTUATOR, old.actuator(a).name))
            for a in range(old.nactuator)]  # by name: actuators of an added or deleted model move ids
    same = [(a, b) for a, b in same if b >= 0]
    if same:
        src, dst = (np.array(ids) for ids in zip(*same, strict=True))
        for field in RUNTIME_ACTUATOR_FIELDS:
            getattr(new, field)[dst] = getattr(old, field)[src]
    for field in _OPTION_FIELDS:
        value = getattr(old.opt, field)
        if isinstance(value, np.ndarray):
            getattr(new.opt, field)[:] = value
        else:
            setattr(new.opt, field, value)
    for geom in range(old.ngeom):
        name = old.geom(geom).name
        if name and mujoco.mj_name2id(new, mujoco.mjtObj.mjOBJ_GEOM, name) == geom:
            new.geom_contype[geom] = old.geom_contype[geom]
            new.geom_conaffinity[geom] = old.geom_conaffinity[geom]
