"""Exercise 5, reference solution: tau = g(q) + kp (q0 - q) - kd dq, g from the live model."""

from __future__ import annotations

import numpy as np

from mexone.control import Param, PythonController


class GravityCompensation(PythonController):
    command_interface = "effort"
    kp = Param(5.0, low=0.0, high=1e4, doc="stiffness, N m/rad")
    kd = Param(0.5, low=0.0, high=1e3, doc="damping, N m s/rad")

    def activate(self, state) -> None:
        self.q0 = np.array(state.q, dtype=float)

    def update(self, state, t: float, dt: float):
        g = self.dynamics.gravity()[self.dofs]  # N m the arm's weight puts on each joint, now
        return g + self.kp * (self.q0 - state.q) - self.kd * state.dq
