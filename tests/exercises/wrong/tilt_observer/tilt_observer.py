"""A wrong solution of exercise 14: the tilt read from the simulator's base orientation (the
world's z, not gravity), not from the IMU."""

import math

from mexone.control import PythonController


class TiltObserver(PythonController):
    exports = {"tilt": 2}

    def update(self, state, t, dt):
        w, x, y, z = (float(v) for v in state.base.quaternion)
        roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
        pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
        self.exports["tilt"][:] = [roll, pitch]
