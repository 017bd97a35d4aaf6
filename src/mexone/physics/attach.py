"""More models in a running world (gazebo_ros' spawn_urdf_model and delete_model): another
RobotModel compiled as the robot is, by compile_model, and attached to the world's MjSpec under a
prefix ("<name>/"), touching the ground and every robot link; MuJoCo recompiles the model and
carries the state over. The simulation's robot keeps its ids (new bodies come after it)."""

from __future__ import annotations

import mujoco
import numpy as np

from mexone.description.model import RobotModel
from mexone.errors import InputError
from mexone.physics.compile import CompileOptions, Spawn, compile_model
from mexone.physics.world import World

__all__ = ["attach_model", "detach_model", "carry_over", "TOUCH_ALL"]

TOUCH_ALL = 2 | 4  # contype/conaffinity that meets both kinds of robot link (compile.collision_bits)
# what the running simulation may have changed on its model since it compiled (gains, physics)
_ACTUATOR_FIELDS = ("actuator_biasprm", "actuator_gainprm", "actuator_forcerange", "actuator_actrange",
                    "actuator_actlimited", "actuator_forcelimited", "actuator_ctrlrange")
_OPTION_FIELDS = ("timestep", "gravity", "iterations", "disableflags", "solver")


def attach_model(spec: mujoco.MjSpec, robot: RobotModel, name: str, world: World,
                 spawn: Spawn) -> str:
    """Add `robot` to `spec` as model `name`; returns the MuJoCo name of its root body."""
    prefix = f"{name}/"
    if any(b.name.startswith(prefix) for b in spec.bodies):
        raise InputError(f"a model named '{name}' already exists", hint="pick another name")
    child = compile_model(robot, world, spawn, CompileOptions(visuals=True)).spec
    for geom in child.geoms:  # free objects meet every robot link, whatever its selfCollide
        if geom.contype or geom.conaffinity:
            geom.contype = geom.conaffinity = TOUCH_ALL
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
    if old.nu == new.nu:
        for field in _ACTUATOR_FIELDS:
            getattr(new, field)[:] = getattr(old, field)
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
