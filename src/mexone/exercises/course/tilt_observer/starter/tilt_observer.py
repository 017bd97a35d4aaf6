"""Exercise 14: the pelvis's tilt from gravity, from the IMU, exported as `tilt` (roll, pitch).

Below: the tilt the accelerometer reads, as it is. It is noisy, and while the robot is pushed
the accelerometer reads the push too. Fuse it with the gyro (docs/robust-control.md).
"""

from __future__ import annotations

import math

from mexone.control import PythonController


class TiltObserver(PythonController):
    exports = {"tilt": 2}  # roll, pitch (rad): the pelvis's tilt from the vertical

    def update(self, state, t: float, dt: float):
        ax, ay, az = (float(v) for v in state.sensors["imu"].linear_acceleration)
        # TODO: fuse with state.sensors["imu"].angular_velocity (rad/s, the IMU's frame)
        self.exports["tilt"][:] = [math.atan2(ay, az), math.atan2(-ax, math.hypot(ay, az))]
