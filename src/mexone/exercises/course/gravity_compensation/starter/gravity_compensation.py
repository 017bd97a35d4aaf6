"""Exercise 5: hold the raised left arm with a weak PD plus gravity compensation.

tau = g(q) + kp (q0 - q) - kd dq. The PD alone (below) sags: add the arm's gravity torque.
"""

from __future__ import annotations

import numpy as np

from mexone.control import Param, PythonController


class GravityCompensation(PythonController):
    command_interface = "effort"
    kp = Param(5.0, low=0.0, high=1e4, doc="stiffness, N m/rad")
    kd = Param(0.5, low=0.0, high=1e3, doc="damping, N m s/rad")

    def activate(self, state) -> None:
        self.q0 = np.array(state.q, dtype=float)  # hold the pose the arm starts in

    def update(self, state, t: float, dt: float):
        # TODO: add the torque gravity puts on each claimed joint (see self.dynamics)
        return self.kp * (self.q0 - state.q) - self.kd * state.dq
