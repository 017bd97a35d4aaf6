"""Whole-body differential inverse kinematics with mink, on a copy of the simulated model.

mink solves, at each step, a small quadratic program for joint velocities that best serve a set
of weighted tasks (frames where they should be, the centre of mass over the feet, a preferred
posture, a gaze) subject to the joints' position and velocity limits, then integrates them.
Repeated steps converge on the pose; steps of a control period give motion a robot can follow.

The model is the simulation's own compiled spec with one site per named frame (hands, soles,
camera) added, compiled again: the IK never reads or writes the simulation's MjData (which only
the simulation thread touches); it keeps its own, seeded from a snapshot of the sim's qpos.
The floating base is free in the IK: the feet are held by high-cost frame tasks, so the legs
move the pelvis, as they do on the real robot.
"""

from __future__ import annotations

from dataclasses import dataclass

import mink
import mujoco
import numpy as np

from mexone.description.transforms import rpy_to_matrix
from mexone.errors import InputError
from mexone.motion.frames import Frame, frames_for
from mexone.physics.simulation import Simulation

__all__ = ["WholeBodyIK", "FrameError", "FEET_COST", "SOLVER", "REACHED", "RESTARTS",
           "reachable_targets"]

SOLVER = "daqp"  # mink's default QP back end (installed with it)
FEET_COST = 100.0  # a planted foot outweighs a hand 100:1 (position, m) and orientation (rad)
COM_COST = 10.0  # COM over the feet (horizontal only): the robot stays standing while it reaches
POSTURE_COST = 1e-3  # a weak pull to the starting posture: picks one of many solutions
# ...stronger on the waist: turning the torso fast twists the feet on the ground (they slip in
# yaw, having only their corners' friction against it), so the arms reach first
WAIST_POSTURE_COST = 0.1
BASE_COST = 1.0  # the pelvis stays upright (orientation only)
DAMPING = 1e-3  # Levenberg-Marquardt damping: bounded steps near singular poses
REACHED = (0.005, np.radians(2.0))  # m, rad: a frame closer than this to its target reached it
RESTARTS = 16  # fresh starts `solve` tries at most when the first one stops short


@dataclass(frozen=True)
class FrameError:
    """How far a frame is from its target: position (m) and orientation (rad, None if free)."""

    frame: str
    position: float
    angle: float | None

    @property
    def reached(self) -> bool:
        """Within REACHED of the target (the orientation too, if it was given)."""
        return self.position <= REACHED[0] and (self.angle is None or self.angle <= REACHED[1])

    def __str__(self) -> str:
        text = f"{self.position * 1000:.1f} mm"
        return text + (f", {np.degrees(self.angle):.1f} deg" if self.angle is not None else "")


def _site_edit(frames: dict[str, Frame]):
    def edit(spec: mujoco.MjSpec) -> None:
        for frame in frames.values():
            spec.body(frame.link).add_site(name=frame.site, pos=list(frame.offset))
    return edit


class WholeBodyIK:
    """One robot's IK: named frame targets, a COM target, a gaze, a posture; `step` moves the
    IK's own configuration one control period toward them within the joint limits."""

    def __init__(self, spec: mujoco.MjSpec, frames: dict[str, Frame], joint_names: list[str],
                 velocity_limits: dict[str, float], feet: tuple[str, ...] = ("l_foot", "r_foot")):
        spec = spec.copy()
        self.frames = frames
        _site_edit(frames)(spec)
        self.model = spec.compile()
        self.configuration = mink.Configuration(self.model)
        self.joint_names = list(joint_names)
        self.qpos_adr = np.array([self.model.jnt_qposadr[self.model.joint(j).id] for j in joint_names])
        self.limits = [mink.ConfigurationLimit(self.model),
                       mink.VelocityLimit(self.model, {j: v for j, v in velocity_limits.items()
                                                       if j in joint_names})]
        self.feet = tuple(f for f in feet if f in frames)
        self.targets: dict[str, mink.FrameTask] = {}
        self.held: dict[str, mink.FrameTask] = {}
        self.com_task = mink.ComTask(cost=np.array([COM_COST, COM_COST, 0.0]))
        cost = np.full(self.model.nv, POSTURE_COST)
        for j in range(self.model.njnt):
            if self.model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
                cost[self.model.jnt_dofadr[j]:self.model.jnt_dofadr[j] + 6] = 0.0
            elif "waist" in self.model.joint(j).name:
                cost[self.model.jnt_dofadr[j]] = WAIST_POSTURE_COST
        self.posture = mink.PostureTask(self.model, cost=cost)
        root = self.model.body(int(self.model.jnt_bodyid[0])).name if self.model.njnt and \
            self.model.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE else None
        self.base = mink.FrameTask(root, "body", position_cost=0.0, orientation_cost=BASE_COST) \
            if root else None
        self.gaze: mink.LookAtTask | None = None

    @classmethod
    def for_sim(cls, sim: Simulation) -> WholeBodyIK:
        """IK for a simulation's robot (reads only its compiled spec, never its data)."""
        robot = sim.robot
        velocity = {j.name: j.limit.velocity for j in robot.moving_joints
                    if j.limit and j.limit.velocity > 0}
        return cls(sim.compiled.spec, frames_for(robot), sim.joint_names, velocity)

    def support_joints(self) -> set[str]:
        """Joints on the chains from the base to the feet: the ones the ground closes a loop
        through (an integral on them fights the whole body's balance)."""
        out = set().union(*(self._chain_joints(foot) for foot in self.feet))
        return {self.model.joint(j).name for j in out} & set(self.joint_names)

    # ----- state ---------------------------------------------------------------------------------
    def reset(self, qpos: np.ndarray) -> None:
        """Start from this configuration (a snapshot of the simulation's qpos): the feet are
        held where they are, the COM over where it is, the posture is this one, no target."""
        self.configuration.update(np.asarray(qpos, dtype=float).copy())
        self.targets.clear()
        self.gaze = None
        self.held = {}
        for foot in self.feet:
            task = self._frame_task(foot, FEET_COST, FEET_COST)
            task.set_target_from_configuration(self.configuration)
            self.held[foot] = task
        self.com_task.set_target_from_configuration(self.configuration)
        self.posture.set_target_from_configuration(self.configuration)
        if self.base is not None:
            self.base.set_target(mink.SE3.from_rotation(mink.SO3.identity()))

    def _frame(self, name: str) -> Frame:
        if name not in self.frames:
            raise InputError(f"no frame named '{name}'",
                             hint="frames: " + ", ".join(sorted(self.frames)))
        return self.frames[name]

    def _frame_task(self, name: str, position_cost: float, orientation_cost: float) -> mink.FrameTask:
        return mink.FrameTask(self._frame(name).site, "site", position_cost=position_cost,
                              orientation_cost=orientation_cost, lm_damping=DAMPING)

    @property
    def qpos(self) -> np.ndarray:
        """The IK's configuration now (MuJoCo's qpos of its model)."""
        return self.configuration.q.copy()

    def joint_positions(self) -> dict[str, float]:
        """The IK's solution: joint -> position, for the position controllers."""
        q = self.configuration.q
        return {name: float(q[adr]) for name, adr in zip(self.joint_names, self.qpos_adr, strict=True)}

    def joint_range(self, joint: str) -> tuple[float, float]:
        """(lower, upper) position limit; unlimited joints give infinities."""
        j = self.model.joint(joint).id
        if not self.model.jnt_limited[j]:
            return -np.inf, np.inf
        low, high = self.model.jnt_range[j]
        return float(low), float(high)

    def pose(self, frame: str) -> tuple[np.ndarray, np.ndarray]:
        """World position and rotation matrix of a named frame in the IK's configuration."""
        site = self.model.site(self._frame(frame).site).id
        data = self.configuration.data
        return data.site_xpos[site].copy(), data.site_xmat[site].reshape(3, 3).copy()

    def com(self) -> np.ndarray:
        """The centre of mass of the IK's configuration (world frame)."""
        return self.configuration.data.subtree_com[1].copy()

    # ----- targets -------------------------------------------------------------------------------
    def set_target(self, frame: str, xyz, rotation: np.ndarray | None = None) -> None:
        """Move `frame` to xyz (world, m), and to `rotation` (3x3) if given."""
        xyz = np.asarray(xyz, dtype=float)
        if xyz.shape != (3,) or not np.isfinite(xyz).all():
            raise InputError(f"target for '{frame}' must be three finite numbers (x, y, z in m)")
        task = self.targets.get(frame) or self.held.pop(frame, None)
        if task is None:
            task = self._frame_task(frame, 1.0, 1.0)
        task.set_orientation_cost(1.0 if rotation is not None else 0.0)
        if frame in self.feet:
            task.set_position_cost(FEET_COST)
            task.set_orientation_cost(FEET_COST if rotation is not None else 0.0)
        rot = rotation if rotation is not None else np.eye(3)
        task.set_target(mink.SE3.from_rotation_and_translation(mink.SO3.from_matrix(rot), xyz))
        self.targets[frame] = task

    def set_rpy_target(self, frame: str, xyz, rpy=None) -> None:
        """Aim `frame` at `xyz` (world frame) and, given `rpy`, at that roll, pitch, yaw."""
        self.set_target(frame, xyz, None if rpy is None else rpy_to_matrix(tuple(rpy)))

    def look_at(self, xyz, frame: str = "camera") -> None:
        """Point the frame's x axis (the camera's view direction) at a world point."""
        self.gaze = mink.LookAtTask(self._frame(frame).site, "site", axis=(1.0, 0.0, 0.0),
                                    cost=1.0, lm_damping=DAMPING)
        self.gaze.set_target(np.asarray(xyz, dtype=float))

    def set_com(self, xy) -> None:
        """Hold the centre of mass over this ground point (its height is left free)."""
        target = self.com()
        target[:2] = np.asarray(xy, dtype=float)[:2]
        self.com_task.set_target(target)

    # ----- solving -------------------------------------------------------------------------------
    @property
    def tasks(self) -> list:
        """The IK's tasks now (mink's), in the order they are solved."""
        tasks = [*self.held.values(), *self.targets.values(), self.com_task, self.posture]
        tasks += [t for t in (self.base, self.gaze) if t is not None]
        return tasks

    def step(self, dt: float) -> None:
        """One control period: the joint velocities the QP picks, integrated over dt."""
        velocity = mink.solve_ik(self.configuration, self.tasks, dt, SOLVER, damping=DAMPING,
                                 limits=self.limits)
        self.configuration.integrate_inplace(velocity, dt)

    def converge(self, dt: float = 0.02, iterations: int = 300, tolerance: float = 1e-5) -> int:
        """Step until the configuration stops moving (a solution, or the closest pose the
        limits allow); returns the steps taken."""
        for i in range(iterations):
            before = self.configuration.q.copy()
            self.step(dt)
            if np.max(np.abs(self.configuration.q - before)) < tolerance:
                return i + 1
        return iterations

    def solve(self, frame: str, iterations: int = 600, restarts: int = RESTARTS,
              seed: int = 0) -> FrameError:
        """Converge on the targets set; if `frame` is still short of its own, start again from
        random positions (within limits) of the joints that carry it, legs and planted feet
        kept, and keep the closest result. Differential IK only descends from where it starts:
        a hand target behind the back, or one needing the elbow the other way, can stop in
        another local minimum (random restarts are TRAC-IK's cure). Deterministic per seed."""
        start = self.configuration.q.copy()
        chain = self._carrying(frame)
        rng = np.random.default_rng(seed)
        best_q, best = None, None
        for attempt in range(restarts + 1):
            q = start.copy()
            if attempt:
                for adr, (low, high) in chain:
                    q[adr] = rng.uniform(low, high)
            self.configuration.update(q)
            self.converge(iterations=iterations)
            error = self.error(frame)
            if best is None or _better(error, best):
                best_q, best = self.configuration.q.copy(), error
            if best.reached:
                break
        self.configuration.update(best_q)
        return best

    def _carrying(self, frame: str) -> list[tuple[int, tuple[float, float]]]:
        """(qpos address, range) of the limited hinge joints between the base and `frame`, not
        on the chain of a foot still held."""
        model = self.model
        held = set().union(*(self._chain_joints(foot) for foot in self.held))
        joints = self._chain_joints(frame)
        return [(int(model.jnt_qposadr[j]), tuple(float(v) for v in model.jnt_range[j]))
                for j in sorted(joints - held)
                if model.jnt_limited[j] and model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]

    def _chain_joints(self, frame: str) -> set[int]:
        """Ids of the joints between the base and the named frame's body."""
        model, out = self.model, set()
        body = model.site_bodyid[model.site(self._frame(frame).site).id]
        while body > 0:
            out.update(range(model.body_jntadr[body], model.body_jntadr[body] + model.body_jntnum[body]))
            body = model.body_parentid[body]
        return out

    def error(self, frame: str) -> FrameError:
        """How far `frame` is from its target (position and orientation)."""
        task = self.targets.get(frame) or self.held.get(frame)
        if task is None:
            raise InputError(f"frame '{frame}' has no target")
        target = task.transform_target_to_world
        position, rotation = self.pose(frame)
        distance = float(np.linalg.norm(position - target.translation()))
        angle = None
        if task.cost[3] > 0:
            relative = target.rotation().as_matrix().T @ rotation
            angle = float(np.arccos(np.clip((np.trace(relative) - 1) / 2, -1.0, 1.0)))
        return FrameError(frame, distance, angle)


def reachable_targets(ik: WholeBodyIK, qpos: np.ndarray, count: int,
                      frames: tuple[str, ...] = ("l_hand", "r_hand"),
                      seed: int = 0) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """`count` (frame, xyz, rotation) poses reachable by construction: forward kinematics of
    `qpos` with the joints that carry one frame alone (for the hands: the arms, not the waist
    they share) drawn uniformly within their limits, the frame drawn among `frames`. Leaves the
    IK's configuration at the last sample: `reset` it before solving."""
    rng = np.random.default_rng(seed)
    carrying = {frame: dict(ik._carrying(frame)) for frame in frames}
    own = {frame: [(adr, span) for adr, span in chain.items()
                   if not any(adr in carrying[other] for other in frames if other != frame)]
           for frame, chain in carrying.items()}
    out = []
    for _ in range(count):
        frame = frames[int(rng.integers(len(frames)))]
        q = np.asarray(qpos, dtype=float).copy()
        for adr, (low, high) in own[frame]:
            q[adr] = rng.uniform(low, high)
        ik.configuration.update(q)
        out.append((frame, *ik.pose(frame)))
    return out


def _better(error: FrameError, than: FrameError) -> bool:
    """Whether `error` is a better result than `than`: reached first, then the nearer (an angle
    weighs as the arc it sweeps 0.1 m out, about a hand's length)."""
    if error.reached != than.reached:
        return error.reached
    return error.position + 0.1 * (error.angle or 0.0) < than.position + 0.1 * (than.angle or 0.0)
