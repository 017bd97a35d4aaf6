"""Linear models of the simulated robot: `linearize` and `operating_point` (issue 32 items 1, 2).

`linearize` differentiates the simulation's own step (`mujoco.mjd_transitionFD`, centred finite
differences, through the contacts as simulated), so the model is the discrete map the physics
applies: x[k+1] = A x[k] + B u[k], y[k] = C x[k] + D u[k] in deviations from the point, at the
time step or at a controller's period with the input held (the steps' Jacobians chained along
the held-input rollout). It returns a python-control `StateSpace` with named signals:

states (tangent space, nx = 2 nv + the actuator states that act on something)
    `<joint>:q` then `<joint>:dq` for hinge and slide joints; a floating base as
    `base:x base:y base:z` (position, world frame), `base:rx base:ry base:rz` (rotation vector,
    root link's frame), `base:vx base:vy base:vz` (world frame) and `base:wx base:wy base:wz`
    (root link's frame), exactly MuJoCo's qvel convention (see mexone.dynamics); other free or ball
    joints the same with their own name; then `<actuator>:act` for actuator states (the PID's
    integral `<joint>/i:act` while its ki is not zero). `state_deviation` turns a measured
    (qpos, qvel, act) into this x (`mj_differentiatePos`: a quaternion has no plain difference).
inputs
    "effort": `<joint>:effort`, the joint torque through each motor's feed-forward input (N m);
    those joints' own PD and I terms are off in the model, as an effort controller claims them,
    so A is the open-loop plant. "position": `<joint>:position`, the PID's setpoint (rad), the
    loop closed by its gains as set now; "velocity": `<joint>:velocity`, its velocity setpoint
    (rad/s), likewise. "ctrl": every MuJoCo control as is (any model).
    Joints not among `joints` keep their controllers as set (held at their setpoints).
outputs
    MuJoCo sensors by name (`imu/gyro:x`...), from MuJoCo's sensor derivatives; "com" (the
    centre of mass, `com:x`...) and "pose:<frame>" (its position and small rotation, world
    frame, `<frame>:x` ... `<frame>:rz`) from the Jacobians; by default the states (C = I).

A reduced model (`held="rigid"`: the joints outside `joints` welded at their current angles;
`fixed_base=True`: the root welded where it is) is a recompiled copy of the model: fewer states,
nothing else approximated.
"""

from __future__ import annotations

import copy
import functools
import threading
import weakref
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import control
import mujoco
import numpy as np
from numpy.typing import ArrayLike

from mexone.control.hardware import (
    INTEGRAL_SUFFIX,
    ControlLayout,
    clear_integrals,
    copy_actuator_state,
    set_hold_controls,
    set_integral_gain,
    set_motor_gain,
)
from mexone.dynamics import Dynamics
from mexone.errors import ArgumentTypeError, InputError, printable
from mexone.physics.attach import RUNTIME_ACTUATOR_FIELDS
from mexone.ranges import SAMPLE_PERIOD

__all__ = ["linearize", "operating_point", "OperatingPoint", "Linearization", "state_deviation",
           "INPUT_KINDS", "SUPPORTS"]

#: what linearize's inputs may be: the joints' effort, position or velocity commands, or MuJoCo's ctrl
INPUT_KINDS = ("effort", "position", "velocity", "ctrl")
#: what operating_point may stand the robot on: both feet, one, or nothing (the base held)
SUPPORTS = ("both", "left", "right", "fixed")
_FEET = {"both": ("l_foot", "r_foot"), "left": ("l_foot",), "right": ("r_foot",), "fixed": ()}
_BASE = "base"
_FREE_POS = ("x", "y", "z", "rx", "ry", "rz")
_FREE_VEL = ("vx", "vy", "vz", "wx", "wy", "wz")
_FREE, _BALL = int(mujoco.mjtJoint.mjJNT_FREE), int(mujoco.mjtJoint.mjJNT_BALL)
_SCALAR_JOINTS = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))


# ----- what we linearise: a private copy of a model and its state ------------------------------
@dataclass
class _Plant:
    model: mujoco.MjModel
    data: mujoco.MjData
    joints: list[str]  # actuated joints (mexone's motor + integral actuators), hardware order
    root_joint: str | None = None  # the robot's free joint
    spec: mujoco.MjSpec | None = None
    feet: tuple[str, ...] = ()
    qpos_index: np.ndarray = field(default_factory=lambda: np.zeros(0, int))  # its qpos in the source's
    qvel_index: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    shared: bool = False  # the source's own model (edits undone after): `Linearization` snapshots


def _take(source: Any, data: mujoco.MjData | None, who: str = "linearize") -> _Plant:
    """A copy of the source's model (its gains as set now) and state, taken in the simulation
    thread when a loop runs in another one."""
    if isinstance(source, mujoco.MjModel):
        if not isinstance(data, mujoco.MjData):
            raise ArgumentTypeError(f"{who}(model, data): give the MjData of the state too")
        return _copy_plant(source, data, [], None, None, ())
    sim = getattr(source, "sim", source)
    if not hasattr(sim, "work") or not hasattr(sim, "compiled"):
        raise ArgumentTypeError(f"{who} takes a mexone Lab or Simulation, or a mujoco.MjModel "
                                f"and its MjData, not {type(source).__name__}")

    def take() -> _Plant:
        model = sim.model
        joints = [j.name for j in sim.robot.actuated_joints
                  if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, j.name) >= 0]
        root = None
        if sim.compiled.free:
            body = sim.compiled.root_body
            root = model.joint(int(model.body_jntadr[body])).name
        feet = tuple(f for f in ("l_foot", "r_foot") if f in sim.compiled.bodies)
        return _copy_plant(model, sim.data, joints, root, sim.compiled.spec, feet)

    if not sim.loop_elsewhere():
        return take()
    return sim.work.call(take)


def _sim_of(source: Any) -> Any:
    """The Simulation behind a Lab or Simulation source, None for a bare MjModel."""
    if isinstance(source, mujoco.MjModel):
        return None
    return getattr(source, "sim", source)


def _live(source: Any, data: mujoco.MjData | None) -> _Plant:
    """The source's own model (not a copy: `_edits_undone` restores what linearize changes) and
    a scratch copy of its state; called in the simulation thread. Copying the 3 MB model and
    allocating an MjData cost more than the finite differences' bookkeeping (issue 38)."""
    if isinstance(source, mujoco.MjModel):
        if not isinstance(data, mujoco.MjData):
            raise ArgumentTypeError("linearize(model, data): give the MjData of the state too")
        joints: list[str] = []
        feet: tuple[str, ...] = ()
        model, live, root, spec = source, data, None, None
    else:
        sim = source
        model, live, spec = sim.model, sim.data, sim.compiled.spec
        joints, root, feet = _robot_layout(sim)
    scratch = _scratch(model)
    mujoco.mj_copyData(scratch, model, live)
    return _Plant(model, scratch, joints, root, spec, feet, np.arange(model.nq), np.arange(model.nv),
                  shared=True)


_LAYOUT: weakref.WeakKeyDictionary[Any, tuple[list[str], str | None, tuple[str, ...]]] = \
    weakref.WeakKeyDictionary()  # model -> (joints, root, feet)
_SCRATCH: weakref.WeakKeyDictionary[Any, list[Any]] = weakref.WeakKeyDictionary()  # model -> [MjData, MjData]
_SCRATCH_LOCK = threading.Lock()


def _robot_layout(sim: Any) -> tuple[list[str], str | None, tuple[str, ...]]:
    model = sim.model
    cached = _LAYOUT.get(model)
    if cached is None:
        joints = [j.name for j in sim.robot.actuated_joints if _actuator(model, j.name) >= 0]
        root = None
        if sim.compiled.free:
            root = model.joint(int(model.body_jntadr[sim.compiled.root_body])).name
        feet = tuple(f for f in ("l_foot", "r_foot") if f in sim.compiled.bodies)
        cached = _LAYOUT[model] = (joints, root, feet)
    return list(cached[0]), cached[1], cached[2]


def _scratch(model: mujoco.MjModel, which: int = 0) -> mujoco.MjData:
    """One of two MjData kept per model for linearize's state and its held-input rollout (the
    caller holds _SCRATCH_LOCK)."""
    pair = _SCRATCH.get(model)
    if pair is None:
        pair = _SCRATCH[model] = [mujoco.MjData(model), None]
    if pair[which] is None:
        pair[which] = mujoco.MjData(model)
    return pair[which]


def _settings(model: mujoco.MjModel) -> tuple[tuple[str, Any], ...]:
    """What a model's copy needs to be the model as linearised: the fields a running simulation
    changes (the controllers' gains and clamps) and linearize's own (friction, flags)."""
    fields = (*RUNTIME_ACTUATOR_FIELDS, "dof_frictionloss")
    return (*((name, getattr(model, name).copy()) for name in fields),
            *((f"opt.{name}", copy.copy(getattr(model.opt, name))) for name in _OPTIONS))


_OPTIONS = ("timestep", "gravity", "disableflags", "enableflags", "integrator", "iterations")


@contextmanager
def _edits_undone(model: mujoco.MjModel) -> Iterator[None]:
    """What linearize changes in a model it does not own (the claimed joints' gains, the dry
    friction, the sensor flag) put back as it was, whatever happens."""
    saved = (model.actuator_biasprm.copy(), model.actuator_gainprm.copy(),
             model.dof_frictionloss.copy(), model.opt.disableflags)
    try:
        yield
    finally:
        model.actuator_biasprm[:], model.actuator_gainprm[:], model.dof_frictionloss[:] = saved[:3]
        model.opt.disableflags = saved[3]


def _copy_plant(source: mujoco.MjModel, data: mujoco.MjData, joints: list[str], root: str | None,
                spec: mujoco.MjSpec | None, feet: tuple[str, ...]) -> _Plant:
    model = copy.copy(source)
    copied = mujoco.MjData(model)
    mujoco.mj_copyData(copied, model, data)
    return _Plant(model, copied, joints, root, spec, feet,
                  np.arange(model.nq), np.arange(model.nv))


def _actuator(model: mujoco.MjModel, name: str) -> int:
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, name)


_IDS: weakref.WeakKeyDictionary[Any, dict[str, tuple[int, int, int]]] = \
    weakref.WeakKeyDictionary()  # model -> {joint: ids}


def _joint_ids(model: mujoco.MjModel, joint: str) -> tuple[int, int, int]:
    """(motor actuator, integral actuator, qpos address) of a joint, looked up once per model."""
    table = _IDS.get(model)
    if table is None:
        table = _IDS[model] = {}
    ids = table.get(joint)
    if ids is None:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint)
        ids = table[joint] = (_actuator(model, joint), _actuator(model, joint + INTEGRAL_SUFFIX),
                              int(model.jnt_qposadr[jid]) if jid >= 0 else -1)
    return ids


# ----- operating points --------------------------------------------------------------------------
@dataclass(frozen=True)
class OperatingPoint:
    """A pose held still: `qpos` (nq,), the joint torques `efforts` (N m, one per name in
    `joints`) that hold it, and the `residual` (6,): the force (N, world frame) and torque
    (N m, about the root link's axes: the free joint's coordinates) on the base that no actuator
    can give (zero when the pose balances on its support; for support="fixed",
    what the weld carries). `contacts`: the links touching the ground."""

    qpos: np.ndarray
    joints: tuple[str, ...]
    efforts: np.ndarray
    residual: np.ndarray
    support: str
    contacts: tuple[str, ...] = ()

    def effort(self, joint: str) -> float:
        """The torque holding one joint (N m)."""
        return float(self.efforts[self.joints.index(joint)])


def operating_point(source: Any, pose: Mapping[str, float] | None = None, support: str = "both",
                    data: mujoco.MjData | None = None) -> OperatingPoint:
    """The joint torques that hold `pose` (joint -> angle; the others as now) still on its
    support, by inverse dynamics through the contacts (MuJoCo's LQR tutorial: mj_inverse at zero
    velocity and acceleration, the base's height searched until the contacts carry the weight).
    support: "both", "left", "right" (those feet, and only those, on the ground: a lifted foot
    must be lifted by the pose) or "fixed" (no ground: the base held where it is)."""
    if support not in SUPPORTS:
        raise InputError(f"support '{support}' is not one of {', '.join(SUPPORTS)}")
    plant = _take(source, data, "operating_point")
    model, d = plant.model, plant.data
    if pose is not None and not isinstance(pose, Mapping):
        raise ArgumentTypeError("operating_point: pose is a mapping of joint names to angles (rad)")
    for name, value in (pose or {}).items():
        joint = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if joint < 0 or int(model.jnt_type[joint]) not in _SCALAR_JOINTS:
            raise InputError(f"pose names {name!r}, which is not a hinge or slide joint of the model",
                             hint="joints: " + ", ".join(plant.joints or _joint_names(model)))
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise InputError(f"pose angle of {name!r} is not a number") from None
        if not np.isfinite(value):
            raise InputError(f"pose angle of {name!r} is not finite")
        low, high = model.jnt_range[joint]
        if model.jnt_limited[joint] and not low - 1e-9 <= value <= high + 1e-9:
            raise InputError(f"pose angle {value:g} of {name!r} is outside its limits [{low:g}, {high:g}]")
        d.qpos[model.jnt_qposadr[joint]] = value
    d.qvel[:] = 0.0
    d.qacc[:] = 0.0
    if plant.root_joint is None and support != "fixed":
        raise InputError(f"support '{support}' needs a floating base; this model has none",
                         hint="use support='fixed'")
    base = slice(0, 6) if plant.root_joint is not None else slice(0, 0)
    contacts: tuple[str, ...] = ()
    if support == "fixed":
        saved = model.opt.disableflags
        model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
        mujoco.mj_inverse(model, d)
        model.opt.disableflags = saved
    else:
        feet = _FEET[support]
        missing = [f for f in feet if f not in plant.feet]
        if missing:
            raise InputError(f"support '{support}' needs links {', '.join(feet)}; the robot has no "
                             f"{', '.join(missing)}", hint="use support='fixed'")
        _settle_height(plant)
        contacts = _touching(plant)
        if set(contacts) != set(feet):
            raise InputError(f"support '{support}': in this pose {', '.join(contacts) or 'nothing'} "
                             f"touches the ground, not {' and '.join(feet)} alone",
                             hint="lift the other foot in the pose (hip, knee) or choose the "
                                  "support that touches")
    adr = [int(model.jnt_dofadr[model.joint(j).id]) for j in plant.joints]
    residual = np.zeros(6)
    residual[: base.stop] = d.qfrc_inverse[base]
    return OperatingPoint(qpos=d.qpos.copy(), joints=tuple(plant.joints),
                          efforts=d.qfrc_inverse[adr].copy(), residual=residual, support=support,
                          contacts=contacts)


def _joint_names(model: mujoco.MjModel) -> list[str]:
    return [model.joint(i).name for i in range(model.njnt)]


def _settle_height(plant: _Plant) -> None:
    """Bisect the base's height until the contacts carry the weight: the vertical force the base
    itself would need (qfrc_inverse[2]) is zero (it falls monotonically with depth)."""
    model, d = plant.model, plant.data

    def need(z: float) -> float:
        d.qpos[2] = z
        mujoco.mj_inverse(model, d)
        return float(d.qfrc_inverse[2])

    high = d.qpos[2]
    for _ in range(60):  # up until nothing touches
        if need(high) > 0 and d.ncon == 0:
            break
        high += 0.05
    low = high
    for _ in range(200):  # down until the ground pushes more than the weight
        low -= 0.01
        if need(low) < 0:
            break
    else:
        raise InputError("no base height puts the robot's weight on the ground in this pose")
    for _ in range(60):
        mid = 0.5 * (low + high)
        if need(mid) > 0:
            high = mid
        else:
            low = mid
    need(0.5 * (low + high))


def _touching(plant: _Plant) -> tuple[str, ...]:
    model, d = plant.model, plant.data
    names = set()
    for i in range(d.ncon):
        for geom in d.contact[i].geom:
            body = int(model.geom_bodyid[geom])
            if body != 0:
                names.add(model.body(body).name)
    return tuple(sorted(names))


# ----- linearisation -----------------------------------------------------------------------------
@dataclass(frozen=True)
class Linearization:
    """Where a model was linearised, attached to the StateSpace as `sys.linearization`:
    `qpos`, `qvel`, `act` (the full state of the linearised model), `u0` (the inputs' values
    there), `period`, which source entries the model's qpos/qvel are (reduced models), and
    `model`: the MuJoCo model as linearised (the claimed joints' PD off, the dry friction out),
    to simulate against the linear model."""

    source: mujoco.MjModel  # the model linearised (a Lab's live one: its layout, never edited)
    qpos: np.ndarray
    qvel: np.ndarray
    act: np.ndarray
    act_rows: np.ndarray  # the act entries kept as states
    u0: np.ndarray
    period: float
    qpos_index: np.ndarray
    qvel_index: np.ndarray
    names: tuple[str, ...] = field(default=())
    # (field, value) the source had while linearised; () = it is `model`
    settings: tuple[tuple[str, Any], ...] = ()
    ctrl: np.ndarray | None = None  # MuJoCo's controls at the point (the sensors' values there)

    @functools.cached_property
    def model(self) -> mujoco.MjModel:
        """The model as linearised: `source` itself, or a copy of a live model with the
        settings it was linearised with (made when first asked for: linearize never copies)."""
        if not self.settings:
            return self.source
        model = copy.copy(self.source)
        for name, value in self.settings:
            if name.startswith("opt."):
                setattr(model.opt, name[4:], value)
            else:
                getattr(model, name)[:] = value
        return model

    def dx(self, qpos: ArrayLike, qvel: ArrayLike, act: ArrayLike | None = None) -> np.ndarray:
        """The state deviation x - x0 of a measured state: `qpos`, `qvel` (and `act`) of the
        simulation as read (full length; a reduced model picks its entries)."""
        q = np.asarray(qpos, dtype=float).reshape(-1)
        v = np.asarray(qvel, dtype=float).reshape(-1)
        if q.size > self.qpos.size:
            q = q[self.qpos_index]
        if v.size > self.qvel.size:
            v = v[self.qvel_index]
        if q.shape != self.qpos.shape or v.shape != self.qvel.shape:
            raise InputError(f"state has {q.size} positions and {v.size} velocities; the model "
                             f"needs nq = {self.qpos.size}, nv = {self.qvel.size}")
        dq = np.zeros(self.qvel.size)
        mujoco.mj_differentiatePos(self.source, dq, 1.0, self.qpos, q)
        out = [dq, v - self.qvel]
        if self.act_rows.size:
            a = self.act if act is None else np.asarray(act, dtype=float).reshape(-1)
            out.append(a[self.act_rows] - self.act[self.act_rows])
        return np.concatenate(out)


def state_deviation(sys: Any, qpos: ArrayLike, qvel: ArrayLike, act: ArrayLike | None = None) -> np.ndarray:
    """x - x0 for a StateSpace from `linearize`: the measured state in its coordinates."""
    point = getattr(sys, "linearization", None)
    if point is None:
        raise InputError("this StateSpace was not made by mexone.design.linearize")
    for name, values, own, index in (("qpos", qpos, point.qpos, point.qpos_index),
                                     ("qvel", qvel, point.qvel, point.qvel_index)):
        try:
            numbers = np.asarray(values, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise InputError(f"state_deviation: {name} is not a list of numbers") from None
        full = int(index.max()) + 1 if index.size else 0
        if numbers.size != own.size and numbers.size < full:  # neither the model's nor the robot's
            raise InputError(f"state_deviation: {name} has {numbers.size} values; give the "
                             f"simulation's whole {name} or the model's {own.size}")
        if not np.all(np.isfinite(numbers)):
            raise InputError(f"state_deviation: {name} has a NaN or inf")
    return point.dx(qpos, qvel, act)


def linearize(source: Any, data: mujoco.MjData | None = None, *, point: OperatingPoint | None = None,
              inputs: str = "effort", joints: Sequence[str] | None = None, held: str = "controllers",
              fixed_base: bool = False, outputs: Iterable[str] | None = None,
              period: float | None = None, joint_friction: bool = False,
              eps: float = 1e-6) -> control.StateSpace:
    """The discrete linear model of the simulated robot at its current state (or at `point`,
    from operating_point, at rest), see the module docstring for the signals.

    source: a Lab or Simulation (the state is copied in the simulation thread), or a
    mujoco.MjModel with `data`. joints: the joints with inputs (default: every actuated one);
    held: "controllers" (the others stay in the model, held by their PIDs as set) or "rigid"
    (welded at their angles: a reduced model); period: the sampling time (a multiple of the
    time step; default the time step), the input held over it. joint_friction: keep the joints'
    dry friction (URDF <dynamics friction>, MuJoCo frictionloss). It is not smooth at rest: a
    finite difference inside its stiction band sees the joints all but locked (on Mex-One's arm
    B comes out 10x too small), so by default it is left out, a disturbance to the design."""
    if inputs not in INPUT_KINDS:
        raise InputError(f"inputs '{inputs}' is not one of {', '.join(INPUT_KINDS)}")
    if held not in ("controllers", "rigid"):
        raise InputError(f"held '{held}' is not 'controllers' or 'rigid'")
    args = (point, inputs, joints, held, fixed_base, outputs, period, joint_friction, eps)
    if held == "rigid" or fixed_base:  # a recompiled private copy: built outside the loop's thread
        return _linearized(_take(source, data), *args)
    sim = _sim_of(source)
    if sim is not None and not (hasattr(sim, "work") and hasattr(sim, "compiled")):
        raise ArgumentTypeError(f"linearize takes a mexone Lab or Simulation, or a mujoco.MjModel "
                                f"and its MjData, not {type(source).__name__}")

    def work() -> control.StateSpace:  # in the simulation thread: the model is the live one
        with _SCRATCH_LOCK:
            plant = _live(sim if sim is not None else source, data)
            with _edits_undone(plant.model):
                return _linearized(plant, *args)

    return sim.work.call(work) if sim is not None and sim.loop_elsewhere() else work()


def _linearized(plant: _Plant, point: Any, inputs: Any, joints: Any, held: Any, fixed_base: Any,
                outputs: Any, period: Any, joint_friction: Any, eps: Any) -> control.StateSpace:
    """linearize's work on a plant taken from the source (its model changed freely: a copy, or
    the live one under `_edits_undone`)."""
    if point is not None:
        _apply(plant, point)
    if isinstance(joints, str):  # a string is a sequence of letters: 'l_elbow' is no joint list
        raise InputError(f"joints is the string {printable(joints, 60)!r}: give a list of joint names",
                         hint=f"joints=[{printable(joints, 60)!r}]")
    chosen = list(plant.joints if joints is None else joints)
    unknown = [j for j in chosen if j not in plant.joints]
    if unknown and inputs != "ctrl":
        raise InputError(f"{', '.join(map(repr, unknown))}: not an actuated joint of the model",
                         hint="actuated joints: " + (", ".join(plant.joints) or "none (no controllers)"))
    if inputs != "ctrl" and joints is not None and not chosen and plant.joints:
        raise InputError("joints is empty: name the joints that get inputs",
                         hint="actuated joints: " + ", ".join(plant.joints))
    if len(set(chosen)) != len(chosen):
        twice = next(j for j in chosen if chosen.count(j) > 1)
        raise InputError(f"joints names {twice!r} twice")
    if inputs != "ctrl" and not chosen:
        raise InputError(f"inputs '{inputs}' needs mexone's joint actuators; this model has none",
                         hint="use inputs='ctrl', or a Lab with controllers")
    if held == "rigid" or fixed_base:
        weld = [j for j in _moving_joints(plant) if j not in chosen] if held == "rigid" else []
        plant = _welded(plant, weld, fixed_base)
    model, d = plant.model, plant.data
    if inputs == "effort":
        _open_loop(model, chosen)
    if not joint_friction:
        model.dof_frictionloss[:] = 0.0
    steps = _steps(model, period)
    output_list = _check_outputs(model, outputs)
    if output_list is not None:
        model.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_SENSOR)

    nx, nu, ns = 2 * model.nv + model.na, model.nu, model.nsensordata
    c, dd = np.zeros((ns, nx)), np.zeros((ns, nu))
    x0 = (d.qpos.copy(), d.qvel.copy(), d.act.copy())
    a, b = np.eye(nx), np.zeros((nx, nu))
    rollout = d  # mjd_transitionFD leaves the state as it found it; a longer period steps a copy
    if steps > 1:
        rollout = _scratch(model, 1)
        mujoco.mj_copyData(rollout, model, d)
    for k in range(steps):
        ak, bk = np.empty((nx, nx)), np.empty((nx, nu))
        if k == 0 and output_list is not None:
            mujoco.mjd_transitionFD(model, rollout, eps, True, ak, bk, c, dd)
        else:
            mujoco.mjd_transitionFD(model, rollout, eps, True, ak, bk, None, None)
        a, b = (ak, bk) if k == 0 else (ak @ a, ak @ b + bk)
        if k + 1 < steps:
            mujoco.mj_step(model, rollout)

    u_map, input_names, u0 = _input_map(plant, chosen, inputs)
    b = b @ u_map
    state_names = _state_names(plant)
    output_names: list[str] = []
    c_all, d_all = np.zeros((0, nx)), np.zeros((0, b.shape[1]))
    if output_list is not None:
        c_all, d_all, output_names = _outputs(model, d, output_list, c, dd @ u_map)
    keep = _kept_states(model, a, c_all)
    a, b = a[np.ix_(keep, keep)], b[keep]
    state_names = [state_names[i] for i in keep]
    if output_list is None:
        c_out, d_out, output_names = np.eye(len(keep)), np.zeros((len(keep), b.shape[1])), state_names
    else:
        c_out, d_out = c_all[:, keep], d_all
    sys = control.ss(a, b, c_out, d_out, steps * model.opt.timestep, states=state_names,
                     inputs=input_names, outputs=output_names, name="robot")
    act_rows = np.array([i - 2 * model.nv for i in keep if i >= 2 * model.nv], dtype=int)
    settings = _settings(model) if plant.shared else ()
    sys.linearization = Linearization(source=model, settings=settings, qpos=x0[0], qvel=x0[1],
                                      act=x0[2], act_rows=act_rows, ctrl=d.ctrl.copy(),
                                      u0=u0, period=steps * model.opt.timestep,
                                      qpos_index=plant.qpos_index, qvel_index=plant.qvel_index,
                                      names=tuple(state_names))
    return sys


def _apply(plant: _Plant, point: OperatingPoint) -> None:
    """The point's pose at rest, every actuated joint's PID set to hold it with the point's
    torque as feed-forward (q_ref = q, no integral)."""
    model, d = plant.model, plant.data
    if point.qpos.shape != (model.nq,):
        raise InputError(f"the operating point has {point.qpos.size} positions; the model nq = {model.nq}")
    d.qpos[:] = point.qpos
    d.qvel[:] = 0.0
    clear_integrals(d)
    for joint, effort in zip(point.joints, point.efforts, strict=True):
        motor, integral, qpos_adr = _joint_ids(model, joint)
        if motor < 0:
            continue
        set_hold_controls(model, d, motor, integral, d.qpos[qpos_adr], effort)
    mujoco.mj_forward(plant.model, d)


def _open_loop(model: mujoco.MjModel, joints: Iterable[str]) -> None:
    """The effort-claimed joints' PD and I terms off, as an effort controller runs them."""
    for joint in joints:
        motor, integral, _ = _joint_ids(model, joint)
        set_motor_gain(model, motor, "p", 0.0)
        set_motor_gain(model, motor, "d", 0.0)
        if integral >= 0:
            set_integral_gain(model, integral, 0.0)


def _steps(model: mujoco.MjModel, period: float | None) -> int:
    step = model.opt.timestep
    if period is None:
        return 1
    SAMPLE_PERIOD.check(period, "period")
    steps = round(period / step)
    if steps < 1 or abs(steps * step - period) > 1e-9 * max(period, 1.0):
        raise InputError(f"period {period:g} s is not a multiple of the time step {step:g} s",
                         hint="choose a period the simulation's steps add up to")
    return steps


def _check_outputs(model: mujoco.MjModel, outputs: Iterable[str] | None) -> list[str] | None:
    if outputs is None:
        return None
    names = [outputs] if isinstance(outputs, str) else list(outputs)
    for name in names:
        if name == "com" or (isinstance(name, str) and name.startswith("pose:")):
            continue
        if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, name) < 0:
            listed = ", ".join(model.sensor(i).name for i in range(model.nsensor)) or "none"
            raise InputError(f"no sensor named {name!r} in the model",
                             hint=f"outputs: a sensor ({listed}), 'com', or 'pose:<frame>'")
    return names


def _outputs(model: mujoco.MjModel, data: mujoco.MjData, names: list[str], c: np.ndarray,
             dd: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Rows of C and D: a sensor's from MuJoCo's sensor derivatives; the centre of mass's and a
    frame's position and small rotation (world frame) from its Jacobian, whose columns are the
    tangent space's (so C = [J, 0], D = 0)."""
    nx, nu = c.shape[1], dd.shape[1]
    rows_c, rows_d, labels = [], [], []
    dyn = None
    for name in names:
        if name == "com" or name.startswith("pose:"):
            if dyn is None:
                state = mujoco.MjData(model)
                mujoco.mj_copyData(state, model, data)
                dyn = Dynamics(model, state, copy=False)
            jac = dyn.com_jacobian() if name == "com" else dyn.jacobian(name[len("pose:"):])
            block = np.zeros((jac.shape[0], nx))
            block[:, :model.nv] = jac
            rows_c.append(block)
            rows_d.append(np.zeros((jac.shape[0], nu)))
            prefix = "com" if name == "com" else _signal(name[len("pose:"):])
            labels += [f"{prefix}:{axis}" for axis in (_FREE_POS[:3] if name == "com" else _FREE_POS)]
            continue
        sensor = model.sensor(name).id
        adr, dim = int(model.sensor_adr[sensor]), int(model.sensor_dim[sensor])
        rows_c.append(c[adr:adr + dim])
        rows_d.append(dd[adr:adr + dim])
        labels += _component_names(_signal(name), dim)
    return np.vstack(rows_c), np.vstack(rows_d), labels


def _component_names(name: str, dim: int) -> list[str]:
    if dim == 1:
        return [name]
    if dim == 3:
        return [f"{name}:{axis}" for axis in "xyz"]
    if dim == 4:
        return [f"{name}:{axis}" for axis in "wxyz"]
    return [f"{name}:{i}" for i in range(dim)]


def _signal(name: str) -> str:
    return name.replace(".", "_")  # python-control reserves '.' for system.signal


_NAMES: weakref.WeakKeyDictionary[Any, Any] = weakref.WeakKeyDictionary()  # model -> {root: names}


def _state_names(plant: _Plant) -> list[str]:
    by_root = _NAMES.get(plant.model)
    if by_root is None:
        by_root = _NAMES[plant.model] = {}
    names = by_root.get(plant.root_joint)
    if names is None:
        names = by_root[plant.root_joint] = _named_states(plant)
    return list(names)


def _named_states(plant: _Plant) -> list[str]:
    model = plant.model
    positions, velocities = [], []
    for j in range(model.njnt):
        name = _signal(model.joint(j).name)
        kind = int(model.jnt_type[j])
        if kind == _FREE:
            prefix = _BASE if model.joint(j).name == plant.root_joint else name
            positions += [f"{prefix}:{s}" for s in _FREE_POS]
            velocities += [f"{prefix}:{s}" for s in _FREE_VEL]
        elif kind == _BALL:
            positions += [f"{name}:{s}" for s in _FREE_POS[3:]]
            velocities += [f"{name}:{s}" for s in _FREE_VEL[3:]]
        else:
            positions.append(f"{name}:q")
            velocities.append(f"{name}:dq")
    acts = []
    for i in range(model.nactuator):
        n = int(model.actuator_actnum[i])
        name = _signal(model.actuator(i).name)
        acts += [f"{name}:act"] if n == 1 else [f"{name}:act{k}" for k in range(n)]
    return positions + velocities + acts


def _kept_states(model: mujoco.MjModel, a: np.ndarray, c: np.ndarray) -> list[int]:
    """Every position and velocity; an actuator state only if something depends on it (an
    integral with ki = 0 would be a mode at 1 nothing sees: dlqr refuses such a model)."""
    first = 2 * model.nv
    acts = np.abs(a[:, first:]).copy()
    acts[first + np.arange(acts.shape[1]), np.arange(acts.shape[1])] = 0.0  # its own entry
    used = (acts.max(axis=0, initial=0.0) > 0) | (np.abs(c[:, first:]).max(axis=0, initial=0.0) > 0)
    return list(range(first)) + [first + int(i) for i in np.flatnonzero(used)]


def _input_map(plant: _Plant, joints: list[str], interface: str) -> tuple[np.ndarray, list[str], np.ndarray]:
    """(nu x m) ctrl per input, the inputs' names, and their values at the point."""
    model, d = plant.model, plant.data
    if interface == "ctrl":
        names = []
        for i in range(model.nactuator):
            n = int(model.actuator_ctrlnum[i])
            base = _signal(model.actuator(i).name)
            if n == 1:
                names.append(base)
            else:
                names += [f"{base}:{mujoco.mj_actuatorInputName(model, i, k) or k}" for k in range(n)]
        return np.eye(model.nu), names, d.ctrl.copy()
    u_map = np.zeros((model.nu, len(joints)))
    u0 = np.zeros(len(joints))
    layout = ControlLayout.of_actuators(
        model, [_actuator(model, j) for j in joints],
        [_actuator(model, j + INTEGRAL_SUFFIX) for j in joints])
    for col, gear in enumerate(layout.gear):  # each interface's ctrl input, as the hardware writes it
        if interface == "effort":
            u_map[layout.ff[col], col] = 1.0 / gear
            u0[col] = d.ctrl[layout.ff[col]] * gear
        elif interface == "velocity":
            u_map[layout.v_ref[col], col] = gear
            u0[col] = d.ctrl[layout.v_ref[col]] / gear
        else:
            u_map[layout.q_ref[col], col] = gear
            if layout.i_ref[col] >= 0:
                u_map[layout.i_ref[col], col] = 1.0
            u0[col] = d.ctrl[layout.q_ref[col]] / gear
    return u_map, [f"{_signal(j)}:{interface}" for j in joints], u0


# ----- reduced models ----------------------------------------------------------------------------
def _moving_joints(plant: _Plant) -> list[str]:
    model = plant.model
    return [model.joint(j).name for j in range(model.njnt)
            if int(model.jnt_type[j]) in _SCALAR_JOINTS]


def _welded(plant: _Plant, joints: list[str], fixed_base: bool) -> _Plant:
    """A recompiled copy with `joints` (and the root's free joint) welded at the current pose:
    each freed body keeps its pose relative to its parent. Actuators, equalities and keyframes
    of the welded joints go; the other actuators keep their parameters as set now."""
    if plant.spec is None:
        raise InputError("a reduced model (held='rigid', fixed_base) needs a mexone Lab or "
                         "Simulation, whose model can be recompiled")
    weld = list(joints)
    if fixed_base:
        if plant.root_joint is None:
            raise InputError("fixed_base: the robot has no floating base to fix")
        weld.append(plant.root_joint)
    model, d = plant.model, plant.data
    reduced = copy.copy(_compiled_without(plant.spec, weld))
    for name in weld:  # each freed body where the state has it, relative to its parent
        child = int(model.jnt_bodyid[model.joint(name).id])
        parent = int(model.body_parentid[child])
        rotation = d.xmat[parent].reshape(3, 3).T
        body = reduced.body(model.body(child).name).id
        reduced.body_pos[body] = rotation @ (d.xpos[child] - d.xpos[parent])
        mujoco.mju_mat2Quat(reduced.body_quat[body], (rotation @ d.xmat[child].reshape(3, 3)).ravel())
    gone = set(weld)
    _copy_settings(model, reduced)
    data = mujoco.MjData(reduced)
    mujoco.mj_setConst(reduced, data)  # what the compiler derives from the poses (invweight0...)
    qpos_index: list[int] = []
    qvel_index: list[int] = []
    for j in range(reduced.njnt):
        old = model.joint(reduced.joint(j).name).id
        width_q = {_FREE: 7, _BALL: 4}.get(int(reduced.jnt_type[j]), 1)
        width_v = {_FREE: 6, _BALL: 3}.get(int(reduced.jnt_type[j]), 1)
        qpos_index += range(model.jnt_qposadr[old], model.jnt_qposadr[old] + width_q)
        qvel_index += range(model.jnt_dofadr[old], model.jnt_dofadr[old] + width_v)
    data.qpos[:] = d.qpos[qpos_index]
    data.qvel[:] = d.qvel[qvel_index]
    copy_actuator_state(model, d, reduced, data)
    mujoco.mj_forward(reduced, data)
    joints_left = [j for j in plant.joints if j not in gone]
    return _Plant(reduced, data, joints_left, None if fixed_base else plant.root_joint, None,
                  plant.feet, plant.qpos_index[qpos_index],
                  np.asarray(plant.qvel_index)[qvel_index])


_REDUCED: dict[tuple[int, tuple[str, ...]], tuple[mujoco.MjSpec, mujoco.MjModel]] = {}
_REDUCED_KEEP = 8  # reduced models kept compiled (MjSpec edits cost ~4 ms per deleted element)


def _compiled_without(spec: mujoco.MjSpec, weld: list[str]) -> mujoco.MjModel:
    """The spec compiled with `weld` joints deleted (their actuators, equalities and the keyframes
    with them), cached per spec and joint set; the caller sets the freed bodies' poses."""
    key = (id(spec), tuple(sorted(weld)))
    cached = _REDUCED.get(key)
    if cached is not None and cached[0] is spec:
        return cached[1]
    edited = spec.copy()
    gone = set(weld)
    for name in weld:
        edited.delete(edited.joint(name))
    for actuator in list(edited.actuators):
        if actuator.target in gone:
            edited.delete(actuator)
    for equality in list(edited.equalities):
        if equality.name1 in gone or equality.name2 in gone:
            edited.delete(equality)
    for key_frame in list(edited.keys):
        edited.delete(key_frame)
    model = edited.compile()
    if len(_REDUCED) >= _REDUCED_KEEP:
        _REDUCED.pop(next(iter(_REDUCED)))
    _REDUCED[key] = (spec, model)
    return model


def _copy_settings(source: mujoco.MjModel, target: mujoco.MjModel) -> None:
    """What changes at run time (gains, clamps, the step, gravity, flags) onto a recompiled copy."""
    for i in range(target.nactuator):
        old = source.actuator(target.actuator(i).name).id
        for name in RUNTIME_ACTUATOR_FIELDS:  # the rest compiled from the same spec
            getattr(target, name)[i] = getattr(source, name)[old]
    for name in _OPTIONS:
        setattr(target.opt, name, getattr(source.opt, name))
