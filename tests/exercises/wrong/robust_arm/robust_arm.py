"""A wrong solution of exercise 15: margins to spare, but too soft to hold the arm against a
push (kp 5 N m/rad)."""

from __future__ import annotations

import numpy as np

from mexone.control import Param, PythonController


class RobustArm(PythonController):
    command_interface = "effort"
    kp = Param(5.0, low=0.0, high=1e4, doc="stiffness, N m/rad")
    kd = Param(0.3, low=0.0, high=1e3, doc="damping, N m s/rad")

    def activate(self, state) -> None:
        self.q0 = np.array(state.q, dtype=float)

    def update(self, state, t: float, dt: float):
        gravity = self.dynamics.gravity()[self.dofs]
        return gravity + self.kp * (self.q0 - state.q) - self.kd * state.dq
