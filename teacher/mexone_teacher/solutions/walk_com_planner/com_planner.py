"""Exercise 11's reference: a centre-of-mass planner on the divergent component of motion
(Englsberger et al. 2015): the plan of `mexone controllers new --part com_planner` with the
DCM's feedback that skeleton leaves out (gain 14/s: the grader's heavier robots and pushes).

xi = c + dc/omega must end each step on the next foothold, so its reference runs backwards
from the last planned step: xi_ref(t) = p + exp(omega (t - t_land)) (xi_end - p) about the
standing foot p. The ZMP command p + (1 + k/omega)(xi - xi_ref), kept inside the standing sole
(both soles' box in double support), gives the COM's acceleration omega^2 (c - zmp)."""

import math

import numpy as np

from mexone.control import Param, PythonController
from mexone.walking.footsteps import Steps


class MyComPlanner(PythonController):
    """Reads `steps` (and `base`, optional); exports `com` (9) and `landing` (5, NaN: the
    steps as planned)."""

    inputs = {"steps": Steps.LENGTH, "base": 13}
    optional_inputs = ("base",)
    exports = {"com": 9, "landing": 5}
    gain = Param(14.0, low=0.0, high=50.0, doc="DCM feedback gain k", unit="1/s")
    height = Param(0.54, low=0.2, high=1.0, doc="COM above the soles", unit="m")
    half_length = Param(0.06, low=0.0, high=0.1, doc="ZMP limit along the sole", unit="m")
    half_width = Param(0.025, low=0.0, high=0.05, doc="ZMP limit across the sole", unit="m")

    def update(self, state, t, dt):
        steps = state.inputs["steps"]
        self.exports["landing"][:] = np.nan
        dyn = self.dynamics
        c, v = dyn.com(), dyn.com_jacobian() @ state.all_dq
        omega = math.sqrt(9.81 / self.height)
        xi = c[:2] + v[:2] / omega
        feet, ahead = Steps.feet(steps), [row for row in Steps.rows(steps) if row[8] > t]
        if not ahead:  # standing: the DCM over the feet's middle
            p_ref = xi_ref = (feet[0, :2] + feet[1, :2]) / 2
        else:  # backwards from the last step: xi at each landing, about the foot standing then
            stands = [feet[1 - int(ahead[0][0]), :2]] + [row[1:3] for row in ahead]
            xi_end = (stands[-1] + stands[-2]) / 2
            for i in range(len(ahead) - 1, 0, -1):
                span = ahead[i][8] - ahead[i - 1][8]
                xi_end = stands[i] + math.exp(-omega * span) * (xi_end - stands[i])
            p_ref = stands[0]
            xi_ref = p_ref + math.exp(omega * (t - ahead[0][8])) * (xi_end - p_ref)
        zmp = p_ref + (1.0 + self.gain / omega) * (xi - xi_ref)
        swing = Steps.swing_now(steps, t)  # the ZMP stays on the soles on the ground
        down = [f for f in range(2) if swing is None or int(swing[0]) != f]
        size = np.array([self.half_length, self.half_width])
        low = np.min([feet[f, :2] for f in down], axis=0) - size
        high = np.max([feet[f, :2] for f in down], axis=0) + size
        acc = omega**2 * (c[:2] - np.clip(zmp, low, high))
        ground = (feet[0, 2] + feet[1, 2]) / 2
        self.exports["com"][:] = [c[0], c[1], ground + self.height, v[0], v[1], 0.0,
                                  acc[0], acc[1], 0.0]
