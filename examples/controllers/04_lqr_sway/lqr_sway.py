"""Sideways sway of standing Mex-One damped by LQR on the linearised robot: the legs' sideways
tilt (both ankle rolls, the hips' roll PD in the plant) as a linear model, K from python-control's
`lqr`, deployed at every step on both ankle rolls. See README.md for the model and the gain."""

from __future__ import annotations

import control
import numpy as np

from mexone.control import Param, PythonController

__all__ = ["LqrSway", "sway_model"]

G = 9.81


def sway_model(mass: float, height: float, stiffness: float) -> tuple[np.ndarray, np.ndarray]:
    """The sideways sway in double support, linearised upright: both legs tilt by phi about the
    ankles' roll axes (a parallelogram: feet flat, pelvis level), the centre of mass `height`
    above them moves sideways by height * phi; gravity tips it further, the hips' roll PD
    (`stiffness`, N m/rad, both hips) holds it back; Q the ankle rolls' torque on the legs.
    x = (phi, dphi):  m h^2 dd(phi) = (m g h - k) phi + Q."""
    inertia = mass * height**2
    a = np.array([[0.0, 1.0], [(mass * G * height - stiffness) / inertia, 0.0]])
    b = np.array([[0.0], [1.0 / inertia]])
    return a, b


class LqrSway(PythonController):
    """Q = -K x on the ankle rolls, K from the LQR of `sway_model`; x measured by each ankle's
    encoder (the leg's tilt over its foot is minus the ankle roll's angle from where it stood),
    so each ankle gives its half, -K (q - q0, dq) / 2: a PD whose two gains the LQR chose."""

    command_interface = "effort"
    q_tilt = Param(100.0, low=0.0, high=1e6, doc="LQR weight on phi, 1/rad^2")
    q_rate = Param(1.0, low=0.0, high=1e6, doc="LQR weight on dphi, s^2/rad^2")
    r_torque = Param(1e-4, low=1e-9, high=1e3, doc="LQR weight on Q, 1/(N m)^2")
    hip_stiffness = Param(600.0, low=0.0, high=1e4, doc="N m/rad: both hips' roll PD, p 300 each")

    def configure(self) -> None:
        self.gain = np.zeros(2)
        self.q0 = np.zeros(len(self.joints))
        self.y0 = 0.0
        self.height = 0.5  # m: the centre of mass above the ankles' axes, measured at activation
        self.worst = 0.0  # m: the largest sideways excursion of the centre of mass

    def activate(self, state) -> None:
        dyn = self.dynamics
        mass = dyn.mass()
        feet = 0.5 * (dyn.pose("l_ankle")[0] + dyn.pose("r_ankle")[0])
        self.height = float(dyn.com()[2] - feet[2])
        a, b = sway_model(mass, self.height, self.hip_stiffness)
        gain, _, poles = control.lqr(a, b, np.diag([self.q_tilt, self.q_rate]),
                                     np.array([[self.r_torque]]))
        self.gain = np.asarray(gain).ravel()
        self.q0 = np.array(state.q, dtype=float)
        self.y0 = float(dyn.com()[1])
        self.log.info("LQR gain K = (%.0f N m/rad, %.1f N m s/rad), closed-loop poles %s",
                      self.gain[0], self.gain[1], np.round(poles, 2))

    def update(self, state, t: float, dt: float):
        self.worst = max(self.worst, abs(float(self.dynamics.com()[1]) - self.y0))
        tilt, rate = -(state.q - self.q0), -state.dq  # each leg's phi and dphi over its foot
        # Q = -K x on the legs is the ankles' reaction: the ankle rolls' torque is +K x
        return (self.gain[0] * tilt + self.gain[1] * rate) / len(self.joints)

    def report(self) -> dict:
        """What `mexone sim --json` prints: the gain and how far the centre of mass swayed (mm)."""
        return {"gain": [round(float(k), 2) for k in self.gain],
                "max_sway_mm": round(1e3 * self.worst, 2)}
