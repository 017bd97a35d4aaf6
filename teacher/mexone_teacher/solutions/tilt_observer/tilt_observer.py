"""Exercise 14 (reference): the pelvis's tilt from gravity with its IMU alone: the gyro's bias
measured while the robot stands still, then a complementary filter, the gyro integrated and
pulled slowly toward the tilt the accelerometer reads (gravity, when nothing else accelerates
it much)."""

from __future__ import annotations

import math

import numpy as np

from mexone.control import Param, PythonController

G = 9.81


class TiltObserver(PythonController):
    exports = {"tilt": 2}
    crossover = Param(0.15, low=0.01, high=20.0, unit="Hz")
    calibrate = Param(0.8, low=0.0, high=5.0, unit="s")

    def activate(self, state):
        self.tilt = np.zeros(2)
        self.bias = np.zeros(2)
        self.samples = 0
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
        if t - self.started < self.calibrate:  # standing still: the gyro reads its bias
            self.samples += 1
            self.bias += (rate - self.bias) / self.samples
            self.tilt += 0.05 * (self.from_gravity(acc) - self.tilt)
        else:
            k = 2 * math.pi * self.crossover
            self.tilt = self.tilt + (rate - self.bias) * dt
            self.tilt = self.tilt + k * dt * (self.from_gravity(acc) - self.tilt)
        self.exports["tilt"][:] = self.tilt
