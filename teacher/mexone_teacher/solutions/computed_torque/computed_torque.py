"""Computed-torque tracking of q_ref(t) = q0 + A sin(w t) on Mex-One's left shoulder and elbow.

tau = M(q) (ddq_ref + kp e + kd de) + h(q, dq) - tau_damping(dq), e = q_ref - q: the error
obeys dde + kd de + kp e = 0 whatever the arm's inertia and speed (exercise 6's reference).
"""

from __future__ import annotations

import math

import numpy as np

from mexone.control import Param, PythonController

__all__ = ["ComputedTorque", "reference"]


def reference(t: float, q0: np.ndarray, amplitude: float, frequency: float):
    """The sine every joint tracks, from q0 at t = 0: (q, dq, ddq) at time t (s)."""
    w = 2.0 * math.pi * frequency
    s, c = math.sin(w * t), math.cos(w * t)
    return q0 + amplitude * s, np.full_like(q0, amplitude * w * c), np.full_like(q0, -amplitude * w * w * s)


class ComputedTorque(PythonController):
    """Feedback linearisation: cancel the arm's dynamics with the model's M and h, then place
    the error's poles with kp, kd (both joints: a critically damped 1/sqrt(kp) s response)."""

    command_interface = "effort"
    amplitude = Param(0.5, low=0.0, high=1.0, doc="rad, of the sine about the start pose")
    frequency = Param(0.5, low=0.0, high=5.0, doc="Hz (0.5: w = pi rad/s)")
    kp = Param(2500.0, low=0.0, high=1e5, doc="1/s^2, the error's stiffness")
    kd = Param(100.0, low=0.0, high=1e3, doc="1/s, the error's damping (2 sqrt(kp): critical)")

    def configure(self) -> None:
        self.q0 = np.zeros(len(self.joints))
        self.t0 = 0.0
        self.squares, self.samples = 0.0, 0
        self.nv = len(self.dynamics.dq)

    def activate(self, state) -> None:
        self.q0 = np.array(state.q, dtype=float)
        self.t0 = state.time
        self.squares, self.samples = 0.0, 0

    def update(self, state, t: float, dt: float):
        q_ref, dq_ref, ddq_ref = reference(t - self.t0, self.q0, self.amplitude, self.frequency)
        error = q_ref - state.q
        self.squares += float(error @ error)
        self.samples += len(error)
        ddq = ddq_ref + self.kp * error + self.kd * (dq_ref - state.dq)
        qacc = np.zeros(self.nv)
        qacc[self.dofs] = ddq  # the rest of the robot (torso, legs) taken as still
        # M ddq + h, less the joints' own damping (passive forces): MuJoCo's inverse dynamics
        return self.dynamics.inverse_dynamics(qacc, contacts=True)[self.dofs]

    def report(self) -> dict:
        """What `mexone sim --json` prints for this controller: the RMS tracking error."""
        rms = math.sqrt(self.squares / self.samples) if self.samples else 0.0
        return {"rms_error_mrad": round(1e3 * rms, 4)}
