"""Exercise 15 (reference): hold the raised arm with gravity compensation and a PD whose gains
keep a disk margin and a delay margin: stiff enough to return after a push, soft enough (kd
small against the arm's inertia at 500 Hz) that a late or stronger command does not ring."""

from __future__ import annotations

import numpy as np

from mexone.control import Param, PythonController


class RobustArm(PythonController):
    command_interface = "effort"
    kp = Param(40.0, low=0.0, high=1e4, doc="stiffness, N m/rad")
    kd = Param(0.5, low=0.0, high=1e3, doc="damping, N m s/rad")

    def activate(self, state) -> None:
        self.q0 = np.array(state.q, dtype=float)

    def update(self, state, t: float, dt: float):
        gravity = self.dynamics.gravity()[self.dofs]
        return gravity + self.kp * (self.q0 - state.q) - self.kd * state.dq
