"""Exercise 8, wrong solution: keep the standing robot up under pushes at the torso, with both ankle pitches.
Deliberately wrong: soft ankles (kp 100) "to absorb the push" -- they let the robot tip.
Feed back the centre of mass (self.dynamics.com(), com_jacobian()) and its velocity instead:
the linear inverted pendulum, an LQR on it, or a capture-point law."""

from __future__ import annotations

import numpy as np

from mexone.control import Param, PythonController


class Balance(PythonController):
    command_interface = "effort"
    kp = Param(100.0, low=0.0, high=1e4, doc="N m/rad")
    kd = Param(3.0, low=0.0, high=1e3, doc="N m s/rad")

    def activate(self, state) -> None:
        self.q0 = np.array(state.q, dtype=float)

    def update(self, state, t: float, dt: float):
        return self.kp * (self.q0 - state.q) - self.kd * state.dq
