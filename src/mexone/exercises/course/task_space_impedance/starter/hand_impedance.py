"""Exercise 7: make the left hand a spring K and damper D to where it started (world frame):
tau = J(q)^T (K (x0 - x) - D v) + g(q). This starter only cancels gravity: a push carries the
hand away. Use self.dynamics.pose(HAND) and self.dynamics.jacobian(HAND, point)."""

from __future__ import annotations

import numpy as np

from mexone.control import Param, PythonController

HAND = "l_forearm"  # the link that carries the hand
HAND_POINT = np.array([0.0, 0.0, -0.17])  # m: the hand, the forearm's far end, in its frame


class HandImpedance(PythonController):
    command_interface = "effort"
    stiffness = Param(200.0, low=0.0, high=5e3, doc="K, N/m, the same along x, y and z")
    damping = Param(20.0, low=0.0, high=500.0, doc="D, N s/m")

    def update(self, state, t: float, dt: float):
        # TODO: the Cartesian spring-damper at the hand, through the Jacobian's transpose
        return self.dynamics.gravity()[self.dofs] - 0.5 * state.dq
