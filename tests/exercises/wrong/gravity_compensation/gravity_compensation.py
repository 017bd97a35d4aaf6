"""Exercise 5, deliberately wrong: gravity torques written down once, for the given arm in the
given pose (measured once with g(q)) -- the hidden payload and pose are not compensated."""

from __future__ import annotations

import numpy as np

from mexone.control import Param, PythonController


class GravityCompensation(PythonController):
    command_interface = "effort"
    kp = Param(5.0, low=0.0, high=1e4, doc="stiffness, N m/rad")
    kd = Param(0.5, low=0.0, high=1e3, doc="damping, N m s/rad")

    def activate(self, state) -> None:
        self.q0 = np.array(state.q, dtype=float)
        # the given arm's torques at the given pose (l_shoulder_pitch -1.2, l_elbow -0.6), nominal
        self.g = np.array([-1.4191, 0.0, -0.363])  # N m: g(q) of the given arm, measured once

    def update(self, state, t: float, dt: float):
        return self.g + self.kp * (self.q0 - state.q) - self.kd * state.dq
