"""Task-space impedance of Mex-One's left hand: the hand behaves as a spring K and damper D to
where it started, tau = J(q)^T (K (x0 - x) - D v) + g(q). Exercise 7's reference."""

from __future__ import annotations

import numpy as np

from mexone.control import Param, PythonController

__all__ = ["HandImpedance", "HAND", "HAND_POINT"]

HAND = "l_forearm"  # the link that carries the hand (Mex-One's arm ends at the forearm)
HAND_POINT = np.array([0.0, 0.0, -0.17])  # m: the hand, the forearm's far end, in its frame


class HandImpedance(PythonController):
    """A Cartesian spring-damper at the hand, in the world frame: a force F on the hand moves it
    F / K once it settles (the arm's weight is compensated, so the spring carries only F)."""

    command_interface = "effort"
    stiffness = Param(200.0, low=0.0, high=5e3, doc="K, N/m, the same along x, y and z")
    damping = Param(20.0, low=0.0, high=500.0, doc="D, N s/m")

    def configure(self) -> None:
        self.x0 = np.zeros(3)
        self.x = np.zeros(3)

    def hand(self) -> tuple[np.ndarray, np.ndarray]:
        """The hand's world position and its 3 x n position Jacobian (the claimed joints' columns)."""
        position, rotation = self.dynamics.pose(HAND)
        point = position + rotation @ HAND_POINT
        jacobian = self.dynamics.jacobian(HAND, point)[:3, self.dofs]
        return point, jacobian

    def activate(self, state) -> None:
        self.x0, _ = self.hand()
        self.x = self.x0.copy()

    def update(self, state, t: float, dt: float):
        self.x, jacobian = self.hand()
        velocity = jacobian @ state.dq
        force = self.stiffness * (self.x0 - self.x) - self.damping * velocity  # N on the hand
        return jacobian.T @ force + self.dynamics.gravity()[self.dofs]

    def report(self) -> dict:
        """What `mexone sim --json` prints: how far the hand is from where it started (mm)."""
        return {"displacement_mm": [round(1e3 * v, 3) for v in self.x - self.x0]}
