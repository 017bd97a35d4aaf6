"""Exercise 6: track q_ref(t) = q0 + amplitude sin(2 pi frequency t) on the left shoulder pitch
and elbow. This starter is a PD on the error plus gravity: it lags the sine. Replace it with
computed torque: tau = M(q) (ddq_ref + kp e + kd de) + h(q, dq) (see self.dynamics)."""

from __future__ import annotations

import math

import numpy as np

from mexone.control import Param, PythonController


class ComputedTorque(PythonController):
    command_interface = "effort"
    amplitude = Param(0.5, low=0.0, high=1.0, doc="rad, of the sine about the start pose")
    frequency = Param(0.5, low=0.0, high=5.0, doc="Hz")
    kp = Param(2500.0, low=0.0, high=1e5, doc="1/s^2, the error's stiffness")
    kd = Param(100.0, low=0.0, high=1e3, doc="1/s, the error's damping")

    def activate(self, state) -> None:
        self.q0 = np.array(state.q, dtype=float)
        self.t0 = state.time

    def update(self, state, t: float, dt: float):
        w = 2.0 * math.pi * self.frequency
        q_ref = self.q0 + self.amplitude * math.sin(w * (t - self.t0))
        dq_ref = np.full_like(self.q0, self.amplitude * w * math.cos(w * (t - self.t0)))
        gravity = self.dynamics.gravity()[self.dofs]
        # TODO: computed torque. This weak PD (N m/rad, N m s/rad) lags the sine by far.
        return gravity + 5.0 * (q_ref - state.q) + 0.5 * (dq_ref - state.dq)
