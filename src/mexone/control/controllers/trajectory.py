"""joint_trajectory_controller: time-parameterised waypoints, linear between positions, cubic
(Hermite) where the points carry velocities; holds the last point when done. The reference is
sampled every control period and tracked by the joints' PID servos (in MuJoCo)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mexone.bus.msgs import JointTrajectory
from mexone.control.controllers.base import register
from mexone.control.controllers.position import PositionController
from mexone.errors import InputError

__all__ = ["TrajectoryController"]


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

    def __init__(self, spec, ctx):
        super().__init__(spec, ctx)
        self.msg_type = JointTrajectory
        self.segments: list[_Segment] = []

    @property
    def periodic(self) -> bool:
        return True

    def starting(self, t: float) -> None:
        super().starting(t)
        self.segments = []

    def values(self, msg) -> JointTrajectory | None:
        if not isinstance(msg, JointTrajectory):
            raise InputError(f"{self.name} takes JointTrajectory, not {type(msg).__name__}")
        missing = [j for j in self.joints if j not in msg.joint_names]
        if missing or not msg.points:
            self.warn_once("traj", f"trajectory without points or joints {missing}; ignored")
            return None
        return msg

    def apply(self, msg: JointTrajectory, t: float) -> None:
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
                return
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
            self.follow(*self.sample(t))
