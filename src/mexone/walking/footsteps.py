"""The footstep planner: from a velocity command (cmd_vel) to where each foot lands, and when.

A step is one foot's swing: it lifts at `t_lift`, lands at `t_land` on the pose (x, y, z, yaw,
pitch, roll) of the ground there; both feet stand `double_support` s between steps. The body's
pose advances by the command's motion each step (vx T, vy T, wz T in its own frame, clipped to
the gait's largest step) and the swinging foot lands beside it, half the stance width out; feet
are never put closer than `min_apart` across. A zero command walks two closing steps (feet
square under the body) and stands. The plan is exported as a flat array (`Steps`): the feet's
poses on the ground now, then the next `Steps.K` steps, the one in the air first.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from mexone.bus.msgs import Twist
from mexone.control.student import Param, PythonController, State
from mexone.walking import body as _body

__all__ = ["Gait", "Steps", "FootstepPlanner", "swing_point", "flat_ground", "FootstepPlannerController"]

Terrain = Callable[[float, float], tuple[float, np.ndarray]]  # (x, y) -> (z, unit normal)
UP = np.array([0.0, 0.0, 1.0])


def flat_ground(x: float, y: float) -> tuple[float, np.ndarray]:
    """The terrain without a world: the plane z = 0 everywhere, its normal up."""
    return 0.0, UP


@dataclass(frozen=True)
class Gait:
    """The step timing and size limits."""

    single_support: float = 0.30  # s a foot is in the air
    double_support: float = 0.10  # s both feet are down between steps
    width: float = 0.12           # m between the feet's centres standing
    max_forward: float = 0.14     # m per step
    max_backward: float = 0.06
    max_sideways: float = 0.05
    max_turn: float = 0.3         # rad per step
    min_apart: float = 0.10       # m between the feet's centres, across
    start_delay: float = 0.6      # s from the first command to the first lift (the COM moves first)
    max_change: float = 0.04      # m (and rad) a step's motion changes from the last one's at most
    quick_single: float = 0.18    # s in the air of a hurried step (`FootstepPlanner.hurry`)
    quick_double: float = 0.0     # s both feet down before a hurried step
    quick_landing: float = 0.06   # s at least from a hurry to the step in the air's landing

    @property
    def period(self) -> float:
        return self.single_support + self.double_support


class Steps:
    """The exported plan: `feet` (2 x 4: each foot's x, y, z, yaw on the ground now) then K
    rows (foot 0 left / 1 right, x, y, z, yaw, pitch, roll, t_lift, t_land; NaN rows: none)."""

    K = 4
    ROW = 9
    LENGTH = 8 + K * ROW

    @staticmethod
    def pack(feet: np.ndarray, rows: list[np.ndarray]) -> np.ndarray:
        out = np.full(Steps.LENGTH, np.nan)
        out[:8] = np.asarray(feet, dtype=float).ravel()
        for i, row in enumerate(rows[:Steps.K]):
            out[8 + Steps.ROW * i:8 + Steps.ROW * (i + 1)] = row
        return out

    @staticmethod
    def feet(array: np.ndarray) -> np.ndarray:
        return np.asarray(array[:8]).reshape(2, 4)

    @staticmethod
    def rows(array: np.ndarray) -> np.ndarray:
        """(n, 9): the planned steps (NaN rows dropped)."""
        rows = np.asarray(array[8:]).reshape(Steps.K, Steps.ROW)
        return rows[np.isfinite(rows[:, 0])]

    @staticmethod
    def swing_now(array: np.ndarray, t: float) -> np.ndarray | None:
        """The step in the air at `t`, or None (both feet down)."""
        for row in Steps.rows(array):
            if row[7] <= t < row[8]:
                return row
        return None


def _min_jerk(tau: float) -> tuple[float, float, float]:
    return (10 * tau**3 - 15 * tau**4 + 6 * tau**5, 30 * tau**2 - 60 * tau**3 + 30 * tau**4,
            60 * tau - 180 * tau**2 + 120 * tau**3)


def swing_point(start: np.ndarray, target: np.ndarray, t_lift: float, t_land: float, t: float,
                height: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The swing foot's (x, y, z, yaw), its velocity and acceleration at `t`: a minimum-jerk
    move from `start` to `target`, lifted `height` on a bump 64 u^3, u = s (1 - s) (zero velocity
    and acceleration at both ends: it lands softly)."""
    span = max(t_land - t_lift, 1e-6)
    tau = min(max((t - t_lift) / span, 0.0), 1.0)
    s, ds, dds = _min_jerk(tau)
    delta = np.asarray(target[:4], dtype=float) - np.asarray(start[:4], dtype=float)
    delta[3] = math.remainder(delta[3], 2 * math.pi)
    pos = start[:4] + delta * s
    vel = delta * ds / span
    acc = delta * dds / span**2
    u = tau * (1 - tau)
    bump = 64 * u**3
    dbump = 192 * u**2 * (1 - 2 * tau)
    ddbump = 384 * u * ((1 - 2 * tau) ** 2 - u)
    pos[2] += height * bump
    vel[2] += height * dbump / span
    acc[2] += height * ddbump / span**2
    return pos, vel, acc


def _compose(pose: np.ndarray, motion: np.ndarray) -> np.ndarray:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.array([pose[0] + c * motion[0] - s * motion[1], pose[1] + s * motion[0] + c * motion[1],
                     pose[2] + motion[2]])


class FootstepPlanner:
    """Steps from a velocity command. `feet`: each foot's (x, y, z, yaw) on the ground now;
    `terrain(x, y)` -> (z, pitch, roll) of the ground there (default flat at z = 0)."""

    def __init__(self, gait: Gait, feet: np.ndarray, terrain: Terrain = flat_ground):
        self.gait = gait
        self.terrain = terrain
        self.feet = np.array(feet, dtype=float).reshape(2, 4)
        self.command = np.zeros(3)
        self.walking = False
        self.closing = 0  # closing steps still to walk after a stop
        self.next_foot = 0
        self.t_next = math.inf
        self.swing: np.ndarray | None = None  # the step in the air (a row)
        self.origin = self.feet[0].copy()  # where the foot in the air lifted from
        self.body = self._body()
        self.last_motion = np.zeros(3)  # the last committed step's motion
        self.quick = False  # the next step lifts and swings as fast as the gait allows
        self.last_foot: int | None = None  # the foot of the last step taken
        self.planned_land: tuple[float, float] | None = None  # (t_lift, t_land) before `late`

    def _body(self) -> np.ndarray:
        yaw = math.atan2(math.sin(self.feet[0, 3]) + math.sin(self.feet[1, 3]),
                         math.cos(self.feet[0, 3]) + math.cos(self.feet[1, 3]))
        return np.array([*(self.feet[0, :2] + self.feet[1, :2]) / 2, yaw])

    def set_command(self, vx: float, vy: float, wz: float) -> None:
        """m/s forward, m/s left, rad/s left; clipped to the gait's largest steps."""
        g = self.gait
        t = g.period
        self.command = np.array([min(max(vx * t, -g.max_backward), g.max_forward),
                                 min(max(vy * t, -g.max_sideways), g.max_sideways),
                                 min(max(wz * t, -g.max_turn), g.max_turn)])

    def _target(self, foot: int, body: np.ndarray, other: np.ndarray) -> np.ndarray:
        side = 1.0 if foot == 0 else -1.0
        pose = _compose(body, np.array([0.0, side * self.gait.width / 2, 0.0]))
        # never closer than min_apart to the other foot, across the body's heading
        across = np.array([-math.sin(body[2]), math.cos(body[2])]) * side
        apart = float(np.dot(pose[:2] - other[:2], across))
        if apart < self.gait.min_apart:
            pose[:2] += across * (self.gait.min_apart - apart)
        z, normal = self.terrain(pose[0], pose[1])
        # the sole flat on the ground there: the normal in the foot's heading frame
        c, s = math.cos(pose[2]), math.sin(pose[2])
        nx, ny = c * normal[0] + s * normal[1], -s * normal[0] + c * normal[1]
        pitch, roll = math.atan2(nx, normal[2]), math.atan2(-ny, math.hypot(nx, normal[2]))
        return np.array([foot, pose[0], pose[1], z, pose[2], pitch, roll])

    def _motion(self, last: np.ndarray, closing: int) -> np.ndarray:
        """The next step's motion: the command (zero while closing), changed from the last
        step's by at most max_change (the robot speeds up and slows down over a few steps)."""
        want = self.command if closing == 0 else np.zeros(3)
        return last + np.clip(want - last, -self.gait.max_change, self.gait.max_change)

    def _next_body(self, body: np.ndarray, foot: int, motion: np.ndarray) -> np.ndarray:
        # sideways and turning, the foot on that side leads: the body moves on its steps only,
        # twice as far (the trailing foot closes in)
        lead = motion.copy()
        moving_left = 1.0 if foot == 0 else -1.0
        lead[1] = 2 * motion[1] if motion[1] * moving_left > 0 else 0.0
        lead[2] = 2 * motion[2] if motion[2] * moving_left > 0 else 0.0
        return _compose(body, lead)

    def measured(self, feet: np.ndarray, t: float) -> None:
        """Where the feet on the ground really are (2 x 4, rows of a foot in the air ignored):
        the plan goes on from there, so a push's sideways drift or the feet's slip is walked
        with rather than stepped back from."""
        for f in range(2):
            if self.swing is None or int(self.swing[0]) != f or t >= self.swing[8]:
                self.feet[f] = feet[f]

    def _anchor(self, foot: int, feet: np.ndarray) -> np.ndarray:
        """The body's pose the next step of `foot` is planned from: half the stance width in
        from the standing foot."""
        stance = feet[1 - foot]
        side = 1.0 if foot == 0 else -1.0
        return _compose(np.array([stance[0], stance[1], stance[3]]),
                        np.array([0.0, side * self.gait.width / 2, 0.0]))

    def hurry(self, t: float, outward: int | None = None) -> bool:
        """Step timing adaptation, for a push the capture point runs away with: the step in the
        air lands as soon as it can (`quick_landing` from now, its swing sped up but at least
        `quick_single` long), the next one lifts `quick_double` after it (or now, both feet
        down) and swings `quick_single`. The standing foot's next step is what catches a push
        towards its side (the foot in the air cannot cross over it): the sooner the less the
        capture point has run away. `outward`: the foot on the side the push goes (both feet
        down, it is the one that steps next, whichever's turn it was). False when there is
        nothing to hurry (not walking, or the plan is already hurried)."""
        g = self.gait
        if self.quick or not self.walking:
            return False
        swing = self.swing
        if swing is not None and t < swing[8]:
            swing[8] = min(swing[8], max(t + g.quick_landing, swing[7] + g.quick_single))
            self.t_next = min(self.t_next, swing[8] + g.quick_double)
        else:
            self.t_next = min(self.t_next, t + g.quick_double)
            if outward is not None and outward != self.last_foot:
                self.next_foot = outward  # the foot on the push's side steps out, unless it just did
        self.quick = True
        return True

    def late(self, t: float, until: float, most: float) -> bool:
        """The step in the air has not touched down: its landing (and every later step) waits
        until `until`, at most `most` s after its planned landing. False when nothing is in
        the air or it has waited that long already."""
        swing = self.swing
        if swing is None or t >= swing[8]:
            return False
        if self.planned_land is None or self.planned_land[0] != swing[7]:
            self.planned_land = (swing[7], swing[8])
        new = min(until, self.planned_land[1] + most)
        if new <= swing[8]:
            return False
        self.t_next += new - swing[8]
        swing[8] = new
        return True

    def update(self, t: float) -> np.ndarray:
        """The plan at time `t` (s), as a `Steps` array."""
        g = self.gait
        moving = bool(np.any(self.command != 0))
        if not self.walking and moving:
            self.walking, self.closing = True, 0
            self.t_next = t + g.start_delay
            self.next_foot = 0 if self.command[1] > 0 or self.command[2] > 0 else 1
        elif self.walking and not moving and self.closing == 0:
            self.closing = 2
        if self.swing is not None and t >= self.swing[8]:
            self.swing = None
        while self.walking and t >= self.t_next:  # the next step lifts now: commit it
            foot = self.next_foot
            self.last_motion = self._motion(self.last_motion, self.closing)
            self.body = self._next_body(self._anchor(foot, self.feet), foot, self.last_motion)
            row = self._target(foot, self.body, self.feet[1 - foot])
            lift = self.t_next
            single = g.quick_single if self.quick else g.single_support
            self.quick = False
            self.swing = np.array([*row, lift, lift + single])
            self.origin = self.feet[foot].copy()
            self.feet[foot] = row[[1, 2, 3, 4]]
            self.next_foot, self.last_foot = 1 - foot, foot
            self.t_next = lift + single + g.double_support
            if self.closing:
                self.closing -= 1
                if self.closing == 0:
                    self.walking = False
                    self.t_next = math.inf
        ground = self.feet.copy()
        rows = []
        if self.swing is not None and t < self.swing[8]:
            rows.append(self.swing)
            foot = int(self.swing[0])
            ground[foot] = self.origin
        # the steps ahead, from the command as it is now
        feet, foot, lift, closing = self.feet.copy(), self.next_foot, self.t_next, self.closing
        walking, motion = self.walking, self.last_motion
        quick = self.quick
        while walking and len(rows) < Steps.K:
            motion = self._motion(motion, closing)
            body = self._next_body(self._anchor(foot, feet), foot, motion)
            row = self._target(foot, body, feet[1 - foot])
            single = g.quick_single if quick else g.single_support
            quick = False
            rows.append(np.array([*row, lift, lift + single]))
            feet[foot] = row[[1, 2, 3, 4]]
            foot, lift = 1 - foot, lift + single + g.double_support
            if closing:
                closing -= 1
                walking = closing > 0
        return Steps.pack(ground, rows)


# ----- the plug-in: the footstep planner in the manager's loop ---------------------------------
class FootstepPlannerController(PythonController):
    """Footsteps from geometry_msgs/Twist on `/<ns>/cmd_vel` (the page's walk pad, ROS 1, ROS 2,
    a routine; linear.x forward, linear.y left, angular.z turn left) or the `vx`, `vy`, `wz`
    parameters when no message came for `timeout` s. Claims no joints; exports `steps`
    (`Steps.LENGTH`: the feet on the ground and the next steps). The ground under each step is
    found by casting a ray down onto the world (the terrain's height and slope there). A command
    that is not finite is refused in one line and the robot stops walking."""

    command_interface = "effort"
    exports = {"steps": Steps.LENGTH}
    inputs = {"base": 13}
    optional_inputs = ("base",)
    topics = {"cmd_vel": Twist}

    vx = Param(0.0, low=-1.0, high=1.0, doc="forward speed without cmd_vel", unit="m/s")
    vy = Param(0.0, low=-1.0, high=1.0, doc="sideways speed (left +) without cmd_vel", unit="m/s")
    wz = Param(0.0, low=-2.0, high=2.0, doc="turn rate (left +) without cmd_vel", unit="rad/s")
    timeout = Param(0.5, low=0.0, high=60.0, doc="a cmd_vel older than this stands the robot", unit="s")
    single_support = Param(0.30, low=0.1, high=2.0, doc="s a foot is in the air", unit="s")
    double_support = Param(0.10, low=0.0, high=2.0, doc="s both feet are down between steps", unit="s")
    max_forward = Param(0.14, low=0.0, high=0.4, doc="longest step forward", unit="m")
    max_sideways = Param(0.05, low=0.0, high=0.2, doc="longest step sideways", unit="m")
    max_turn = Param(0.3, low=0.0, high=1.0, doc="largest turn per step", unit="rad")
    hurry_at = Param(0.02, low=0.0, high=1.0, doc="the capture point this far outside the standing "
                     "foot hurries the steps (step timing adaptation; 1 m: never)", unit="m")
    width = Param(0.12, low=0.08, high=0.4, doc="between the feet's centres", unit="m")
    touchdown = Param(0.008, low=0.0, high=0.1, doc="a sole (its lowest corner) still this high "
                      "above the ground where it lands at its landing time lands later (0: on time)",
                      unit="m")
    max_late = Param(0.03, low=0.0, high=0.3, doc="a landing waits for its touchdown this long at most",
                     unit="s")
    settle = Param(1.0, low=0.0, high=60.0, doc="s after it starts before it walks (the robot "
                   "crouches into its stance)", unit="s")

    def configure(self) -> None:
        self.model = self.dynamics.model
        self.ray = mujoco.MjData(self.model)
        self.scratch = mujoco.MjData(self.model)
        self.dyn = _body.state_dynamics(self.model, self.scratch)
        self.robot_bodies = set(range(1, self.model.nbody))
        self._latest: tuple[float, np.ndarray] | None = None  # (wall-clock-free sim time, twist)
        self.refused: str | None = None

    def _feet(self, state: State) -> np.ndarray:
        """Each sole's (x, y, z, yaw) now, from the encoders and the base (the estimator's when
        `base` is bound, else the simulator's)."""
        d = self.scratch
        d.qpos[:], d.qvel[:] = state.all_q, state.all_dq
        inputs = getattr(state, "inputs", None) or {}
        base = inputs.get("base")
        if base is not None and np.isfinite(base[0]):
            d.qpos[:3], d.qpos[3:7] = base[:3], base[3:7]
            d.qvel[:3], d.qvel[3:6] = base[7:10], base[10:13]
        self.dyn.refresh()
        feet = []
        for name in _body.FEET:
            p, r = self.dyn.pose(name)
            sole = p + r @ _body.SOLE_OFFSET
            feet.append([sole[0], sole[1], sole[2], _body.yaw_of(r)])
        return np.array(feet)

    def activate(self, state: State) -> None:
        self.ray.qpos[:] = state.all_q
        mujoco.mj_kinematics(self.model, self.ray)  # the world's geoms' poses (they never move)
        feet = self._feet(state)
        gait = Gait(self.single_support, self.double_support, self.width, self.max_forward,
                    max_sideways=self.max_sideways, max_turn=self.max_turn)
        self.planner = FootstepPlanner(gait, feet, self.terrain)
        self.refused = None
        self.hurried = 0  # steps hurried by a push (step timing adaptation)
        self.late = 0  # updates a landing waited for its foot's touchdown
        self.t_start = state.time
        self._heard_at: float | None = None

    def terrain(self, x: float, y: float) -> tuple[float, np.ndarray]:
        """(z, unit normal) of the world's surface under (x, y): a ray down onto the world's
        geoms (group 0: the ground and the terrain; the robot's are in other groups)."""
        geom = np.zeros(1, dtype=np.int32)
        normal = np.zeros(3)
        dist = mujoco.mj_ray(self.model, self.ray, np.array([x, y, 2.0]), np.array([0.0, 0.0, -1.0]),
                             _GROUND_GROUP, 1, -1, geom, normal)
        if dist < 0:
            return 0.0, UP
        return 2.0 - dist, normal if normal[2] > 0 else -normal

    def update(self, state: State, t: float, dt: float) -> np.ndarray | None:
        msg: Any = state.messages.get("cmd_vel")  # a Twist (the class `topics` names)
        if msg is not None:
            received = np.array([msg.linear.x, msg.linear.y, msg.angular.z], dtype=np.float64)
            if not np.all(np.isfinite(received)):
                if self.refused is None:
                    self.log.error("cmd_vel (%s) is not finite: refused, the robot stops walking",
                                   ", ".join(f"{v:g}" for v in received))
                self.refused = "cmd_vel not finite"
                self._command = np.zeros(3)
                self._heard_at = t
            else:
                self.refused = None
                self._command, self._heard_at = received, t
        if self._heard_at is not None and t - self._heard_at <= self.timeout:
            command = self._command
        else:
            command = np.array([self.vx, self.vy, self.wz])
        if t - self.t_start < self.settle:  # the robot settles into its stance first
            command = np.zeros(3)
        self.planner.set_command(*command)
        if self.planner.walking:
            feet = self._feet(state)
            self.planner.measured(feet, t)
            outward = self._pushed_outwards(feet, t)
            if outward is not None and self.planner.hurry(t, outward):
                self.hurried += 1
            wait = t + 2 * max(dt, 0.005)  # the next update looks again
            if self.touchdown > 0 and self._in_the_air(feet, t, dt) \
                    and self.planner.late(t, wait, self.max_late):
                self.late += 1
        self.exports["steps"][:] = self.planner.update(t)
        return None

    def _in_the_air(self, feet: np.ndarray, t: float, dt: float) -> bool:
        """The step in the air lands by the next update but its sole is still more than
        `touchdown` above the ground there (measured against the standing sole: the base's
        height estimate drifts)."""
        swing = self.planner.swing
        if swing is None or not t < swing[8] <= t + max(dt, 0.005) + 1e-9:
            return False
        f = int(swing[0])
        stand = feet[1 - f]
        low = self._lowest_corners()  # a sole landed rolled onto an edge is down
        above = (low[f] - low[1 - f]) - (swing[3] - self.terrain(stand[0], stand[1])[0])
        return bool(above > self.touchdown)

    def _lowest_corners(self) -> list[float]:
        """Each sole's lowest corner's height (the scratch state `_feet` set)."""
        out = []
        a, b = _body.SOLE_SIZE[0] / 2, _body.SOLE_SIZE[1] / 2
        for name in _body.FEET:
            p, r = self.dyn.pose(name)
            centre = p + r @ _body.SOLE_OFFSET
            out.append(float(centre[2] - abs(r[2, 0]) * a - abs(r[2, 1]) * b))
        return out

    def _pushed_outwards(self, feet: np.ndarray, t: float) -> int | None:
        """The standing foot the capture point (c + ċ/ω of the LIPM) is more than `hurry_at`
        outside of, across (the standing one while the other is in the air, either in double
        support), or None: a push sideways the next steps must catch, sooner than planned."""
        swing = self.planner.swing
        down = [1 - int(swing[0])] if swing is not None and t < swing[8] else [0, 1]
        c = self.dyn.com()
        v = self.dyn.com_jacobian() @ self.scratch.qvel
        for f in down:
            x, y, z, yaw = feet[f]
            omega = math.sqrt(9.81 / max(c[2] - z, 0.1))
            side = 1.0 if f == 0 else -1.0  # the foot's outward side: left for the left foot
            out = side * (-math.sin(yaw) * (c[0] + v[0] / omega - x)
                          + math.cos(yaw) * (c[1] + v[1] / omega - y))
            if out > self.hurry_at:
                return f
        return None

    def report(self) -> dict[str, Any]:
        return {"walking": bool(self.planner.walking), "refused": self.refused, "hurried": self.hurried,
                "late": self.late}


_GROUND_GROUP = np.array([1, 0, 0, 0, 0, 0], dtype=np.uint8)
