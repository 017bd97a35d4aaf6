"""Exercise 11: my own centre-of-mass planner for Mex-One's walking stack (replaces walking.yaml's
`com_planner`). This starter keeps the COM over the middle of the feet: when a foot lifts, the
COM is not over the standing foot and the robot falls. Make the COM move over each standing
foot in time (the LIPM: c'' = omega^2 (c - zmp), the ZMP inside the standing sole)."""

import numpy as np

from mexone.control import Param, PythonController
from mexone.walking.footsteps import Steps


class MyComPlanner(PythonController):
    """Reads `steps` (and `base`, the estimator's, optional); exports `com` (9: position,
    velocity, acceleration, world) and `landing` (5; NaN: the steps as planned)."""

    inputs = {"steps": Steps.LENGTH, "base": 13}
    optional_inputs = ("base",)
    exports = {"com": 9, "landing": 5}
    height = Param(0.54, low=0.2, high=1.0, doc="COM above the soles", unit="m")

    def update(self, state, t, dt):
        steps = state.inputs["steps"]
        feet = Steps.feet(steps)  # rows: foot 0 (left), 1 (right): x, y, z, yaw
        middle = (feet[0, :3] + feet[1, :3]) / 2  # TODO: over the standing foot, in time
        self.exports["com"][:] = [middle[0], middle[1], middle[2] + self.height, 0.0, 0.0, 0.0,
                                  0.0, 0.0, 0.0]
        self.exports["landing"][:] = np.nan
