"""Exercise 13's reference: leg odometry with the IMU's attitude (the estimator
`mexone controllers new --part estimator` writes). A foot on the ground does not move, so the
base's velocity is v = -(J_foot dq) with the base's linear columns left out (the joints' and the
IMU's angular velocity only), turned into the world by the IMU's attitude; the position is where
the standing foot touched down, less that foot's offset from the base. It reads no base pose
from the simulator: only the legs' kinematics relative to the pelvis, which the encoders give."""

import numpy as np

from mexone.control import Param, PythonController
from mexone.walking.body import FEET, matrix_to_quat, quat_to_matrix


class MyEstimator(PythonController):
    """Exports `base` (13: position, quaternion w x y z, velocity (world), angular velocity
    (base frame)) and `contact` (2)."""

    exports = {"base": 13, "contact": 2}
    contact_force = Param(20.0, low=0.0, high=1e4, doc="normal force that counts as contact", unit="N")

    def activate(self, state):
        self.position = np.array(state.all_q[:3], dtype=float)  # where the robot was put
        self.touched = [None, None]

    def update(self, state, t, dt):
        imu = state.sensors["imu"]  # on the pelvis, its axes the pelvis's
        x, y, z, w = imu.orientation
        rotation = quat_to_matrix(np.array([w, x, y, z]))
        omega = np.array(imu.angular_velocity)
        dyn = self.dynamics  # only the feet relative to the base are used: the encoders'
        base_p, base_r = dyn.pose("pelvis")
        velocities, positions, contact = [], [], np.zeros(2)
        for f, name in enumerate(FEET):
            if state.sensors[name + "_contact"].force[2] < self.contact_force:
                self.touched[f] = None
                continue
            contact[f] = 1.0
            p_foot, _ = dyn.pose(name)  # the foot from the base, turned by the IMU's attitude
            offset = rotation @ base_r.T @ (p_foot - base_p)
            if self.touched[f] is None:
                self.touched[f] = self.position + offset
            positions.append(self.touched[f] - offset)
            dq = np.array(state.all_dq)
            dq[:3], dq[3:6] = 0.0, omega
            velocities.append(-(rotation @ base_r.T @ (dyn.jacobian(name)[:3] @ dq)))
        velocity = np.mean(velocities, axis=0) if velocities else np.zeros(3)
        self.position = np.mean(positions, axis=0) if positions else self.position + velocity * dt
        out = self.exports["base"]
        out[:3], out[3:7], out[7:10], out[10:] = self.position, matrix_to_quat(rotation), velocity, omega
        self.exports["contact"][:] = contact
