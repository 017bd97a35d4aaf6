"""SimHardware: ros_control's hardware interface on MuJoCo, and the only code that touches actuators.

`build_actuators` edits the MjSpec before the model compiles (as mjlab's actuator configs do) and
gives every joint with a <transmission> two MuJoCo actuators::

    <joint>     MuJoCo's native PID servo with the P and D terms and a feed-forward input,
                    torque = kp (q_ref - q) + kd (v_ref - qdot) + ff
                the D term integrated implicitly, so stiff gains stay stable;
    <joint>/i   a native PID integral state z (dz/dt = q_ref - q): control_toolbox's I term,
                    torque = clamp(ki z, i_clamp_min, i_clamp_max)
                antiwindup clamps z itself to [i_clamp_min/ki, i_clamp_max/ki], as ROS does;

and limits the joint's total actuator torque to the URDF effort limit. Gains, clamps and setpoints
are model and data fields, so retuning costs nothing and the whole PID runs in C every step.

`read()` copies the joint state into `state`; `write()` sends `command` to MuJoCo; `writer(rows,
interface)` is write() of one command interface on a few joints alone, for a Python controller's
update (the manager's fast path). All run in the simulation thread only. Where each joint's
controls live is one `ControlLayout`, which every writer reads (write, the writers, a
linearisation's copies); nothing outside this module writes ctrl, and it is the one writer of
qpos and qvel for ideal servos. Everything is in joint space: the transmission's
mechanicalReduction r is folded in here (actuator length = r q, torque = r force).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, fields
from typing import TypeVar

import mujoco
import numpy as np

from mexone.control.spec import PidGains
from mexone.control.student import strided_view
from mexone.description.model import RobotModel
from mexone.errors import InputError, ModelError
from mexone.physics.simulation import Simulation

__all__ = ["SimHardware", "ControlLayout", "strided_view", "JointCommands",
           "JointStates", "build_actuators", "bake_gains", "INTEGRAL_SUFFIX", "set_motor_gain",
           "motor_gains", "set_integral_gain", "set_hold_controls", "clear_integrals",
           "copy_actuator_state", "set_actuator_state", "gain_to_biasprm", "biasprm_to_gain",
           "Q_REF", "V_REF", "FF",
           "TELEPORT_NONE", "TELEPORT_POSITION", "TELEPORT_VELOCITY"]

INTEGRAL_SUFFIX = "/i"
Q_REF, V_REF, FF = 0, 1, 2  # the motor's three control inputs, in ctrl order (_MOTOR_INPUTS)
TELEPORT_NONE, TELEPORT_POSITION, TELEPORT_VELOCITY = 0, 1, 2
_MOTOR_INPUTS = int(mujoco.mjtCtrlInput.mjINPUT_POS | mujoco.mjtCtrlInput.mjINPUT_VEL
                    | mujoco.mjtCtrlInput.mjINPUT_FF)
_TINY = 1e-12  # the compiler wants forcerange lo < hi; write() sets the real clamps


def build_actuators(spec: mujoco.MjSpec, robot: RobotModel) -> None:
    """A physics.compile SpecEdit: the motor and integral actuators of every transmission."""
    for joint in robot.actuated_joints:
        transmission = robot.transmission_for(joint.name)
        reduction = transmission.mechanical_reduction if transmission is not None else 1.0
        effort = joint.limit.effort if joint.limit and joint.limit.effort > 0 else 0.0
        motor = spec.add_actuator(name=joint.name, target=joint.name,
                                  trntype=mujoco.mjtTrn.mjTRN_JOINT)
        motor.gear = (reduction, 0, 0, 0, 0, 0)
        motor.gaintype = mujoco.mjtGain.mjGAIN_PID
        motor.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        motor.dyntype = mujoco.mjtDyn.mjDYN_NONE
        motor.gainprm = np.zeros(10)
        motor.biasprm = np.zeros(10)
        motor.ctrlspec = _MOTOR_INPUTS
        motor.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
        integral = spec.add_actuator(name=joint.name + INTEGRAL_SUFFIX, target=joint.name,
                                     trntype=mujoco.mjtTrn.mjTRN_JOINT)
        integral.gaintype = mujoco.mjtGain.mjGAIN_PID
        integral.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        integral.dyntype = mujoco.mjtDyn.mjDYN_PID  # one state: the integral of q_ref - q
        integral.gainprm = np.r_[1.0, np.zeros(9)]  # ki > 0 at compile time allocates the state
        integral.dynprm = np.zeros(10)  # dynprm[0] is MuJoCo's own imax: none, the clamps are ours
        integral.biasprm = np.zeros(10)
        integral.ctrlspec = int(mujoco.mjtCtrlInput.mjINPUT_POS)
        integral.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
        integral.actearly = True  # the I term uses this step's error, as control_toolbox does
        integral.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        integral.forcerange = (-_TINY, _TINY)
        if effort > 0:
            motor.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
            motor.forcerange = (-effort / abs(reduction), effort / abs(reduction))
            mj_joint = spec.joint(joint.name)
            mj_joint.actfrclimited = mujoco.mjtLimited.mjLIMITED_TRUE
            mj_joint.actfrcrange = (-effort, effort)


# The one home of the gain <-> actuator mapping: MuJoCo's PID servo holds -gain / gear^2 of the
# joint-space p and d gains in biasprm[1] and biasprm[2] (actuator length = gear q).
_BIAS_COLUMN = {"p": 1, "d": 2}
Numeric = TypeVar("Numeric", float, np.ndarray)  # a gain, or an array of them


def gain_to_biasprm(gain: Numeric, gear: Numeric) -> Numeric:
    """A joint-space p or d gain as the motor's biasprm entry."""
    return -gain / gear**2


def biasprm_to_gain(biasprm: Numeric, gear: Numeric) -> Numeric:
    """The joint-space gain a motor's biasprm entry holds (gain_to_biasprm's inverse)."""
    return -biasprm * gear**2


def set_motor_gain(model: mujoco.MjModel, actuator: int, term: str, value: float) -> None:
    """Write a p or d gain into a motor actuator of `model` as write() does, for models that are
    not a running simulation's, e.g. identification's rollout copies."""
    gear = model.actuator_gear[actuator, 0]
    model.actuator_biasprm[actuator, _BIAS_COLUMN[term]] = gain_to_biasprm(value, gear)


def set_integral_gain(model: mujoco.MjModel, actuator: int, ki: float) -> None:
    """Write the I gain of an integral actuator of `model` (a copy, as set_motor_gain)."""
    model.actuator_gainprm[actuator, 0] = ki


def set_hold_controls(model: mujoco.MjModel, data: mujoco.MjData, motor: int, integral: int,
                      q: float, effort: float) -> None:
    """The controls of one joint's motor (q_ref = q, v_ref = 0, `effort` feed-forward, in joint
    space) and integral actuator (q_ref = q; none if `integral` < 0), on a model and data that are
    not a running simulation's (linearisation's copies); write() does the same at run time."""
    layout = ControlLayout.of_actuators(model, [motor], [integral])
    gear = layout.gear[0]
    data.ctrl[layout.q_ref] = gear * q
    data.ctrl[layout.v_ref] = 0.0
    data.ctrl[layout.ff] = effort / gear
    if integral >= 0:
        data.ctrl[layout.i_ref] = q


def copy_actuator_state(source: mujoco.MjModel, source_data: mujoco.MjData,
                        target: mujoco.MjModel, target_data: mujoco.MjData) -> None:
    """Each of `target`'s actuators' controls and states from the same-named actuator of
    `source` (a reduced copy of a model, e.g. linearisation's with joints welded)."""
    for i in range(target.nactuator):
        old = source.actuator(target.actuator(i).name).id
        n = int(target.actuator_ctrlnum[i])
        start, from_ = target.actuator_ctrladr[i], source.actuator_ctrladr[old]
        target_data.ctrl[start:start + n] = source_data.ctrl[from_:from_ + n]
        m = int(target.actuator_actnum[i])
        if m:
            start, from_ = target.actuator_actadr[i], source.actuator_actadr[old]
            target_data.act[start:start + m] = source_data.act[from_:from_ + m]


def set_actuator_state(data: mujoco.MjData, ctrl: np.ndarray | None = None,
                       act: np.ndarray | None = None, rows: np.ndarray | None = None) -> None:
    """The controls and actuator states (all of `act`, or its `rows`) of a data that is not a
    running simulation's: the analysis's copies (mexone.design's twin, probes, rollouts)."""
    if ctrl is not None:
        data.ctrl[:] = ctrl
    if act is not None:
        if rows is None:
            data.act[:] = act
        else:
            data.act[rows] = act


def clear_integrals(data: mujoco.MjData) -> None:
    """Every actuator state (the integral terms) to zero, on a copy's data."""
    data.act[:] = 0.0


def motor_gains(model: mujoco.MjModel, actuator: int) -> tuple[float, float]:
    """(p, d) of a motor actuator of `model`, in joint space."""
    gear = model.actuator_gear[actuator, 0]
    p, d = (float(biasprm_to_gain(model.actuator_biasprm[actuator, _BIAS_COLUMN[term]], gear))
            for term in ("p", "d"))
    return p, d


def bake_gains(gains: Mapping[str, PidGains]) -> Callable[[mujoco.MjSpec, RobotModel], None]:
    """A SpecEdit after build_actuators: the controllers' gains written into the actuators, as
    write() sets them at run time, so an exported MJCF holds its pose by itself (ctrl of the
    motor: q_ref, v_ref, feed-forward effort; of the integral actuator: q_ref)."""

    def edit(spec: mujoco.MjSpec, robot: RobotModel) -> None:
        for joint, pid in gains.items():
            motor, integral = spec.actuator(joint), spec.actuator(joint + INTEGRAL_SUFFIX)
            gear = motor.gear[0]
            bias = np.zeros(10)
            for term in ("p", "d"):
                bias[_BIAS_COLUMN[term]] = gain_to_biasprm(getattr(pid, term), gear)
            motor.biasprm = bias
            if pid.integrates:  # else the I term stays clamped to nothing, as build_actuators left it
                integral.gainprm = np.r_[pid.i, np.zeros(9)]
                integral.forcerange = (pid.i_clamp_min, pid.i_clamp_max)

    return edit


@dataclass(frozen=True)
class ControlLayout:
    """Where some joints' controls and states live in a MuJoCo model: the one home of the
    actuators' control layout (build_actuators' two actuators per joint), read by every writer.

    Per joint, in the given order: the motor actuator (its ctrl inputs `q_ref` = r q, `v_ref` =
    r qdot and the feed-forward `ff` = torque / r, at Q_REF, V_REF and FF after its ctrl
    address), the integral actuator (its ctrl input `i_ref` = q and its state `i_act`; -1 where a
    model has none), the gear r, and the joint's qpos and dof addresses."""

    motor: np.ndarray
    integral: np.ndarray
    gear: np.ndarray
    q_ref: np.ndarray
    v_ref: np.ndarray
    ff: np.ndarray
    i_ref: np.ndarray
    i_act: np.ndarray
    qpos: np.ndarray
    dof: np.ndarray

    @classmethod
    def of(cls, model: mujoco.MjModel, joints: Sequence[str], prefix: str = "") -> ControlLayout:
        """The layout of `joints` (their MuJoCo names carry `prefix`); a model without mexone's
        actuators is a ModelError."""
        try:
            motor = [model.actuator(prefix + j).id for j in joints]
            integral = [model.actuator(prefix + j + INTEGRAL_SUFFIX).id for j in joints]
        except KeyError:
            raise ModelError("the model was compiled without mexone's actuators",
                             hint="build the Simulation with edits=[build_actuators]") from None
        return cls.of_actuators(model, motor, integral)

    @classmethod
    def of_actuators(cls, model: mujoco.MjModel, motor: Sequence[int],
                     integral: Sequence[int]) -> ControlLayout:
        """The layout of the joints these motor (and integral, -1: none) actuators drive."""
        motors = np.asarray(motor, dtype=int)
        integrals = np.asarray(integral, dtype=int)
        has = integrals >= 0
        ctrl = model.actuator_ctrladr[motors].astype(int)
        joint = model.actuator_trnid[motors, 0].astype(int)
        return cls(motors, integrals, model.actuator_gear[motors, 0].copy(), ctrl + Q_REF,
                   ctrl + V_REF, ctrl + FF,
                   np.where(has, model.actuator_ctrladr[np.where(has, integrals, 0)], -1).astype(int),
                   np.where(has, model.actuator_actadr[np.where(has, integrals, 0)], -1).astype(int),
                   model.jnt_qposadr[joint].astype(int), model.jnt_dofadr[joint].astype(int))

    def take(self, rows: np.ndarray) -> ControlLayout:
        """The layout of some of these joints (`rows` into this one's order)."""
        rows = np.asarray(rows, dtype=int)
        return ControlLayout(*(getattr(self, f.name)[rows] for f in fields(self)))


@dataclass
class JointStates:
    """The state interfaces, as read at the start of an update (joint space)."""

    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray


@dataclass
class JointCommands:
    """The command interfaces controllers write (joint space, one entry per actuated joint)."""

    n: int
    position: np.ndarray = field(init=False)  # q_ref
    velocity: np.ndarray = field(init=False)  # v_ref
    effort: np.ndarray = field(init=False)  # feed-forward torque
    kp: np.ndarray = field(init=False)
    kd: np.ndarray = field(init=False)
    ki: np.ndarray = field(init=False)
    i_min: np.ndarray = field(init=False)
    i_max: np.ndarray = field(init=False)
    antiwindup: np.ndarray = field(init=False)
    teleport: np.ndarray = field(init=False)  # TELEPORT_*: Gazebo's SetPosition/SetVelocity

    def __post_init__(self) -> None:
        for name in ("position", "velocity", "effort", "kp", "kd", "ki", "i_min", "i_max"):
            setattr(self, name, np.zeros(self.n))
        self.antiwindup = np.zeros(self.n, dtype=bool)
        self.teleport = np.zeros(self.n, dtype=np.int8)


class SimHardware:
    """`robot`/`prefix`: a second robot spawned into the world (its MuJoCo names carry the
    model's prefix, "robot2/"); its controllers see plain joint names, as in its own URDF."""

    def __init__(self, sim: Simulation, robot: RobotModel | None = None, prefix: str = ""):
        self.sim, self.robot, self.prefix = sim, robot or sim.robot, prefix
        robot = self.robot
        self.joints = [j.name for j in robot.actuated_joints]  # hardware order
        self.index = {name: i for i, name in enumerate(self.joints)}
        self._bind()
        sim.on_model_change(self._bind)  # models added or removed: MuJoCo ids may move
        joints = [robot.joints[j] for j in self.joints]
        limited = [j.type in ("revolute", "prismatic") for j in joints]
        self.lower = np.array([j.limit.lower if lim and j.limit else -np.inf
                               for j, lim in zip(joints, limited, strict=True)])
        self.upper = np.array([j.limit.upper if lim and j.limit else np.inf
                               for j, lim in zip(joints, limited, strict=True)])
        self.effort_limit = np.array([j.limit.effort if j.limit and j.limit.effort > 0 else np.inf
                                      for j in joints])
        self.velocity_limit = np.array([j.limit.velocity if j.limit and j.limit.velocity > 0
                                        else np.inf for j in joints])
        n = len(self.joints)
        self.command = JointCommands(n)
        self.state = JointStates(np.zeros(n), np.zeros(n), np.zeros(n))
        self._gains_changed = np.zeros(n, dtype=bool)
        self._integral_reset = np.zeros(n, dtype=bool)
        self.writes = 0  # write() calls, for tests and benchmarks

    def _bind(self) -> None:
        """The control layout of this robot's joints, found by name (MuJoCo ids move when
        models are added or removed)."""
        model, pre = self.sim.model, self.prefix
        if pre and not any(model.actuator(i).name.startswith(pre) for i in range(model.nactuator)):
            return  # the model was deleted; its manager is closed
        self.layout = layout = ControlLayout.of(model, self.joints, pre)
        self.qpos_adr, self.dof_adr, self.gear = layout.qpos, layout.dof, layout.gear
        # write()'s one scatter: the motors' q_ref, v_ref, ff, then the integral actuators' q_ref
        self._ctrl_all = np.concatenate((layout.q_ref, layout.v_ref, layout.ff, layout.i_ref))
        self._ctrl_values = np.zeros(len(self._ctrl_all))

    def rows(self, names: Iterable[str]) -> np.ndarray:
        """The hardware rows of these joints (an InputError naming one without a transmission)."""
        missing = [n for n in names if n not in self.index]
        if missing:
            raise InputError(f"joint {', '.join(missing)} has no transmission, so no controller "
                             "can drive it", hint="add a <transmission> for it to the URDF")
        return np.array([self.index[n] for n in names], dtype=int)

    # ----- state (reading is safe in the simulation thread at any time) --------------------------
    def position(self, rows: int | np.ndarray | slice = slice(None)) -> np.ndarray:
        """Joint positions now (rad or m), of `rows` or all, read from MuJoCo."""
        return self.sim.data.qpos[self.qpos_adr[rows]]

    def velocity(self, rows: int | np.ndarray | slice = slice(None)) -> np.ndarray:
        """Joint velocities now (rad/s or m/s), of `rows` or all, read from MuJoCo."""
        return self.sim.data.qvel[self.dof_adr[rows]]

    def effort(self, rows: int | np.ndarray | slice = slice(None)) -> np.ndarray:
        """Joint torque the motors applied in the last step (after the effort limit)."""
        return self.sim.data.qfrc_actuator[self.dof_adr[rows]]

    def read(self) -> None:
        """Copy every joint's position, velocity and effort into `state` (the loop's read)."""
        data, state = self.sim.data, self.state
        state.position[:] = data.qpos[self.qpos_adr]
        state.velocity[:] = data.qvel[self.dof_adr]
        state.effort[:] = data.qfrc_actuator[self.dof_adr]

    # ----- commands ------------------------------------------------------------------------------
    def gains_changed(self, rows: np.ndarray) -> None:
        """Controllers call this after writing kp/kd/ki/clamps: write() sends them to MuJoCo."""
        self._gains_changed[rows] = True

    def reset_integral(self, rows: np.ndarray) -> None:
        """The I term restarts from zero at the next write (a controller starting)."""
        self._integral_reset[rows] = True

    def release(self, rows: np.ndarray) -> None:
        """No controller: the motor applies nothing."""
        c = self.command
        for array in (c.position, c.velocity, c.effort, c.kp, c.kd, c.ki, c.i_min, c.i_max):
            array[rows] = 0.0
        c.antiwindup[rows] = False
        c.teleport[rows] = TELEPORT_NONE
        self.gains_changed(rows)
        self.reset_integral(rows)

    def writer(self, rows: np.ndarray, interface: str) -> Callable[[np.ndarray], None]:
        """write() of one command interface ("effort", "position", "velocity") on `rows` alone,
        for a loop cycle in which nothing else changed (a Python controller's update): the
        returned function stores its values (checked, clamped, one per row) into `command` and
        sends the same ctrl (and, for an ideal servo, qpos/qvel) as write() would, in a few
        stores (views where the rows and controls are evenly spaced). Built after the controller
        started (its teleport mode is read now); rebuilt when the model changes."""
        rows = np.asarray(rows, dtype=int)
        layout = self.layout.take(rows)
        ctrl = self.sim.data.ctrl  # MuJoCo keeps its arrays for the model's life
        gear = layout.gear
        teleport = bool(np.count_nonzero(self.command.teleport[rows]))
        commands: np.ndarray = getattr(self.command, interface)
        held = strided_view(commands, rows)
        if interface == "effort":
            ff = layout.ff
            view = strided_view(ctrl, ff)
            if held is None or view is None:
                def write_effort(values: np.ndarray) -> None:
                    commands[rows] = values
                    ctrl[ff] = values / gear
                return write_effort
            if bool(np.all(gear == 1.0)):  # values / 1.0 is values, bit for bit
                def write_effort_copy(values: np.ndarray) -> None:
                    held[...] = values
                    view[...] = values
                return write_effort_copy

            def write_effort_view(values: np.ndarray) -> None:  # one ufunc, no temporary
                held[...] = values
                np.divide(values, gear, out=view)
            return write_effort_view
        sim = self.sim
        if interface == "velocity":
            v_ref, dofs = layout.v_ref, layout.dof

            def write_velocity(values: np.ndarray) -> None:
                commands[rows] = values
                ctrl[v_ref] = gear * values
                if teleport:
                    sim.data.qvel[dofs] = values
            return write_velocity
        index = np.concatenate((layout.q_ref, layout.i_ref))  # the motor's, the integral's
        both = np.concatenate((gear, np.ones(len(gear))))
        qpos, dofs = layout.qpos, layout.dof

        def write_position(values: np.ndarray) -> None:
            commands[rows] = values
            ctrl[index] = both * np.concatenate((values, values))
            if teleport:
                data = sim.data
                data.qpos[qpos] = values
                data.qvel[dofs] = 0.0
        return write_position

    def write(self) -> None:
        """Send the commands to MuJoCo: the only place that writes ctrl, act and actuator
        parameters (and, for ideal servos, qpos/qvel)."""
        model, data, c, r = self.sim.model, self.sim.data, self.command, self.gear
        self.writes += 1
        out = self._ctrl_values  # one gather-free scatter: q_ref, v_ref, ff of the motors, q_ref
        n = len(r)
        np.multiply(r, c.position, out=out[:n])
        np.multiply(r, c.velocity, out=out[n:2 * n])
        np.divide(c.effort, r, out=out[2 * n:3 * n])
        out[3 * n:] = c.position
        data.ctrl[self._ctrl_all] = out
        if np.count_nonzero(self._gains_changed):
            rows = np.flatnonzero(self._gains_changed)
            self._gains_changed[:] = False
            motor, integral = self.layout.motor[rows], self.layout.integral[rows]
            model.actuator_biasprm[motor, _BIAS_COLUMN["p"]] = gain_to_biasprm(c.kp[rows], r[rows])
            model.actuator_biasprm[motor, _BIAS_COLUMN["d"]] = gain_to_biasprm(c.kd[rows], r[rows])
            ki = c.ki[rows]
            model.actuator_gainprm[integral, 0] = ki
            model.actuator_forcerange[integral, 0] = c.i_min[rows]
            model.actuator_forcerange[integral, 1] = c.i_max[rows]
            wind = c.antiwindup[rows] & (ki > 0)
            model.actuator_actlimited[integral] = wind
            with np.errstate(divide="ignore", invalid="ignore"):
                a, b = c.i_min[rows] / ki, c.i_max[rows] / ki
            model.actuator_actrange[integral[wind], 0] = np.minimum(a, b)[wind]
            model.actuator_actrange[integral[wind], 1] = np.maximum(a, b)[wind]
        if np.count_nonzero(self._integral_reset):
            rows = np.flatnonzero(self._integral_reset)
            self._integral_reset[:] = False
            data.act[self.layout.i_act[rows]] = 0.0
        teleport = c.teleport
        if np.count_nonzero(teleport):
            pos = teleport == TELEPORT_POSITION
            data.qpos[self.qpos_adr[pos]] = c.position[pos]
            moving = teleport != TELEPORT_NONE
            data.qvel[self.dof_adr[moving]] = c.velocity[moving]
