"""What can be identified, one rule each: where the value lives in MuJoCo and in the URDF, its
unit, its typical size (the optimiser works in multiples of it) and its bounds.

Every unknown is a `mujoco.sysid.Parameter` whose value is the physical value divided by its
scale, so all of them are of order 1: the optimiser's steps, its finite-difference steps and the
covariance are all conditioned the same way whether the unknown is 0.01 kg m^2 or 300 N m/rad.
Joint and link unknowns edit the MjSpec (as the URDF would); controller gains are fields the
controllers write into the compiled model, so they are applied after compiling.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from mujoco import sysid

from mexone.control.hardware import motor_gains, set_motor_gain
from mexone.description.model import RobotModel
from mexone.errors import InputError

__all__ = ["KINDS", "Unknown", "Kind", "unknowns_for", "check_kinds", "parameter_dict", "apply_to_model",
           "JOINT_KINDS", "LINK_KINDS", "delay_unknown", "DELAY", "DELAY_RANGE"]


@dataclass(frozen=True)
class Kind:
    name: str
    of: str  # "joint" or "link"
    unit: str
    what: str  # for --help and the report


KINDS: dict[str, Kind] = {k.name: k for k in (
    Kind("damping", "joint", "N m s/rad", "viscous friction, URDF <dynamics damping>"),
    Kind("frictionloss", "joint", "N m", "Coulomb friction, URDF <dynamics friction>"),
    Kind("armature", "joint", "kg m^2", "rotor inertia through the gearbox, <dynamics armature>"),
    Kind("mass", "link", "kg", "link mass, URDF <inertial><mass>"),
    Kind("com", "link", "m", "centre of mass, URDF <inertial><origin xyz>"),
    Kind("gains", "joint", "N m/rad, N m s/rad", "the position controller's p and d, in the YAML"),
)}
DELAY = Kind("delay", "bag", "s", "when the commands acted, relative to their receive times")
DELAY_SCALE = 0.005  # s: a few milliseconds of network and driver
DELAY_RANGE = 0.25  # s either way: a loaded ROS graph delivers /clock late by 100 ms and more
JOINT_KINDS = tuple(k for k, v in KINDS.items() if v.of == "joint")
LINK_KINDS = tuple(k for k, v in KINDS.items() if v.of == "link")
_COM_SCALE = 0.05  # m: a centre of mass is known to a few centimetres
_COM_RANGE = 0.2  # m either side of the URDF's


@dataclass(frozen=True)
class Unknown:
    """One scalar to identify. `name` is what reports and --json show: kind:target[.component]."""

    kind: str
    target: str  # joint or link name
    component: str  # "", "x"/"y"/"z" (com) or "p"/"d" (gains)
    nominal: float  # the model's value
    scale: float  # a typical size: the optimiser sees value / scale
    lower: float
    upper: float

    @property
    def name(self) -> str:
        return f"{self.kind}:{self.target}" + (f".{self.component}" if self.component else "")

    @property
    def unit(self) -> str:
        if self.kind == "gains":
            return "N m/rad" if self.component == "p" else "N m s/rad"
        return DELAY.unit if self.nuisance else KINDS[self.kind].unit

    @property
    def nuisance(self) -> bool:
        """Not a property of the robot: fitted, reported, never written into a model file."""
        return self.kind == DELAY.name

    @property
    def on_model(self) -> bool:
        """Applied to the compiled model (controller gains) rather than to the spec."""
        return self.kind == "gains"

    def apply_spec(self, spec: mujoco.MjSpec, value: float) -> None:
        if self.kind == "damping":
            joint = spec.joint(self.target)
            damping = np.array(joint.damping, dtype=float)
            damping[0] = value
            joint.damping = damping
        elif self.kind == "frictionloss":
            spec.joint(self.target).frictionloss = value
        elif self.kind == "armature":
            spec.joint(self.target).armature = value
        elif self.kind == "mass":
            spec.body(self.target).mass = value
        elif self.kind == "com":
            body = spec.body(self.target)
            ipos = np.array(body.ipos, dtype=float)
            ipos["xyz".index(self.component)] = value
            body.ipos = ipos

    def apply_model(self, model: mujoco.MjModel, value: float) -> None:
        set_motor_gain(model, model.actuator(self.target).id, self.component, value)


def check_kinds(kinds) -> list[str]:
    """--params as given: at least one, each a kind of `KINDS`, none twice (before any bag is
    read, so a typo costs no replay)."""
    kinds = list(kinds)
    bad = [k for k in kinds if k not in KINDS]
    if bad:
        raise InputError(f"--params: unknown parameter {', '.join(bad)}",
                         hint="choose from " + ",".join(KINDS))
    if not kinds:
        raise InputError("--params names no parameter to fit",
                         hint="choose from " + ",".join(KINDS))
    return list(dict.fromkeys(kinds))


def unknowns_for(kinds: list[str], joints: list[str], links: list[str], robot: RobotModel,
                 model: mujoco.MjModel) -> list[Unknown]:
    """The unknowns of each kind for the joints (joint kinds) and links (link kinds), with their
    nominal values read from the compiled nominal model."""
    kinds = check_kinds(kinds)
    if any(KINDS[k].of == "link" for k in kinds) and not links:
        raise InputError(f"--params {','.join(k for k in kinds if KINDS[k].of == 'link')} needs "
                         "--links: which links to weigh", hint="e.g. --links torso")
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    inertia = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, inertia)
    out: list[Unknown] = []
    for kind in kinds:
        for target in (joints if KINDS[kind].of == "joint" else links):
            out += _unknowns(kind, target, robot, model, np.diag(inertia))
    return out


def _unknowns(kind: str, target: str, robot: RobotModel, model: mujoco.MjModel,
              inertia: np.ndarray) -> list[Unknown]:
    """inertia: the mass matrix's diagonal at the start (armature included)."""
    if KINDS[kind].of == "link":
        if target not in robot.links:
            raise InputError(f"--links: the model has no link '{target}'",
                             hint="links: " + ", ".join(robot.links))
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, target)
        if body < 0:
            raise InputError(f"--links: link '{target}' is merged into its parent by a fixed "
                             "joint, so it has no mass of its own to identify",
                             hint="weigh the link it is fixed to")
        if kind == "mass":
            mass = float(model.body_mass[body])
            return [Unknown("mass", target, "", mass, mass, 0.1 * mass, 5.0 * mass)]
        ipos = model.body_ipos[body]
        return [Unknown("com", target, axis, float(ipos[i]), _COM_SCALE, float(ipos[i]) - _COM_RANGE,
                        float(ipos[i]) + _COM_RANGE) for i, axis in enumerate("xyz")]
    joint = model.joint(target)
    dof = int(joint.dofadr[0])
    motor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, target)
    kp = kd = 0.0
    if motor >= 0:
        kp, kd = motor_gains(model, motor)
    if kind == "damping":
        nominal = float(model.dof_damping[dof])
        scale = nominal or 0.1 * kd or 0.1
        return [Unknown(kind, target, "", nominal, scale, 0.0, 10.0 * scale)]
    if kind == "frictionloss":
        nominal = float(model.dof_frictionloss[dof])
        effort = robot.joints[target].limit.effort if robot.joints[target].limit else 0.0
        scale = nominal or 0.01 * effort or 0.05
        return [Unknown(kind, target, "", nominal, scale, 0.0, 10.0 * scale)]
    if kind == "armature":
        nominal = float(model.dof_armature[dof])
        links = float(inertia[dof]) - nominal  # what the joint moves, seen from its axis
        scale = nominal or 0.1 * links or 1e-3
        return [Unknown(kind, target, "", nominal, scale, 0.0, 10.0 * max(scale, links))]
    if motor < 0 or kp <= 0:
        raise InputError(f"--params gains: joint '{target}' has no position controller with a p "
                         "gain to identify", hint="leave it out with --joints")
    return [Unknown("gains", target, "p", kp, kp, 0.1 * kp, 10.0 * kp),
            Unknown("gains", target, "d", kd, kd or 0.05 * kp, 0.0, 10.0 * (kd or 0.05 * kp))]


def delay_unknown(bag: str) -> Unknown:
    """A bag's command delay: commands (Float64) carry no stamp, only when the bag received them,
    a few milliseconds after they were sent -- and a fit reads a few milliseconds of delay in a
    servo loop as damping and inertia. So the delay is fitted too, one per bag."""
    return Unknown(DELAY.name, bag, "", 0.0, DELAY_SCALE, -DELAY_RANGE, DELAY_RANGE)


def parameter_dict(unknowns: list[Unknown]) -> sysid.ParameterDict:
    """sysid parameters in scaled units; spec-side ones carry their modifier."""
    params = sysid.ParameterDict()
    for u in unknowns:
        modifier = None if u.on_model or u.nuisance else (
            lambda spec, p, u=u: u.apply_spec(spec, float(p.value[0]) * u.scale))
        params.add(sysid.Parameter(u.name, u.nominal / u.scale, u.lower / u.scale,
                                   u.upper / u.scale, modifier=modifier))
    return params


def apply_to_model(unknowns: list[Unknown], params: sysid.ParameterDict,
                   model: mujoco.MjModel) -> None:
    """The unknowns that live in the compiled model (controller gains)."""
    for u in unknowns:
        if u.on_model:
            u.apply_model(model, float(params[u.name].value[0]) * u.scale)
