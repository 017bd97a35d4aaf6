"""Exercise 14 (reference): the pelvis's tilt from gravity with its IMU alone: a complementary
filter, the gyro integrated and pulled toward the tilt the accelerometer reads (gravity, when
nothing else accelerates it much). On a slope the robot sways on its feet from the start, and
its accelerometer reads the sway many times over: the pull starts as the running mean of what
the accelerometer said since landing (a Kalman filter's gain for a constant) and settles to the
crossover's, and the gyro's bias is learned slowly from the same pull (an integral term, as in
Mahony's filter), not measured in a moment the robot is assumed still (was: 7-17 mrad RMS
under a pitched slope, a bias read while it swayed)."""

from __future__ import annotations

import math

import numpy as np

from mexone.control import Param, PythonController

G = 9.81


class TiltObserver(PythonController):
    exports = {"tilt": 2}
    crossover = Param(0.15, low=0.01, high=20.0, unit="Hz")
    integral = Param(0.05, low=0.0, high=5.0, unit="1/s^2")

    def activate(self, state):
        self.tilt = np.zeros(2)
        self.bias = np.zeros(2)
        self.started = None  # the time gravity alone was first read

    @staticmethod
    def from_gravity(acc):
        ax, ay, az = (float(v) for v in acc)
        return np.array([math.atan2(ay, az), math.atan2(-ax, math.hypot(ay, az))])

    def update(self, state, t, dt):
        imu = state.sensors["imu"]
        acc = imu.linear_acceleration
        rate = np.asarray(imu.angular_velocity[:2], dtype=float)
        if self.started is None:  # falling onto its feet: wait for gravity alone
            if abs(float(np.linalg.norm(acc)) - G) < 0.2:
                self.started, self.tilt = t, self.from_gravity(acc)
            self.exports["tilt"][:] = self.tilt
            return
        gain = max(1.0 / (t - self.started + dt), 2 * math.pi * self.crossover)  # 1/s
        miss = self.from_gravity(acc) - self.tilt
        self.tilt = self.tilt + (rate - self.bias) * dt + gain * dt * miss
        self.bias = self.bias - self.integral * dt * miss
        self.exports["tilt"][:] = self.tilt
