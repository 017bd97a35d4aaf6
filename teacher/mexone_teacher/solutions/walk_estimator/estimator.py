"""Exercise 13's reference: a Kalman filter on the base's position and velocity, written from
scratch (numpy only). Leg odometry alone -- what `mexone controllers new --part estimator`
writes -- passes the encoders' noise straight into the velocity (about 0.06 m/s RMS here); the
filter predicts with the IMU's acceleration and corrects with the legs:

- attitude and angular velocity from the IMU (on the pelvis, its axes the pelvis's);
- state x = (p, v) in the world; predict x+ = F x + B a with a = R f + g (f the accelerometer's
  proper acceleration), P+ = F P F' + q^2 B B';
- correct with each standing foot: it does not move, so v = -(J_foot dq) with the base's linear
  columns left out (the joints' and the gyro's velocities only) and p = where the foot touched
  down less its offset from the base; K = P H' (H P H' + R)^-1, Joseph form for P.

It reads no base pose from the simulator: only the legs' kinematics relative to the pelvis."""

import numpy as np

from mexone.control import Param, PythonController
from mexone.walking.body import FEET, matrix_to_quat, quat_to_matrix

GRAVITY = np.array([0.0, 0.0, -9.81])
H_VELOCITY = np.hstack([np.zeros((3, 3)), np.eye(3)])
H_POSITION = np.hstack([np.eye(3), np.zeros((3, 3))])


class MyEstimator(PythonController):
    """Exports `base` (13: position, quaternion w x y z, velocity (world), angular velocity
    (base frame)) and `contact` (2)."""

    exports = {"base": 13, "contact": 2}
    contact_force = Param(20.0, low=0.0, high=1e4, doc="normal force that counts as contact", unit="N")
    accel_noise = Param(2.0, low=1e-6, high=1e3, doc="process noise: the acceleration's", unit="m/s^2")
    velocity_noise = Param(0.05, low=1e-6, high=10.0, doc="leg odometry's velocity noise", unit="m/s")
    position_noise = Param(0.005, low=1e-6, high=1.0, doc="leg kinematics' position noise", unit="m")

    def activate(self, state):
        self.x = np.concatenate([np.array(state.all_q[:3], dtype=float), np.zeros(3)])
        self.P = np.diag([1e-4] * 3 + [1e-2] * 3)
        self.touched = [None, None]

    def predict(self, accel, dt):
        F = np.eye(6)
        F[:3, 3:] = dt * np.eye(3)
        B = np.vstack([0.5 * dt * dt * np.eye(3), dt * np.eye(3)])
        self.x = F @ self.x + B @ accel
        self.P = F @ self.P @ F.T + self.accel_noise**2 * (B @ B.T)

    def correct(self, z, H, r):
        S = H @ self.P @ H.T + np.diag(r)
        K = np.linalg.solve(S, H @ self.P).T  # P H' S^-1 (S and P symmetric)
        self.x = self.x + K @ (z - H @ self.x)
        A = np.eye(6) - K @ H
        self.P = A @ self.P @ A.T + K @ np.diag(r) @ K.T

    def update(self, state, t, dt):
        imu = state.sensors["imu"]
        x, y, z, w = imu.orientation
        rotation = quat_to_matrix(np.array([w, x, y, z]))
        omega = np.array(imu.angular_velocity)
        self.predict(rotation @ np.asarray(imu.linear_acceleration) + GRAVITY, dt)
        dyn = self.dynamics  # only the feet relative to the base are used: the encoders'
        base_p, base_r = dyn.pose("pelvis")
        dq = np.array(state.all_dq)
        dq[:3], dq[3:6] = 0.0, omega
        zs, hs, rs, contact = [], [], [], np.zeros(2)
        for f, name in enumerate(FEET):
            if state.sensors[name + "_contact"].force[2] < self.contact_force:
                self.touched[f] = None
                continue
            contact[f] = 1.0
            p_foot, _ = dyn.pose(name)  # the foot from the base, turned by the IMU's attitude
            offset = rotation @ base_r.T @ (p_foot - base_p)
            if self.touched[f] is None:
                self.touched[f] = self.x[:3] + offset
            zs += [-(rotation @ base_r.T @ (dyn.jacobian(name)[:3] @ dq)), self.touched[f] - offset]
            hs += [H_VELOCITY, H_POSITION]
            rs += [self.velocity_noise**2] * 3 + [self.position_noise**2] * 3
        if zs:
            self.correct(np.concatenate(zs), np.vstack(hs), np.array(rs))
        out = self.exports["base"]
        out[:3], out[3:7], out[7:10], out[10:] = self.x[:3], matrix_to_quat(rotation), self.x[3:], omega
        self.exports["contact"][:] = contact
