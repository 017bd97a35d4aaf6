"""Walking, planned: footsteps, the centre of mass by ZMP preview control (Kajita et al. 2003),
swing-foot arcs, and whole-body IK turning them into joint positions, one control period apart.

Footsteps come from body motions, one per step (forward, sideways, turn: a course's legs or a
cmd_vel Twist): the body's pose advances by the step's motion and the swinging foot lands
beside the pose half way there, so feet alternate ahead/aside of each other as in human gait
(the first step is a half step; a stop brings the feet side by side).

The COM follows the linear inverted pendulum at a constant height z (the "cart-table"): the
zero moment point is p = x - (z/g) x''. Preview control picks the COM's jerk each period from
the state and the ZMP reference of the next `preview` seconds (the footsteps, planned that far
ahead), so the COM starts moving before the ZMP jumps to the next foot. The feet stay flat; the
swing foot rises `step_height` on a half sine while it moves (and turns) on a cosine ease.
WholeBodyIK (feet frames + COM + upright pelvis) gives the joint positions; the routine sends
them to the position controllers. Closed by what the robot senses (IMU, encoders): at each
step the IMU's yaw against the plan's is the feet's slip, and the plan still ahead turns about
the stance foot to cancel it; each period the ankles take back a share of the pelvis's measured
tilt, so the soles stay flat on the ground (tilted onto an edge a foot loses its grip and spins;
see the README); and at each lift-off the centre of mass measured relative to the stance foot
(encoders, IMU attitude and gyro through the model's kinematics) gives the capture point's
error against the plan's: the swing foot lands that much further and the plan ahead moves with
it (Pratt et al. 2006). Without that, sidesteps sway wider each step until the robot tips: the
real COM lags the plan's weight shift by 1-3 cm and its sway is not the plan's.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field, fields
from functools import cached_property
from pathlib import Path

import mink
import numpy as np
import scipy.linalg

from mexone import yamlio
from mexone.errors import InputError
from mexone.motion.ik import WholeBodyIK

__all__ = ["Gait", "preview_gains", "FootstepPlanner", "PlanTick", "Swing", "bent_knees",
           "walk_ticks", "course_steps", "Measured", "ComEstimate", "GAIT_YAML", "LEGS", "COURSE",
           "WalkPlan", "com_rollout", "DRAWN_STEPS"]

G = 9.81
MAX_CORRECTION = 0.05  # rad: the most one step turns the plan to cancel the feet's slip
IK_ITERATIONS = 2  # IK steps (QPs) per solve: most of walking's CPU (1: turns overshoot 6 deg)
IK_EVERY = 1  # control periods per IK solve, the targets carried on between (2, 50 Hz: falls sideways)
CORRECTION_GAIN = 0.3  # share of the measured slip one step cancels
SLIP_WINDOW = 2.0  # steps the slip is averaged over
BIAS_SHARE = 0.2  # share of each landing's capture-point error its foot's running mean takes
MAX_STEP_SHIFT = 0.04  # m: the most one landing moves against the COM's error
MIN_APART = 0.10  # m between the feet's centres at least (Mex-One's soles are 0.08 m wide)
GAIT_YAML = Path(__file__).resolve().parents[1] / "robots" / "mex_one" / "routines" / "walk.yaml"
LEGS = ("forward", "sideways", "turn")  # a course's legs: metres, metres (left +), degrees (left +)
COURSE = (("forward", 3.0), ("turn", 90.0), ("sideways", -1.0))  # the course
DRAWN_STEPS = 40  # footsteps already walked that a WalkPlan keeps (cmd_vel walks for ever)


@dataclass(frozen=True)
class Gait:
    """The walking parameters a student edits (robots/mex_one/routines/walk.yaml)."""

    step_length: float = 0.06   # m, forward per step at most
    side_step: float = 0.025    # m, sideways per step at most
    turn_step: float = 0.2      # rad, turn per step at most
    step_height: float = 0.03   # m, swing foot's highest lift
    period: float = 0.4         # s per step
    double_support: float = 0.2  # share of the period both feet are down
    knee_bend: float = 0.4      # rad: the legs walk bent (straight knees are singular for height)
    dt: float = 0.01            # s, control period
    preview: float = 1.6        # s of ZMP reference the COM looks ahead
    stand: float = 1.0          # s standing before the first step and after the last
    flat_feet: float = 0.3      # share of the pelvis's measured tilt the ankles take back
    step_feedback: float = 1.0  # share of the measured capture-point error each landing takes
    course: tuple[tuple[str, float], ...] = COURSE  # what `mexone run walk` walks

    @classmethod
    def load(cls, path: Path | str = GAIT_YAML) -> Gait:
        raw = yamlio.load(Path(path).read_text()) or {}
        known = {f.name for f in fields(cls)}
        if not isinstance(raw, dict) or set(raw) - known:
            extra = sorted(set(raw) - known) if isinstance(raw, dict) else raw
            raise InputError(f"{path}: unknown gait parameter(s) {extra}",
                             hint="parameters: " + ", ".join(sorted(known)))
        values = {}
        for key, value in raw.items():
            if key == "course":
                values[key] = parse_course(value, str(path))
            elif isinstance(value, bool) or not isinstance(value, int | float) \
                    or not math.isfinite(value):
                raise InputError(f"{path}: {key} is {value!r}, not a number")
            else:
                values[key] = float(value)
        gait = cls(**values)
        if not (gait.period > 0 and 0 <= gait.double_support < 1 and gait.dt > 0
                and gait.step_length > 0 and gait.side_step > 0 and gait.turn_step > 0):
            raise InputError(f"{path}: period, dt, step_length, side_step and turn_step must be > 0, "
                             "double_support in [0, 1)")
        return gait


def parse_course(value, where: str = "course") -> tuple[tuple[str, float], ...]:
    """[[forward, 3.0], [turn, 90], [sideways, -1.0]]: legs walked one after the other."""
    hint = "a list of [leg, amount]: forward m, sideways m (left +), turn degrees (left +)"
    if not isinstance(value, list | tuple):
        raise InputError(f"{where}: the course is {value!r}", hint=hint)
    out = []
    for item in value:
        if not (isinstance(item, list | tuple) and len(item) == 2 and item[0] in LEGS
                and isinstance(item[1], int | float) and not isinstance(item[1], bool)
                and math.isfinite(item[1])):
            raise InputError(f"{where}: course leg {item!r} is not [leg, amount]", hint=hint)
        out.append((str(item[0]), float(item[1])))
    return tuple(out)


def course_steps(gait: Gait, course: Iterable[tuple[str, float]]) -> Iterator[tuple[str, np.ndarray]]:
    """Each step's body motion (dx, dy, dyaw; m, m, rad in the body's frame) walking `course`,
    as even steps no longer than the gait's, labelled with their leg's name; None between legs
    (the feet come side by side and stand a period: each leg starts from a square stance)."""
    for i, (leg, amount) in enumerate(course):
        if i:
            yield None
        most, index = {"forward": (gait.step_length, 0), "sideways": (gait.side_step, 1),
                       "turn": (gait.turn_step, 2)}[leg]
        amount = math.radians(amount) if leg == "turn" else amount
        n = math.ceil(abs(amount) / most - 1e-9)
        motion = np.zeros(3)
        if n:
            motion[index] = amount / n
        for _ in range(n):
            yield leg, motion


def preview_gains(z: float, dt: float, horizon: int):
    """The cart-table model (state: position, velocity, acceleration; input: jerk) and its
    preview controller: integral gain, state gain, and the gains on the next `horizon` ZMP
    references (Katayama et al. 1985, as Kajita 2003 uses)."""
    a = np.array([[1.0, dt, dt * dt / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    b = np.array([[dt ** 3 / 6], [dt * dt / 2], [dt]])
    c = np.array([[1.0, 0.0, -z / G]])
    # augmented with the summed ZMP error, so the ZMP settles on its reference
    aa = np.block([[np.eye(1), c @ a], [np.zeros((3, 1)), a]])
    bb = np.vstack([c @ b, b])
    q, r = np.diag([1.0, 0.0, 0.0, 0.0]), np.array([[1e-6]])
    p = scipy.linalg.solve_discrete_are(aa, bb, q, r)
    inv = np.linalg.inv(r + bb.T @ p @ bb)
    k = inv @ bb.T @ p @ aa
    closed = aa - bb @ k
    x = -closed.T @ p @ np.array([[1.0], [0.0], [0.0], [0.0]])
    preview = np.empty(horizon)
    for j in range(horizon):
        preview[j] = (inv @ bb.T @ x).item()
        x = closed.T @ x
    return a, b, c, k[0, 0], k[0, 1:], preview


def _preview_step(x: np.ndarray, summed: np.ndarray, ref, ahead: np.ndarray, gains):
    """One control period of preview control: the COM's next state (position, velocity,
    acceleration; x y) and summed ZMP error, for the reference `ref` now and `ahead` after it."""
    a, b, c, k_sum, k_state, k_preview = gains
    summed = summed + ((c @ x)[0] - ref)  # the order walking always summed in
    jerk = -k_sum * summed - k_state @ x - k_preview @ ahead
    return a @ x + b @ jerk[None, :], summed


def com_rollout(x: np.ndarray, summed: np.ndarray, refs, horizon: int, gains) -> np.ndarray:
    """The COM positions (n, 2) preview control will give over the ZMP references `refs` (the
    plan's periods ahead, the last one held after them) from the state `x`: the planned path."""
    refs = np.asarray(refs, dtype=float).reshape(-1, 2)
    padded = np.vstack([refs, np.repeat(refs[-1:], horizon, axis=0)])
    out = np.empty((len(refs), 2))
    for j in range(len(refs)):
        x, summed = _preview_step(x, summed, refs[j], padded[j + 1:j + 1 + horizon], gains)
        out[j] = x[0]
    return out


@dataclass
class WalkPlan:
    """The plan as it stands, for drawing (world frame, m): the footsteps (x, y, yaw; the last
    DRAWN_STEPS walked, then those planned), the ZMP reference and the COM preview control
    gives, each a control period apart from now to the end of what is planned. The COM is
    worked out when first read (a few ms): a plan nobody draws costs nothing."""

    footsteps: list[np.ndarray]
    zmp: np.ndarray  # (n, 2)
    ground: float    # the soles' height
    com_height: float  # the cart-table's constant COM height
    dt: float        # s between the paths' points
    state: tuple = field(repr=False, default=())  # the preview's (x, summed, horizon, gains)

    @cached_property
    def com(self) -> np.ndarray:
        """(n, 2), the first now."""
        x, summed, horizon, gains = self.state
        if len(self.zmp) < 2:
            return x[0][None, :].copy()
        return np.vstack([x[0], com_rollout(x, summed, self.zmp[1:], horizon, gains)])


def compose(pose: np.ndarray, motion) -> np.ndarray:
    """pose (x, y, yaw) moved by `motion` given in its own frame."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.array([pose[0] + c * motion[0] - s * motion[1],
                     pose[1] + s * motion[0] + c * motion[1], pose[2] + motion[2]])


@dataclass
class Swing:
    """One foot's step: from `origin` to `target` (x, y, yaw), both planned poses."""

    foot: int  # 0 left, 1 right
    origin: np.ndarray
    target: np.ndarray
    started: bool = False


@dataclass
class PlanTick:
    """One control period of the plan: the ZMP reference, the swing under way (and how far)."""

    zmp: np.ndarray
    swing: Swing | None = None
    progress: float = 0.0
    leg: str | None = None  # the course leg this period walks (its closing steps too); None: standing


END = object()


class FootstepPlanner:
    """The plan, a period at a time, `lookahead` periods ahead of the one walked: footsteps from
    a source of body motions (each a step, None: stand a period; its end: stop and stand)."""

    def __init__(self, gait: Gait, feet: list[np.ndarray], source: Iterable, lookahead: int = 0):
        self.gait = gait
        self.feet = [np.array(f, dtype=float) for f in feet]  # the last planned pose of each
        yaw = (self.feet[0][2] + self.feet[1][2]) / 2
        middle = (self.feet[0][:2] + self.feet[1][:2]) / 2
        self.body = np.array([*middle, yaw])
        across = self.feet[0][:2] - self.feet[1][:2]
        self.width = float(-math.sin(yaw) * across[0] + math.cos(yaw) * across[1])
        self.source = iter(source)
        self.lookahead = lookahead
        self.ticks: deque[PlanTick] = deque()
        self.standing = True
        self.ended = False
        self.next_foot = 0
        self.last_leg: str | None = None
        self.n_double = round(gait.double_support * gait.period / gait.dt)
        self.n_single = round((1 - gait.double_support) * gait.period / gait.dt)
        self._last_zmp = self._middle()
        self._extend(self._middle(), round(gait.stand / gait.dt))

    def __iter__(self) -> Iterator[PlanTick]:
        while True:
            while not self.ended and len(self.ticks) <= self.lookahead:
                self._plan_next()
            if not self.ticks:
                return
            tick = self.ticks.popleft()
            self._last_zmp = tick.zmp.copy()
            yield tick

    def _middle(self) -> np.ndarray:
        return (self.feet[0][:2] + self.feet[1][:2]) / 2

    def _extend(self, zmp, n: int, leg: str | None = None) -> None:
        self.ticks.extend(PlanTick(np.array(zmp, dtype=float), leg=leg) for _ in range(n))

    def _zmp_now(self) -> np.ndarray:
        """The ZMP reference at the end of the plan so far (walked or not)."""
        return self.ticks[-1].zmp.copy() if self.ticks else self._last_zmp

    def _plan_next(self) -> None:
        item = next(self.source, END)
        if item is END or item is None:
            if not self.standing:  # both feet onto the body's pose, then the ZMP between them
                leg = self.last_leg or "stop"
                self._step(np.zeros(3), leg, close=True)  # part of the leg they end
                self._step(np.zeros(3), leg, close=True)
                start, middle = self._zmp_now(), self._middle()
                for i in range(self.n_double):
                    self._extend(start + (middle - start) * (i + 1) / self.n_double, 1, leg)
                self.standing = True
            n = round((self.gait.stand if item is END else self.gait.period) / self.gait.dt)
            self._extend(self._middle(), n)
            self.ended = item is END
            return
        leg, motion = item
        self._step(np.asarray(motion, dtype=float), leg)

    def _step(self, motion: np.ndarray, leg: str, close: bool = False) -> None:
        swing = self.next_foot
        stance = 1 - swing
        side = self.width / 2 if swing == 0 else -self.width / 2
        # sideways, the leading foot steps out twice the motion and the trailing one closes in:
        # the feet never come closer than at standing (their edges are 4 cm apart there)
        lateral = motion[1] * (2.0 if motion[1] * side > 0 else 1.0)
        half = compose(self.body, (motion[0] / 2, 0.0, motion[2] / 2))
        target = compose(half, (0.0, side + lateral, 0.0))
        stance_pose = self.feet[stance]
        across = np.array([-math.sin(target[2]), math.cos(target[2])])
        apart = float(np.dot(target[:2] - stance_pose[:2], across)) * np.sign(side)
        if apart < abs(self.width):  # the first step of a sideways leg by the trailing foot
            target[:2] += across * np.sign(side) * (abs(self.width) - apart)
        self.body = compose(self.body, motion)
        if close:  # square under the body, standing's width apart
            target = compose(self.body, (0.0, side, 0.0))
        start, foot = self._zmp_now(), self.feet[stance][:2].copy()
        for i in range(self.n_double):
            self._extend(start + (foot - start) * (i + 1) / self.n_double, 1, leg)
        step = Swing(swing, self.feet[swing], target)
        for i in range(self.n_single):
            self.ticks.append(PlanTick(foot.copy(), step, (i + 1) / self.n_single, leg))
        self.feet[swing] = target
        self.next_foot = stance
        self.standing = False
        self.last_leg = leg

    def shift_ahead(self, delta, swing: Swing) -> None:
        """Move everything from `swing`'s landing on (its target, the footsteps after it, the
        ZMP; the ZMP's shift onto it ramps in over the double support) by `delta` (m, x y):
        the stance foot and the ZMP on it stay."""
        delta = np.asarray(delta, dtype=float)[:2]
        moved: set[int] = set()

        def move(pose: np.ndarray, share: float = 1.0) -> None:
            if id(pose) not in moved:
                moved.add(id(pose))
                pose[:2] += share * delta

        move(swing.target)
        after, ramp = False, 0
        for tick in self.ticks:
            if not after:
                after = tick.swing is not swing
            if not after:
                continue
            if tick.swing is None and ramp < self.n_double:
                ramp += 1
                move(tick.zmp, ramp / self.n_double)
                continue
            ramp = self.n_double
            move(tick.zmp)
            if tick.swing is not None and not tick.swing.started:
                move(tick.swing.target)
        for pose in (*self.feet, self.body):
            if any(t.swing is not None and t.swing.target is pose for t in self.ticks) \
                    or pose is self.body or pose is swing.target:
                move(pose)

    def turn_ahead(self, angle: float, pivot) -> None:
        """Turn everything still ahead (ZMP, footsteps not yet begun, the body) by `angle` rad
        about the ground point `pivot`: the stance foot, which stays."""
        c, s = math.cos(angle), math.sin(angle)
        rot = np.array([[c, -s], [s, c]])
        pivot = np.asarray(pivot, dtype=float)[:2]
        turned: set[int] = set()

        def turn(pose: np.ndarray, with_yaw: bool) -> None:
            if id(pose) in turned:
                return
            turned.add(id(pose))
            pose[:2] = pivot + rot @ (pose[:2] - pivot)
            if with_yaw:
                pose[2] += angle

        for tick in self.ticks:
            turn(tick.zmp, False)
            if tick.swing is not None and not tick.swing.started:
                turn(tick.swing.target, True)
        for pose in (*self.feet, self.body):
            if any(t.swing is not None and t.swing.target is pose for t in self.ticks) \
                    or pose is self.body:
                turn(pose, True)


def _heading(ik: WholeBodyIK) -> float:
    """The IK's base yaw (rad); body 1 is the floating base, the world's first child."""
    rotation = ik.configuration.data.xmat[1].reshape(3, 3)
    return float(np.arctan2(rotation[1, 0], rotation[0, 0]))


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def _yaw(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def bent_knees(ik: WholeBodyIK, qpos: np.ndarray, bend: float) -> np.ndarray:
    """The standing configuration with hips, knees and ankles bent (feet under the hips, the
    pelvis lowered so the soles stay on the ground): where walking starts and ends."""
    q = np.array(qpos, dtype=float)
    for side in "lr":
        for joint, angle in (("hip_pitch", -bend), ("knee", 2 * bend), ("ankle_pitch", -bend)):
            q[ik.model.jnt_qposadr[ik.model.joint(f"{side}_{joint}").id]] = angle
    thigh_and_shank = 0.46  # m, Mex-One's 0.23 + 0.23
    q[2] -= thigh_and_shank * (1 - np.cos(bend))
    return q


@dataclass
class Measured:
    """What the robot senses of itself: joint positions and velocities (encoders), the
    pelvis's roll, pitch (IMU attitude) and angular velocity (gyro, its own frame)."""

    positions: dict[str, float]
    velocities: dict[str, float]
    roll: float
    pitch: float
    gyro: np.ndarray


class ComEstimate:
    """The centre of mass's position and velocity relative to a foot (m, m/s; x y in the IK's
    heading) from what the robot senses: forward kinematics and Jacobians on a data of the
    IK's own model. Relative to a foot, so no position sensor is needed."""

    def __init__(self, ik: WholeBodyIK, names: tuple[str, str]):
        import mujoco
        self._mj = mujoco
        self.ik = ik
        self.data = mujoco.MjData(ik.model)
        self.sites = [ik.model.site(ik.frames[n].site).id for n in names]
        model = ik.model
        self.dof_adr = np.array([model.jnt_dofadr[model.joint(j).id] for j in ik.joint_names])
        self.jac_com = np.zeros((3, model.nv))
        self.jac_foot = np.zeros((3, model.nv))

    def relative(self, sensed: Measured, foot: int) -> tuple[np.ndarray, np.ndarray]:
        mj, data, ik, model = self._mj, self.data, self.ik, self.ik.model
        data.qpos[:] = ik.configuration.q
        data.qvel[:] = 0.0
        for name, adr, dof in zip(ik.joint_names, ik.qpos_adr, self.dof_adr, strict=True):
            data.qpos[adr] = sensed.positions.get(name, data.qpos[adr])
            data.qvel[dof] = sensed.velocities.get(name, 0.0)
        c, s = math.cos(sensed.roll), math.sin(sensed.roll)
        rx = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
        c, s = math.cos(sensed.pitch), math.sin(sensed.pitch)
        ry = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
        quat = np.empty(4)
        mj.mju_mat2Quat(quat, (_yaw(_heading(ik)) @ ry @ rx).ravel())
        data.qpos[3:7] = quat
        data.qvel[3:6] = sensed.gyro  # the free joint's angular velocity is in the body's frame
        mj.mj_kinematics(model, data)
        mj.mj_comPos(model, data)
        mj.mj_jacSubtreeCom(model, data, self.jac_com, 1)
        site = self.sites[foot]
        mj.mj_jacSite(model, data, self.jac_foot, None, site)
        position = data.subtree_com[1][:2] - data.site_xpos[site][:2]
        velocity = ((self.jac_com - self.jac_foot) @ data.qvel)[:2]
        return position, velocity


def _foot_pose(ik: WholeBodyIK, foot: str) -> np.ndarray:
    position, rotation = ik.pose(foot)
    return np.array([position[0], position[1], math.atan2(rotation[1, 0], rotation[0, 0])])


def nominal_feet(width: float = 0.12) -> list[np.ndarray]:
    """Feet side by side at the origin, facing +x: a plan's timing does not depend on where."""
    return [np.array([0.0, width / 2, 0.0]), np.array([0.0, -width / 2, 0.0])]


def walk_ticks(ik: WholeBodyIK, qpos: np.ndarray, gait: Gait, source: Iterable,
               imu: Callable[[], tuple[float, float, float]] | None = None,
               measured: Callable[[], Measured] | None = None,
               on_plan: Callable[[PlanTick, np.ndarray], None] | None = None,
               on_replan: Callable[[WalkPlan], None] | None = None
               ) -> Iterator[dict[str, float]]:
    """Walk the body motions of `source` (course_steps, or a cmd_vel's) from the standing
    configuration `qpos`: the joint positions of each control period, planned as they are
    needed (the first is the bent-knee stance the robot should already be in). `imu`, if
    given, measures the pelvis's roll, pitch, yaw (rad): at each step the plan ahead turns
    against the yaw's difference from the IK's, so slipping feet do not steer, and the ankles
    take back `flat_feet` of the tilt. `measured`, if given, senses joints and pelvis at each
    lift-off: the landing moves by `step_feedback` of the capture point's error (less its
    running mean: a steady lean is not chased). `on_plan(tick, com)` sees each period's plan
    (for drawing it); `on_replan(plan)` the plan ahead when it changes: at the start and at each
    lift-off (after the corrections), when the step's landing is settled and new ones planned."""
    ik.reset(bent_knees(ik, qpos, gait.knee_bend))
    names = ("l_foot", "r_foot")
    feet = [_foot_pose(ik, f) for f in names]
    ground = ik.pose(names[0])[0][2]
    horizon = round(gait.preview / gait.dt)
    planner = FootstepPlanner(gait, feet, source, lookahead=horizon + 1)
    com_height = ik.com()[2]
    gains = preview_gains(com_height - ground, gait.dt, horizon)
    x = np.zeros((3, 2))  # the COM's position, velocity, acceleration in x and y
    x[0] = ik.com()[:2]
    summed = np.zeros(2)
    correction = 0.0  # rad the plan has turned against the feet's slip
    standing = [f.copy() for f in feet]  # each foot's pose while it is down
    slips: deque[float] = deque(maxlen=int(SLIP_WINDOW * round(gait.period / gait.dt)) or 1)
    estimate = ComEstimate(ik, names) if measured is not None else None
    omega = math.sqrt(G / (ik.com()[2] - ground))
    bias = np.zeros((2, 2))  # each foot's landings' steady capture-point error (running mean)
    landings = [0, 0]
    before, after = None, None  # the IK's last two solutions
    walked: deque[np.ndarray] = deque((f.copy() for f in feet), maxlen=DRAWN_STEPS)
    for n, tick in enumerate(planner):
        ahead = [t.zmp for t in list(planner.ticks)[:horizon]]
        ahead += [ahead[-1] if ahead else tick.zmp] * (horizon - len(ahead))
        x, summed = _preview_step(x, summed, tick.zmp, np.array(ahead), gains)
        ik.set_com(x[0])
        swing = tick.swing
        replanned = n == 0
        if swing is not None:
            if not swing.started:
                swing.started = True
                replanned = True
                if slips:
                    # the world's heading less the IK's, over the last two steps (the pelvis
                    # yaws to and fro with each swing), is the feet's slip: turn the plan back
                    slip = float(np.mean(slips))
                    turn = float(np.clip(CORRECTION_GAIN * (-slip - correction),
                                         -MAX_CORRECTION, MAX_CORRECTION))
                    correction += turn
                    planner.turn_ahead(turn, standing[1 - swing.foot])
                if estimate is not None and gait.step_feedback:
                    got = estimate.relative(measured(), 1 - swing.foot)
                    # the capture point's error against the plan's: the foot lands that
                    # much further (Pratt et al. 2006), and the plan after it moves along
                    planned = x[0] - standing[1 - swing.foot][:2]
                    error = got[0] - planned + (got[1] - x[1]) / omega
                    # a steady error (the real robot leans or lags a little, step after
                    # step) is left alone: correcting it would walk shorter than planned
                    # (the mean of each foot's landings so far, then a running mean; a
                    # foot's first landing only starts it)
                    landings[swing.foot] += 1
                    steady = bias[swing.foot].copy() if landings[swing.foot] > 1 else error
                    share = max(BIAS_SHARE, 1.0 / landings[swing.foot])
                    bias[swing.foot] = steady + share * (error - steady)
                    shift = gait.step_feedback * (error - steady)
                    size = float(np.linalg.norm(shift))
                    if size > MAX_STEP_SHIFT:
                        shift *= MAX_STEP_SHIFT / size
                    # ...but never so far in that the feet touch
                    yaw = swing.target[2]
                    across = np.array([-math.sin(yaw), math.cos(yaw)]) * (1 - 2 * swing.foot)
                    apart = float(np.dot(swing.target[:2] + shift
                                         - standing[1 - swing.foot][:2], across))
                    if apart < MIN_APART:
                        shift += across * (MIN_APART - apart)
                    planner.shift_ahead(shift, swing)
                walked.append(swing.target.copy())  # where it lands: settled now
            s = tick.progress
            ease = (1 - np.cos(np.pi * s)) / 2
            pose = swing.origin + (swing.target - swing.origin) * ease
            ik.set_target(names[swing.foot], [pose[0], pose[1], ground + gait.step_height *
                                              np.sin(np.pi * s)], _yaw(pose[2]))
            if s >= 1.0:
                standing[swing.foot] = swing.target.copy()
            else:
                standing[swing.foot] = pose
        if ik.base is not None:
            yaw = (standing[0][2] + standing[1][2]) / 2
            ik.base.set_target(mink.SE3.from_rotation(mink.SO3.from_rpy_radians(0.0, 0.0, yaw)))
        if n % IK_EVERY == 0:  # the IK solves every IK_EVERY periods; between, interpolated
            for _ in range(IK_ITERATIONS):  # the targets are met, not chased
                ik.step(gait.dt * IK_EVERY)
            solved = ik.joint_positions()
            before, after = after or solved, solved
        share = 1.0 + (n % IK_EVERY) / IK_EVERY  # on time: the last step carried on
        joints = {name: before[name] + share * (after[name] - before[name]) for name in after}
        if imu is not None:
            roll, pitch, yaw = imu()
            slips.append(_wrap(yaw - _heading(ik)))
            # the legs tilt with the pelvis and lift the soles' edges: the feet lose grip and
            # spin; the ankles turn them back toward flat by a share of the tilt
            for side in "lr":
                joints[f"{side}_ankle_pitch"] -= gait.flat_feet * pitch
                joints[f"{side}_ankle_roll"] -= gait.flat_feet * roll
        if on_plan is not None:
            on_plan(tick, x[0].copy())
        if replanned and on_replan is not None:
            on_replan(_plan_now(planner, walked, tick, x, summed, horizon, gains, ground,
                                com_height, gait.dt))
        yield joints


def _plan_now(planner: FootstepPlanner, walked, tick: PlanTick, x, summed, horizon: int, gains,
              ground: float, com_height: float, dt: float) -> WalkPlan:
    ahead, seen = [], set()
    for t in planner.ticks:
        if t.swing is not None and not t.swing.started and id(t.swing) not in seen:
            seen.add(id(t.swing))
            ahead.append(t.swing.target.copy())
    zmp = np.array([tick.zmp, *(t.zmp for t in planner.ticks)])
    return WalkPlan([*walked, *ahead], zmp, ground, com_height, dt,
                    (x.copy(), summed.copy(), horizon, gains))


def plan_phases(gait: Gait, source: Iterable) -> tuple[float, list[tuple[str, float, float]]]:
    """How long walking `source` takes (s, from the first period) and its legs' spans
    (leg, start s, end s): the plan's timing, which corrections never change."""
    phases: list[list] = []
    n = 0
    for n, tick in enumerate(FootstepPlanner(gait, nominal_feet(), source), start=1):
        if tick.leg is not None:
            if phases and phases[-1][0] == tick.leg and phases[-1][2] == (n - 1) * gait.dt:
                phases[-1][2] = n * gait.dt
            else:
                phases.append([tick.leg, (n - 1) * gait.dt, n * gait.dt])
    return n * gait.dt, [(leg, round(a, 6), round(b, 6)) for leg, a, b in phases]
