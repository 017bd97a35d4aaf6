"""joint_trajectory_controller: time-parameterised waypoints, linear between positions, cubic
(Hermite) where the points carry velocities; holds the last point when done. The reference is
sampled every control period and tracked by the joints' PID servos (in MuJoCo).

A trajectory comes from the `command` topic, or as a goal (control_msgs/FollowJointTrajectory,
served by the ROS bridge) with path and goal tolerances: the goal is checked every control
period and ends with one of control_msgs' error codes, as joint_trajectory_controller does."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from mexone.bus.msgs import JointTrajectory
from mexone.control.controllers.base import ControllerContext, register
from mexone.control.controllers.position import PositionController
from mexone.control.spec import ControllerSpec
from mexone.errors import InputError
from mexone.ranges import JOINT_VALUE, VELOCITY, number_text

__all__ = ["TrajectoryController", "TrajectoryGoal", "trajectory_problem", "NOT_INCREASING",
           "SUCCESSFUL", "INVALID_GOAL", "INVALID_JOINTS",
           "PATH_TOLERANCE_VIOLATED", "GOAL_TOLERANCE_VIOLATED", "PREEMPTED"]

# joint_trajectory_controller's words for the one check it makes of the times
NOT_INCREASING = "Trajectory message contains waypoints that are not strictly increasing in time."
# control_msgs/FollowJointTrajectoryResult error codes (and PREEMPTED: a newer goal or a cancel)
SUCCESSFUL, INVALID_GOAL, INVALID_JOINTS = 0, -1, -2
PATH_TOLERANCE_VIOLATED, GOAL_TOLERANCE_VIOLATED = -4, -5
PREEMPTED = 1
FEEDBACK_PERIOD = 0.05  # s of sim time between feedbacks (actionlib's usual 20 Hz)


@dataclass
class TrajectoryGoal:
    """Tolerances per joint in the controller's joint order (> 0: checked; 0 or < 0: not),
    and who hears the outcome. The callbacks run in the simulation thread."""

    path_position: np.ndarray
    goal_position: np.ndarray
    goal_velocity: np.ndarray
    goal_time: float  # s after the trajectory's end the goal tolerances may still be met
    done: Callable[[int, str], None]
    feedback: Callable[[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray], None] | None = None
    end: float = 0.0
    last_feedback: float = field(default=-np.inf)


@dataclass
class _Segment:
    t0: float
    t1: float
    p0: np.ndarray
    p1: np.ndarray
    v0: np.ndarray | None
    v1: np.ndarray | None


@register("effort_controllers/JointTrajectoryController", "EffortJointInterface", False)
@register("position_controllers/JointTrajectoryController", "PositionJointInterface", False)
class TrajectoryController(PositionController):
    kind = "trajectory"
    sliders = False
    holds_position = False  # its commands are trajectories, not setpoints
    takes_trajectories = True

    def __init__(self, spec: ControllerSpec, ctx: ControllerContext) -> None:
        super().__init__(spec, ctx)
        self.msg_type = JointTrajectory
        self.segments: list[_Segment] = []
        self.goal: TrajectoryGoal | None = None

    @property
    def periodic(self) -> bool:
        return True

    def starting(self, t: float) -> None:
        super().starting(t)
        self.segments = []
        self._end_goal(PREEMPTED, "the controller restarted")

    def stopping(self) -> None:
        self._end_goal(PREEMPTED, "the controller stopped")
        super().stopping()

    def values(self, msg: object) -> JointTrajectory | None:
        if not isinstance(msg, JointTrajectory):
            raise InputError(f"{self.name} takes JointTrajectory, not {type(msg).__name__}")
        missing = [j for j in self.joints if j not in msg.joint_names]
        if missing or not msg.points:
            self.warn_once("traj", f"trajectory without points or joints {missing}; ignored")
            return None
        problem = trajectory_problem(msg)
        if problem:
            self.warn_once("bad", f"{problem}; trajectory ignored")
            return None
        return msg

    def apply(self, msg: JointTrajectory, t: float) -> None:
        """Replace the trajectory (a topic command also ends a goal in progress, as in ROS)."""
        self._end_goal(PREEMPTED, "replaced by a command on the topic")
        self._replace(msg, t)

    def _replace(self, msg: JointTrajectory, t: float) -> bool:
        """Replace the trajectory; it starts at its header stamp, or now if that is zero."""
        order = {name: i for i, name in enumerate(msg.joint_names)}
        start = msg.header.stamp.to_sec() or t
        idx = [order[j] for j in self.joints]
        limits = self.hw.lower[self.rows], self.hw.upper[self.rows]
        segments, t_prev = [], t
        p_prev, v_prev = self.setpoint, self.hw.command.velocity[self.rows].copy()
        for point in msg.points:
            p = np.array([point.positions[i] for i in idx], dtype=float)
            v = np.array([point.velocities[i] for i in idx], dtype=float) if point.velocities else None
            if not np.isfinite(p).all() or (v is not None and not np.isfinite(v).all()):
                self.warn_once("nan", "trajectory point is not finite; trajectory ignored")
                return False
            p = self.clamp(p, *limits, "joint limits")
            t_point = start + point.time_from_start.to_sec()
            if t_point > t_prev:
                segments.append(_Segment(t_prev, t_point, p_prev, p,
                                         v_prev if v is not None else None, v))
            t_prev, p_prev = max(t_point, t_prev), p
            v_prev = v if v is not None else np.zeros(len(p))
        if not segments:
            segments.append(_Segment(t, t, p_prev, p_prev, None, None))
        self.segments = segments
        return True

    # ----- goals (FollowJointTrajectory), simulation thread ------------------------------------
    def execute(self, msg: JointTrajectory, goal: TrajectoryGoal, t: float) -> None:
        """Start a goal; a goal in progress is preempted. Bad goals end at once with their code."""
        if not self.running:
            goal.done(INVALID_GOAL, f"controller '{self.name}' is not running")
            return
        if sorted(msg.joint_names) != sorted(self.joints):
            goal.done(INVALID_JOINTS, f"joints {list(msg.joint_names)} are not this controller's "
                                      f"{self.joints}")
            return
        problem = trajectory_problem(msg)
        if problem:
            goal.done(INVALID_GOAL, problem)
            return
        self._end_goal(PREEMPTED, "preempted by a newer goal")
        if not self._replace(msg, t):
            goal.done(INVALID_GOAL, "a trajectory point is not finite")
            return
        goal.end = self.segments[-1].t1
        self.goal = goal

    def cancel(self, t: float) -> None:
        """Cancel the goal in progress and hold where the joints are (as ROS does)."""
        if self.goal is not None:
            self._end_goal(PREEMPTED, "canceled")
            self._hold(t)

    def _hold(self, t: float) -> None:
        hold = self.hw.state.position[self.rows].copy()
        self.segments = [_Segment(t, t, hold, hold, None, None)]

    def _end_goal(self, code: int, text: str) -> None:
        goal, self.goal = self.goal, None
        if goal is not None:
            goal.done(code, text)

    def _check_goal(self, t: float, desired: np.ndarray, velocity: np.ndarray) -> None:
        goal = self.goal
        if goal is None:
            return
        actual = self.hw.state.position[self.rows]
        actual_v = self.hw.state.velocity[self.rows]
        error = desired - actual
        if goal.feedback is not None and t - goal.last_feedback >= FEEDBACK_PERIOD:
            goal.last_feedback = t
            goal.feedback(t, desired, velocity, actual.copy(), actual_v.copy())
        if t < goal.end:
            tol = goal.path_position
            bad = (tol > 0) & (np.abs(error) > tol)
            if bad.any():
                joint = self.joints[int(np.flatnonzero(bad)[0])]
                self._end_goal(PATH_TOLERANCE_VIOLATED, f"{joint} left its path tolerance")
                self._hold(t)  # as joint_trajectory_controller does on an abort
            return
        pos_ok = (goal.goal_position <= 0) | (np.abs(error) <= goal.goal_position)
        vel_ok = (goal.goal_velocity <= 0) | (np.abs(actual_v) <= goal.goal_velocity)
        if (pos_ok & vel_ok).all():
            self._end_goal(SUCCESSFUL, "")
        elif t > goal.end + max(goal.goal_time, 0.0):
            joint = self.joints[int(np.flatnonzero(~(pos_ok & vel_ok))[0])]
            self._end_goal(GOAL_TOLERANCE_VIOLATED, f"{joint} is not within its goal tolerance "
                                                    f"{goal.goal_time:g} s after the trajectory's end")

    def query_state(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The reference at sim time t (control_msgs/QueryTrajectoryState): positions, velocities
        and accelerations (by a central difference)."""
        if not self.segments:
            p = self.setpoint
            return p, np.zeros(len(p)), np.zeros(len(p))
        h = 1e-4
        p, v = self.sample(t)
        acc = (self.sample(t + h)[1] - self.sample(t - h)[1]) / (2 * h)
        return p, v, acc

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        for seg in self.segments:
            if t < seg.t1:
                h = seg.t1 - seg.t0
                s = min(max((t - seg.t0) / h, 0.0), 1.0)
                if seg.v0 is None or seg.v1 is None:
                    return seg.p0 + s * (seg.p1 - seg.p0), (seg.p1 - seg.p0) / h
                h00, h10, h01, h11 = 2*s**3 - 3*s**2 + 1, s**3 - 2*s**2 + s, -2*s**3 + 3*s**2, s**3 - s**2
                pos = h00 * seg.p0 + h10 * h * seg.v0 + h01 * seg.p1 + h11 * h * seg.v1
                d00, d10, d01, d11 = 6*s**2 - 6*s, 3*s**2 - 4*s + 1, -6*s**2 + 6*s, 3*s**2 - 2*s
                vel = (d00 * seg.p0 + d01 * seg.p1) / h + d10 * seg.v0 + d11 * seg.v1
                return pos, vel
        last = self.segments[-1]
        return last.p1, np.zeros(len(last.p1))

    def update(self, t: float, dt: float) -> None:
        super().update(t, dt)
        if self.segments:
            desired, velocity = self.sample(t)
            self.follow(desired, velocity)
            if self.goal is not None:
                self._check_goal(t, desired, velocity)


def trajectory_problem(msg: JointTrajectory) -> str | None:
    """What makes a trajectory unusable, or None: no points; a point without one position per
    joint, or with velocities or accelerations of the wrong length; a value that is not finite
    or beyond mexone.ranges (JOINT_VALUE, VELOCITY); a negative time; times not strictly
    increasing (joint_trajectory_controller refuses those with NOT_INCREASING)."""
    n = len(msg.joint_names)
    if not msg.points:
        return "Trajectory message contains empty trajectory. Nothing to convert."
    times = []
    for k, point in enumerate(msg.points):
        if len(point.positions) != n:
            return f"point {k} has {len(point.positions)} positions for {n} joints"
        for field_name, rng in (("velocities", VELOCITY), ("accelerations", None)):
            values = getattr(point, field_name)
            if values and len(values) != n:
                return f"point {k} has {len(values)} {field_name} for {n} joints"
            for j, v in enumerate(values):
                if not np.isfinite(v) or (rng is not None and not rng.contains(abs(v))):
                    bound = f" within +-{number_text(rng.high)} {rng.unit}" if rng else ""
                    return (f"point {k}: {field_name} of {msg.joint_names[j]} {number_text(v)} "
                            f"must be finite{bound}")
        for j, v in enumerate(point.positions):
            if not JOINT_VALUE.contains(v):
                return (f"point {k} position of {msg.joint_names[j]} {number_text(v)} must be "
                        f"{JOINT_VALUE.describe()}")
        t = point.time_from_start.to_sec()
        if t < 0:
            return f"point {k} time_from_start {number_text(t)} s is negative"
        times.append(t)
    if any(b <= a for a, b in zip(times, times[1:], strict=False)):
        return NOT_INCREASING
    return None
