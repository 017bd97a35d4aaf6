"""Gravity compensation + PD on Mex-One's left arm: tau = g(q) + kp (q0 - q) - kd dq.

Run it (see README.md): mexone sim --controllers controllers.yaml --pose pose.yaml
"""

from __future__ import annotations

import numpy as np

from mexone.control import Param, PythonController

__all__ = ["GravityCompensationPD"]


class GravityCompensationPD(PythonController):
    """Hold the pose the arm had when started: PD on the joint error plus the arm's own gravity
    torque g(q) from the simulated model, so the PD has no load to sag under. `gravity = 0` is
    plain PD with the same gains (the comparison the README measures)."""

    command_interface = "effort"
    kp = Param(5.0, low=0.0, high=1e4, doc="stiffness, N m/rad")
    kd = Param(0.5, low=0.0, high=1e3, doc="damping, N m s/rad")
    gravity = Param(1.0, low=0.0, high=1.0, doc="share of g(q) fed forward: 1 compensates, 0 is plain PD")

    def configure(self) -> None:
        self.q0 = np.zeros(len(self.joints))
        self.worst = 0.0  # rad: the largest joint error seen since activation

    def activate(self, state) -> None:
        self.q0 = np.array(state.q, dtype=float)
        self.worst = 0.0

    def update(self, state, t: float, dt: float):
        error = self.q0 - state.q
        self.worst = max(self.worst, float(np.abs(error).max()))
        g = self.dynamics.gravity()[self.dofs]  # N m the arm's own weight puts on each joint
        return self.gravity * g + self.kp * error - self.kd * state.dq

    def report(self) -> dict:
        """What `mexone sim --json` prints for this controller."""
        return {"max_error_mrad": round(1e3 * self.worst, 3)}
