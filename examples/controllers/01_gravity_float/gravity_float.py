"""Gravity compensation alone on Mex-One's right arm: tau = g(q) - kd dq. The arm weighs nothing:
push it and it stays where you leave it.

Run it (see README.md): mexone sim --controllers controllers.yaml --pose pose.yaml
"""

from __future__ import annotations

import numpy as np

from mexone.control import Param, PythonController

__all__ = ["GravityFloat"]


class GravityFloat(PythonController):
    """Cancel the arm's weight with g(q), the torque gravity puts on each joint, read from the
    simulated model at every update, and damp its motion: with no spring it has no pose of its
    own, it floats (a robot's "hand-guiding" mode). `gravity = 0` leaves the damping alone: the
    arm falls (the comparison the README measures)."""

    command_interface = "effort"
    kd = Param(0.3, low=0.0, high=1e3, doc="viscous damping, N m s/rad")
    gravity = Param(1.0, low=0.0, high=1.0, doc="share of g(q) fed forward: 1 floats, 0 falls")

    def configure(self) -> None:
        self.start = np.zeros(len(self.joints))
        self.moved = 0.0  # rad: the farthest any joint got from where it started

    def activate(self, state) -> None:
        self.start = np.array(state.q, dtype=float)
        self.moved = 0.0

    def update(self, state, t: float, dt: float):
        self.moved = max(self.moved, float(np.abs(state.q - self.start).max()))
        weight = self.dynamics.gravity()[self.dofs]  # N m the arm's weight puts on each joint, now
        return self.gravity * weight - self.kd * state.dq

    def report(self) -> dict:
        """What `mexone sim --json` prints for this controller."""
        return {"moved_mrad": round(1e3 * self.moved, 3)}
