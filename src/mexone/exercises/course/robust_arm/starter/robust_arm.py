"""Exercise 15: hold the raised left arm with gravity compensation and a PD, at 500 Hz, with
margins: the grader adds a delay to your commands and scales them (a slower, a weaker or
stronger amplifier), and pushes the hand.

These gains are stiff: the arm holds its pose hard, but at 500 Hz against the forearm's small
inertia the derivative gain rings. Find gains that keep a delay margin and a disk margin
(`mexone certify` predicts them; docs/robust-control.md).
"""

from __future__ import annotations

import numpy as np

from mexone.control import Param, PythonController


class RobustArm(PythonController):
    command_interface = "effort"
    kp = Param(150.0, low=0.0, high=1e4, doc="stiffness, N m/rad")
    kd = Param(3.0, low=0.0, high=1e3, doc="damping, N m s/rad")

    def activate(self, state) -> None:
        self.q0 = np.array(state.q, dtype=float)  # hold the pose the arm starts in

    def update(self, state, t: float, dt: float):
        gravity = self.dynamics.gravity()[self.dofs]
        return gravity + self.kp * (self.q0 - state.q) - self.kd * state.dq
