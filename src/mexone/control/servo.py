"""ServoBank: the PID position servos of every actuated joint, in one set of arrays.

Position controllers (single, group, trajectory) write their joints' setpoints here; the P and D
terms run inside MuJoCo's actuators (see hardware.py), and the integral terms, when any joint
has one, advance for all joints in one vectorised update per control period.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from mexone.control.config import PidGains
from mexone.control.hardware import SimHardware
from mexone.control.pid import PidArray

__all__ = ["ServoBank"]


class ServoBank:
    def __init__(self, hw: SimHardware):
        n = len(hw.joints)
        self.hw = hw
        self.pid = PidArray([PidGains(p=0.0)] * n)
        self.setpoint = np.zeros(n)
        self.velocity = np.zeros(n)
        self.i_term = np.zeros(n)
        self.integrating = np.zeros(n, dtype=bool)

    def configure(self, rows: np.ndarray, gains: Sequence[PidGains]) -> None:
        """Take over `rows` as PID servos holding their current position (ros_controllers'
        starting()); the I term restarts from zero."""
        staged = PidArray(gains)
        for name in ("p", "i", "d", "i_min", "i_max", "antiwindup"):
            getattr(self.pid, name)[rows] = getattr(staged, name)
        self.pid.i_error[rows] = 0.0
        self.pid.last_error[rows] = 0.0
        self.i_term[rows] = 0.0
        self.integrating[rows] = (staged.i != 0) & ((staged.i_min != 0) | (staged.i_max != 0))
        self.setpoint[rows] = self.hw.position(rows)
        self.velocity[rows] = 0.0
        self.hw.set_feedback(rows, -self.pid.p[rows], -self.pid.d[rows])
        self.write(rows)

    def set_gains(self, rows: np.ndarray, gains: Sequence[PidGains]) -> None:
        """Retune live: the setpoint and the accumulated integral stay."""
        staged = PidArray(gains)
        for name in ("p", "i", "d", "i_min", "i_max", "antiwindup"):
            getattr(self.pid, name)[rows] = getattr(staged, name)
        self.integrating[rows] = (staged.i != 0) & ((staged.i_min != 0) | (staged.i_max != 0))
        self.hw.set_feedback(rows, -self.pid.p[rows], -self.pid.d[rows])
        self.write(rows)

    def release(self, rows: np.ndarray) -> None:
        self.integrating[rows] = False
        self.hw.release(rows)

    def write(self, rows: np.ndarray) -> None:
        pid = self.pid
        self.hw.set_u(rows, pid.p[rows] * self.setpoint[rows] + pid.d[rows] * self.velocity[rows]
                      + self.i_term[rows])

    def integrate(self, dt: float) -> None:
        rows = np.flatnonzero(self.integrating)
        if rows.size == 0:
            return
        error = self.setpoint[rows] - self.hw.position(rows)
        self.i_term[rows] = self.pid.integral(error, dt, rows)
        self.write(rows)
