"""Computed torque on Mex-One's right shoulder pitch and elbow: a minimum-jerk move from the start
pose by `move_shoulder`, `move_elbow` rad in `duration` s, then a hold.

tau = M(q) (ddq_r + kp e + kd de) + h(q, dq) - tau_passive(dq), e = q_r - q: MuJoCo's inverse
dynamics of the acceleration the error's dynamics asks for (README.md derives it).
"""

from __future__ import annotations

import numpy as np

from mexone.control import Param, PythonController

__all__ = ["ComputedTorqueMove", "minimum_jerk"]


def minimum_jerk(t: float, duration: float) -> tuple[float, float, float]:
    """The share of the move done at time t (s): s(t) = 10 u^3 - 15 u^4 + 6 u^5, u = t/duration,
    and its first two derivatives (1/s, 1/s^2); 0 before, 1 after."""
    u = min(max(t / duration, 0.0), 1.0)
    share = u**3 * (10 - 15 * u + 6 * u**2)
    rate = 30 * u**2 * (1 - u) ** 2 / duration
    accel = 60 * u * (1 - u) * (1 - 2 * u) / duration**2
    return share, rate, accel


class ComputedTorqueMove(PythonController):
    """Feedback linearisation: the model's inverse dynamics cancels the arm's inertia, Coriolis,
    gravity and damping, leaving dde + kd de + kp e = 0 (poles placed by kp, kd) whatever the
    arm carries or how fast it moves."""

    command_interface = "effort"
    move_shoulder = Param(-0.8, low=-3.0, high=3.0, doc="rad the shoulder pitch moves by")
    move_elbow = Param(-0.9, low=-3.0, high=3.0, doc="rad the elbow moves by")
    duration = Param(1.0, low=0.05, high=60.0, doc="s the move takes")
    kp = Param(2500.0, low=0.0, high=1e5, doc="1/s^2, the error's stiffness")
    kd = Param(100.0, low=0.0, high=1e3, doc="1/s, the error's damping (2 sqrt(kp): critical)")

    def configure(self) -> None:
        self.start = np.zeros(len(self.joints))
        self.began = 0.0
        self.worst = 0.0  # rad: the largest tracking error since activation
        self.qacc = np.zeros(len(self.dynamics.dq))

    def activate(self, state) -> None:
        self.start = np.array(state.q, dtype=float)
        self.began = state.time
        self.worst = 0.0

    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q_r, dq_r, ddq_r) at time t since the move began."""
        move = np.array([self.move_shoulder, self.move_elbow])
        share, rate, accel = minimum_jerk(t, self.duration)
        return self.start + share * move, rate * move, accel * move

    def update(self, state, t: float, dt: float):
        q_r, dq_r, ddq_r = self.reference(t - self.began)
        error = q_r - state.q
        self.worst = max(self.worst, float(np.abs(error).max()))
        self.qacc[self.dofs] = ddq_r + self.kp * error + self.kd * (dq_r - state.dq)
        return self.dynamics.inverse_dynamics(self.qacc, contacts=True)[self.dofs]

    def report(self) -> dict:
        """What `mexone sim --json` prints for this controller: the largest tracking error."""
        return {"max_error_mrad": round(1e3 * self.worst, 4)}
