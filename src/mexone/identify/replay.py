"""A Recording replayed through mexone's own controllers -> an Experiment that MuJoCo can roll
out open-loop in C.

The controllers are the ones the student ran (the same YAML, the same classes), fed the recorded
commands at their recorded times; what they write into MuJoCo's actuators each step (setpoints,
velocity references, feed-forward) is captured as `ctrl`. Because the PID lives in the actuators,
replaying `ctrl` with `mujoco.rollout` reproduces the closed loop -- for any candidate model --
without a line of Python per step.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from mexone.bus import msgs
from mexone.control.spec import ControlConfig
from mexone.description.model import RobotModel
from mexone.description.transforms import matrix_to_rpy
from mexone.errors import InputError, MexoneError
from mexone.identify.recording import STILL, Recording
from mexone.lab import Lab
from mexone.physics.attach import RUNTIME_ACTUATOR_FIELDS
from mexone.physics.compile import CompileOptions, Spawn
from mexone.physics.divergence import DivergenceError
from mexone.record.reader import FLOAT64, MULTI, TRAJECTORY

__all__ = ["Experiment", "replay", "BASES", "HANG_HEIGHT", "SENSOR_SUFFIX"]

BASES = ("auto", "fixed", "free")
HANG_HEIGHT = 0.5  # m of air under the lowest point of a robot on a stand (no /tf to say where)
SENSOR_SUFFIX = "/identify"  # the joint-position sensors added to the fitting model
_MOVED = 0.001  # m: a base that moved more than this was not on a stand
_FULL = mujoco.mjtState.mjSTATE_FULLPHYSICS


@dataclass
class Experiment:
    """One bag, replayed: the model to fit (as an editable spec), the controls of every step, the
    initial state, and the measured positions on the sensors' grid."""

    recording: Recording
    fixed_base: bool
    spec: mujoco.MjSpec
    model: mujoco.MjModel  # the nominal model, compiled from spec
    ctrl: np.ndarray  # (steps, nu)
    initial_state: np.ndarray
    times: np.ndarray  # every sample time (s), increasing
    measured: np.ndarray  # (len(times), len(joints)); NaN where a joint has no sample then
    joints: list[str]
    runtime: dict[str, np.ndarray]  # actuator fields the controllers wrote after compiling
    base_link: str
    notes: list[str] = field(default_factory=list)

    @property
    def name(self) -> str:
        return self.recording.name

    def compile(self, spec: mujoco.MjSpec | None = None) -> mujoco.MjModel:
        """The spec (edited or not) compiled, with the controllers' gains and clamps as the Lab
        had them: a model field, not a spec one, since MuJoCo allocates the integral state only
        for a gain that is non-zero at compile time."""
        model = (spec or self.spec).compile()
        # the Lab computes its sensors on request (mjDSBL_SENSOR); a rollout needs the pass on
        model.opt.disableflags = int(self.runtime["disableflags"][0]) & ~int(
            mujoco.mjtDisableBit.mjDSBL_SENSOR)
        for name, values in self.runtime.items():
            if name != "disableflags":
                getattr(model, name)[:] = values
        return model

    @property
    def timestep(self) -> float:
        return float(self.model.opt.timestep)

    @property
    def steps(self) -> int:
        return len(self.ctrl)

    @property
    def base(self) -> str:
        return "fixed" if self.fixed_base else "free"


def replay(recording: Recording, robot: RobotModel, config: ControlConfig,
           base: str = "auto") -> Experiment:
    """Build the Lab the bag was recorded in, set it to the bag's first sample and feed its
    controllers the recorded commands, capturing every step's actuator controls."""
    fixed, spawn, notes = _base(recording, robot, base)
    options = CompileOptions(visuals=False, fixed_base=fixed)
    lab = Lab.create(robot, config, spawn=spawn, options=options)
    sim, manager = lab.sim, lab.manager
    _set_initial_pose(lab, recording, fixed)
    manager.restart()  # controllers hold the first recorded pose, as they held the robot's
    state = np.empty(mujoco.mj_stateSize(sim.model, _FULL))
    mujoco.mj_getState(sim.model, sim.data, state, _FULL)
    dt = sim.timestep
    steps = int(np.floor(recording.duration / dt + 1e-9)) + 2
    ctrl = np.empty((steps, sim.model.nu))
    topics = {name: manager.topic(name) for name in config.controllers}
    commands, i = recording.commands, 0
    try:
        for k in range(steps):
            while i < len(commands) and commands[i].t <= (k + 0.5) * dt:
                command = commands[i]
                lab.bus.publish(topics[command.controller], _message(command, recording.t0))
                i += 1
            sim.step(1)
            ctrl[k] = sim.data.ctrl
    except DivergenceError as exc:  # the bag's start or commands, not the user's gains
        raise InputError(f"replaying the bag, the model {exc.what.removeprefix('simulation ')}",
                         file=recording.bag,
                         hint="the recorded start pose or commands are more than this model can "
                              "follow: is --model (and --controllers) the robot that was "
                              "recorded?") from None
    except MexoneError as exc:
        raise InputError(f"replaying the commands at t = {k * dt:.3f} s: {exc.what}",
                         file=recording.bag, hint=exc.hint) from None
    _refuse_what_ctrl_cannot_carry(lab, recording)
    spec = _fitting_spec(lab, recording.joints)
    times, measured = _grid(recording)
    model = sim.model
    runtime = {name: getattr(model, name).copy() for name in RUNTIME_ACTUATOR_FIELDS}
    runtime["disableflags"] = np.array([model.opt.disableflags])
    experiment = Experiment(recording, fixed, spec, model, ctrl, state, times, measured,
                            list(recording.joints), runtime, robot.base_link,
                            notes + list(recording.notes))
    experiment.model = experiment.compile()
    return experiment


def _base(recording: Recording, robot: RobotModel, base: str) -> tuple[bool, Spawn, list[str]]:
    """Fixed or free, and where: /tf says where the base was and whether it moved."""
    if base not in BASES:
        raise InputError(f"--base {base}: must be one of {', '.join(BASES)}")
    pose, bag = recording.base, recording.bag
    if robot.fixed_to_world:
        return True, Spawn(), []
    if base == "fixed" and pose is not None and pose.moved > _MOVED:
        raise InputError(f"the base ({robot.base_link}) moved {pose.moved * 1000:.0f} mm in /tf: "
                         "the robot was not on a stand", file=bag, hint="drop --base fixed")
    fixed = base == "fixed" or (base == "auto" and pose is not None and pose.moved < STILL)
    if fixed and pose is not None:
        rotation = np.zeros(9)
        mujoco.mju_quat2Mat(rotation, pose.quat)
        rpy = matrix_to_rpy(rotation.reshape(3, 3))
        return True, Spawn(tuple(pose.xyz), tuple(rpy), on_ground=False), []
    if fixed:
        return True, Spawn((0.0, 0.0, HANG_HEIGHT)), [
            f"{bag.name}: on a stand with no /tf of {robot.base_link}: hung with its lowest point "
            f"{HANG_HEIGHT} m above the ground"]
    if pose is None:
        return False, Spawn(), [
            f"{bag.name}: no /tf of {robot.base_link}: the robot is assumed standing still on "
            "the ground at the start (say --base fixed if it was on a stand)"]
    return False, Spawn(), []


def _set_initial_pose(lab: Lab, recording: Recording, fixed: bool) -> None:
    sim = lab.sim
    model = sim.model
    sim.set_joint_positions(recording.q0)
    qpos, qvel = sim.data.qpos.copy(), sim.data.qvel.copy()
    for name, velocity in recording.v0.items():
        qvel[model.joint(name).dofadr[0]] = velocity
    sim.set_state(qpos, qvel)
    if not fixed and sim.compiled.free:
        free = model.joint(f"{sim.robot.base_link}_free")
        adr = free.qposadr[0]
        if recording.base is not None:
            qpos[adr:adr + 3] = recording.base.xyz
            qpos[adr + 3:adr + 7] = recording.base.quat
        else:
            qpos[adr + 2] -= _height_above_ground(model, sim.data)
        sim.set_state(qpos)


def _height_above_ground(model: mujoco.MjModel, data: mujoco.MjData) -> float:
    """How far the robot's lowest collision geometry is above the ground plane."""
    plane = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "ground_plane")
    if plane < 0:
        return 0.0
    fromto = np.zeros(6)
    gaps = [mujoco.mj_geomDistance(model, data, g, plane, 10.0, fromto)
            for g in range(model.ngeom) if g != plane and model.geom_bodyid[g] > 0
            and (model.geom_contype[g] or model.geom_conaffinity[g])]
    return min(gaps) if gaps else 0.0


def _message(command, t0: float):
    """The recorded message as the bus type its controller subscribes to."""
    m = command.message
    if m.msgtype == FLOAT64:
        return msgs.Float64(float(m.values[0]))
    if m.msgtype == MULTI:
        return msgs.Float64MultiArray([float(v) for v in m.values])
    assert m.msgtype == TRAJECTORY
    stamp = msgs.Time() if m.stamp is None else msgs.Time.from_sec(max(m.stamp - t0, 1e-9))
    points = [msgs.JointTrajectoryPoint(list(p.positions), list(p.velocities),
                                        time_from_start=msgs.Duration.from_sec(p.time_from_start))
              for p in m.points]
    return msgs.JointTrajectory(msgs.Header(stamp=stamp), list(m.joint_names), points)


def _refuse_what_ctrl_cannot_carry(lab: Lab, recording: Recording) -> None:
    """Commands that act on the state in Python (ideal servos teleport, velocity PIDs with I or D
    terms) cannot be replayed open-loop: their output depends on the state being fitted."""
    for name in recording.commanded:
        ctrl = lab.manager.controllers[name]
        ideal = getattr(ctrl, "ideal", False)
        native = getattr(ctrl, "native", True)
        if ideal or not native:
            what = "an ideal servo (it teleports the joint)" if ideal else \
                "a velocity PID with I or D terms, computed from the measured state in Python"
            raise InputError(f"controller '{name}' is {what}: its commands cannot be replayed "
                             "through the motors", file=recording.bag,
                             hint="identify from position, trajectory or effort commands")


def _fitting_spec(lab: Lab, joints: list[str]) -> mujoco.MjSpec:
    """The Lab's model as an editable spec, with a position sensor per measured joint (MuJoCo
    computes sensors before it integrates, so row k of a rollout's sensordata is the position at
    k * timestep: the recorded samples interpolate between rows)."""
    spec = lab.sim.compiled.spec.copy()
    for joint in joints:
        spec.add_sensor(name=joint + SENSOR_SUFFIX, type=mujoco.mjtSensor.mjSENS_JOINTPOS,
                        objtype=mujoco.mjtObj.mjOBJ_JOINT, objname=joint)
    return spec


def _grid(recording: Recording) -> tuple[np.ndarray, np.ndarray]:
    """Every joint's samples on one time grid (NaN where a joint was not sampled)."""
    times = np.unique(np.concatenate([recording.t[j] for j in recording.joints]))
    measured = np.full((len(times), len(recording.joints)), np.nan)
    for col, joint in enumerate(recording.joints):
        rows = np.searchsorted(times, recording.t[joint])
        measured[rows, col] = recording.q[joint]
    return times, measured
