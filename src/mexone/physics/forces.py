"""Forces pushed onto a running simulation for a while, as Gazebo's apply_body_wrench and
apply_joint_effort do: each acts from its start to its end in sim time (integer ns), or until
cleared. The Simulation owns one `Forces` and asks it when the next change is due, so MuJoCo
steps in C between changes; with none active nothing runs per step."""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

__all__ = ["Wrench", "JointEffort", "Forces", "FOREVER"]

FOREVER = math.inf
_REFRESH_STEPS = 10  # a wrench in a moving frame (or at a point off the COM) is re-aimed this often


@dataclass
class Wrench:
    """A force and torque on a body: both in `frame_body`'s frame (-1: the world), the force
    acting at `point` (in that frame), from start_ns to end_ns of sim time."""

    body: int
    force: np.ndarray
    torque: np.ndarray
    point: np.ndarray
    frame_body: int
    start_ns: int
    end_ns: float

    def world(self, data: mujoco.MjData) -> np.ndarray:
        """[force, torque about the body's centre of mass], world frame: MuJoCo's xfrc_applied."""
        if self.frame_body < 0:
            rot, origin = np.eye(3), np.zeros(3)
        else:
            rot = data.xmat[self.frame_body].reshape(3, 3)
            origin = data.xpos[self.frame_body]
        force, torque = rot @ self.force, rot @ self.torque
        at = origin + rot @ self.point
        return np.r_[force, torque + np.cross(at - data.xipos[self.body], force)]

    @property
    def moving(self) -> bool:
        """Whether its world value changes as bodies move (then it is re-aimed every few steps)."""
        return self.frame_body >= 0


@dataclass
class JointEffort:
    dof: int
    effort: float
    start_ns: int
    end_ns: float


class Forces:
    """Timed wrenches and joint efforts; `apply(data, now)` writes their sum for this moment."""

    def __init__(self) -> None:
        self.wrenches: list[Wrench] = []
        self.efforts: list[JointEffort] = []
        self.changed = False  # something was added or cleared since the last apply

    @property
    def active(self) -> bool:
        return bool(self.wrenches or self.efforts)

    def next_change_ns(self, now: int, step_ns: int) -> float:
        """Sim time of the next start or end; soon again while a wrench must be re-aimed."""
        if self.changed:
            return now
        spans = [(w.start_ns, w.end_ns) for w in self.wrenches] + \
            [(e.start_ns, e.end_ns) for e in self.efforts]
        times = [t for span in spans for t in span if t > now]
        if any(w.moving and w.start_ns <= now for w in self.wrenches):
            times.append(now + _REFRESH_STEPS * step_ns)
        return min(times, default=FOREVER)

    def apply(self, data: mujoco.MjData, now: int, half_step: int) -> None:
        """xfrc_applied and qfrc_applied for time `now`: every force acting now (the one writer
        of both); expired ones are dropped."""
        self.changed = False
        self.wrenches = [w for w in self.wrenches if w.end_ns > now + half_step]
        self.efforts = [e for e in self.efforts if e.end_ns > now + half_step]
        data.xfrc_applied[:] = 0.0
        for w in self.wrenches:
            if w.start_ns <= now + half_step:
                data.xfrc_applied[w.body] += w.world(data)
        data.qfrc_applied[:] = 0.0
        for e in self.efforts:
            if e.start_ns <= now + half_step:
                data.qfrc_applied[e.dof] += e.effort

    def clear_body(self, body: int | None = None) -> int:
        """Drop the wrenches on `body` (all if None); how many were dropped."""
        before = len(self.wrenches)
        self.wrenches = [w for w in self.wrenches if body is not None and w.body != body]
        self.changed = True
        return before - len(self.wrenches)

    def clear_joint(self, dof: int | None = None) -> int:
        before = len(self.efforts)
        self.efforts = [e for e in self.efforts if dof is not None and e.dof != dof]
        self.changed = True
        return before - len(self.efforts)
