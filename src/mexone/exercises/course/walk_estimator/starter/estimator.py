"""Exercise 13: my own estimator of Mex-One's floating base (replaces walking.yaml's `estimator`).
This starter exports where the robot started, at rest, with the IMU's attitude: the walking
stack believes the robot stands still and it falls. Estimate the base's position and velocity
from the legs (a foot on the ground does not move) and the IMU."""

import numpy as np

from mexone.control import Param, PythonController
from mexone.walking.body import FEET


class MyEstimator(PythonController):
    """Exports `base` (13: position, quaternion w x y z, velocity (world), angular velocity
    (base frame)) and `contact` (2)."""

    exports = {"base": 13, "contact": 2}
    contact_force = Param(20.0, low=0.0, high=1e4, doc="normal force that counts as contact", unit="N")

    def activate(self, state):
        self.position = np.array(state.all_q[:3], dtype=float)  # where the robot was put

    def update(self, state, t, dt):
        imu = state.sensors["imu"]
        x, y, z, w = imu.orientation
        velocity = np.zeros(3)  # TODO: from the standing feet (leg odometry) and the IMU
        out = self.exports["base"]
        out[:3], out[3:7], out[7:10], out[10:] = self.position, (w, x, y, z), velocity, \
            imu.angular_velocity
        self.exports["contact"][:] = [state.sensors[f + "_contact"].force[2] > self.contact_force
                                      for f in FEET]
