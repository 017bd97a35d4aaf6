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

`read()` copies the joint state into `state`; `write()` sends `command` to MuJoCo. Both run in the
simulation thread only (the ControllerManager's update). Everything is in joint space: the
transmission's mechanicalReduction r is folded in here (actuator length = r q, torque = r force).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import mujoco
import numpy as np

from mexone.control.spec import PidGains
from mexone.description.model import RobotModel
from mexone.errors import InputError, ModelError
from mexone.physics.simulation import Simulation

__all__ = ["SimHardware", "strided_view", "JointCommands", "JointStates", "build_actuators", "bake_gains",
           "INTEGRAL_SUFFIX", "set_motor_gain", "motor_gains", "set_integral_gain",
           "set_hold_controls", "clear_integrals", "copy_actuator_state", "set_actuator_state",
           "gain_to_biasprm",
           "biasprm_to_gain",
           "TELEPORT_NONE", "TELEPORT_POSITION", "TELEPORT_VELOCITY"]

INTEGRAL_SUFFIX = "/i"
FLOAT_WRITE_JOINTS = 6  # effort_floats_writer up to this many joints (numpy beyond)
TELEPORT_NONE, TELEPORT_POSITION, TELEPORT_VELOCITY = 0, 1, 2
_MOTOR_INPUTS = int(mujoco.mjtCtrlInput.mjINPUT_POS | mujoco.mjtCtrlInput.mjINPUT_VEL
                    | mujoco.mjtCtrlInput.mjINPUT_FF)
_TINY = 1e-12  # the compiler wants forcerange lo < hi; write() sets the real clamps


def build_actuators(spec: mujoco.MjSpec, robot: RobotModel) -> None:
    """A physics.compile SpecEdit: the motor and integral actuators of every transmission."""
    for joint in robot.actuated_joints:
        reduction = robot.transmission_for(joint.name).mechanical_reduction
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


def gain_to_biasprm(gain, gear):
    """A joint-space p or d gain as the motor's biasprm entry."""
    return -gain / gear**2


def biasprm_to_gain(biasprm, gear):
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
    gear = model.actuator_gear[motor, 0]
    adr = model.actuator_ctrladr[motor]
    data.ctrl[adr:adr + 3] = gear * q, 0.0, effort / gear
    if integral >= 0:
        data.ctrl[model.actuator_ctrladr[integral]] = q


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
    return tuple(float(biasprm_to_gain(model.actuator_biasprm[actuator, _BIAS_COLUMN[term]], gear))
                 for term in ("p", "d"))


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


def strided_view(array: np.ndarray, index: np.ndarray) -> np.ndarray | None:
    """A view of array[index] when the indices are evenly spaced and increasing (a limb's joints
    usually are), else None."""
    if len(index) == 0:
        return None
    if len(index) == 1:
        return array[int(index[0]):int(index[0]) + 1]
    step = int(index[1] - index[0])
    if step <= 0 or not np.array_equal(np.diff(index), np.full(len(index) - 1, step)):
        return None
    return array[int(index[0]):int(index[-1]) + 1:step]


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
        self.lower = np.array([j.limit.lower if lim else -np.inf for j, lim in zip(joints, limited,
                                                                                    strict=True)])
        self.upper = np.array([j.limit.upper if lim else np.inf for j, lim in zip(joints, limited,
                                                                                   strict=True)])
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
        """MuJoCo ids and addresses of this robot's actuators and joints, by name."""
        model, pre = self.sim.model, self.prefix
        if pre and not any(model.actuator(i).name.startswith(pre) for i in range(model.nactuator)):
            return  # the model was deleted; its manager is closed
        try:
            self.motor = np.array([model.actuator(pre + j).id for j in self.joints], dtype=int)
            self.integral = np.array([model.actuator(pre + j + INTEGRAL_SUFFIX).id
                                      for j in self.joints], dtype=int)
        except KeyError:
            raise ModelError("the model was compiled without mexone's actuators",
                             hint="build the Simulation with edits=[build_actuators]") from None
        ids = [model.joint(pre + j).id for j in self.joints]
        self.qpos_adr = np.array([model.jnt_qposadr[i] for i in ids], dtype=int)
        self.dof_adr = np.array([model.jnt_dofadr[i] for i in ids], dtype=int)
        self.gear = model.actuator_gear[self.motor, 0].copy()
        self._ctrl_motor = model.actuator_ctrladr[self.motor]  # [q_ref, v_ref, ff] each
        self._ctrl_integral = model.actuator_ctrladr[self.integral]
        self._act_integral = model.actuator_actadr[self.integral]
        motor = self._ctrl_motor
        self._ctrl_all = np.concatenate((motor, motor + 1, motor + 2, self._ctrl_integral))
        self._ctrl_values = np.zeros(len(self._ctrl_all))

    def rows(self, names) -> np.ndarray:
        missing = [n for n in names if n not in self.index]
        if missing:
            raise InputError(f"joint {', '.join(missing)} has no transmission, so no controller "
                             "can drive it", hint="add a <transmission> for it to the URDF")
        return np.array([self.index[n] for n in names], dtype=int)

    # ----- state (reading is safe in the simulation thread at any time) --------------------------
    def position(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        return self.sim.data.qpos[self.qpos_adr[rows]]

    def velocity(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        return self.sim.data.qvel[self.dof_adr[rows]]

    def effort(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """Joint torque the motors applied in the last step (after the effort limit)."""
        return self.sim.data.qfrc_actuator[self.dof_adr[rows]]

    def read(self) -> None:
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

    def effort_floats_writer(self, rows: np.ndarray) -> Callable[[list[float]], None] | None:
        """For a few joints: their effort commands from Python floats (checked already), into
        the hardware's commands and MuJoCo's ctrl at once, float by float (a handful of stores
        cost less than two numpy calls); None for more joints (rows_writer then). Rebuilt with
        rows_writer."""
        rows = [int(r) for r in rows]
        gears = [float(self.gear[r]) for r in rows]
        if len(rows) > FLOAT_WRITE_JOINTS or not all(g != 0.0 and math.isfinite(g) for g in gears):
            return None
        effort, ctrl = self.command.effort, self.sim.data.ctrl
        slots = [(row, int(self._ctrl_motor[row]) + 2, gear)
                 for row, gear in zip(rows, gears, strict=True)]

        def write_effort_floats(values: list[float]) -> None:
            for (row, ff, gear), value in zip(slots, values):  # noqa: B905 - both n long
                effort[row] = value
                ctrl[ff] = value / gear

        return write_effort_floats

    def rows_writer(self, rows: np.ndarray, interface: str) -> Callable[[np.ndarray], None]:
        """write() of one command interface ("effort", "position", "velocity") on `rows` alone,
        taking the new values: for a loop cycle in which nothing else changed (a Python
        controller's update), a few numpy calls instead of every actuator's. Built after the
        controller started (its teleport mode is read now); rebuilt when the model changes."""
        rows = np.asarray(rows, dtype=int)
        sim, gear = self.sim, self.gear[rows].copy()
        motor = self._ctrl_motor[rows]
        teleport = bool(np.count_nonzero(self.command.teleport[rows]))
        if interface == "effort":
            ff = motor + 2
            view = strided_view(sim.data.ctrl, ff)
            if view is not None:  # one ufunc into MuJoCo's ctrl, no temporary
                def write_effort_view(values: np.ndarray) -> None:
                    np.divide(values, gear, out=view)
                return write_effort_view

            def write_effort(values: np.ndarray) -> None:
                sim.data.ctrl[ff] = values / gear
            return write_effort
        if interface == "velocity":
            v_ref, dofs = motor + 1, self.dof_adr[rows]

            def write_velocity(values: np.ndarray) -> None:
                data = sim.data
                data.ctrl[v_ref] = gear * values
                if teleport:
                    data.qvel[dofs] = values
            return write_velocity
        index = np.concatenate((motor, self._ctrl_integral[rows]))
        both = np.concatenate((gear, np.ones(len(rows))))
        qpos, dofs = self.qpos_adr[rows], self.dof_adr[rows]

        def write_position(values: np.ndarray) -> None:
            data = sim.data
            data.ctrl[index] = both * np.concatenate((values, values))
            if teleport:
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
            motor, integral = self.motor[rows], self.integral[rows]
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
            data.act[self._act_integral[rows]] = 0.0
        teleport = c.teleport
        if np.count_nonzero(teleport):
            pos = teleport == TELEPORT_POSITION
            data.qpos[self.qpos_adr[pos]] = c.position[pos]
            moving = teleport != TELEPORT_NONE
            data.qvel[self.dof_adr[moving]] = c.velocity[moving]
