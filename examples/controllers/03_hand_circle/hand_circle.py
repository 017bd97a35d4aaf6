"""Mex-One's right hand drawing a circle by operational-space control: a spring and damper pulling
the hand along the circle, the arm's weight carried by g(q):

    tau = J(q)^T (K (x_r - x) + D (v_r - v)) + g(q)

Run it (see README.md): mexone sim --controllers controllers.yaml --pose pose.yaml
"""

from __future__ import annotations

import math

import numpy as np

from mexone.control import Param, PythonController

__all__ = ["HandCircle", "circle", "HAND", "HAND_POINT"]

HAND = "r_forearm"  # the link that carries the right hand (Mex-One's arm ends at the forearm)
HAND_POINT = np.array([0.0, 0.0, -0.17])  # m: the hand, the forearm's far end, in its frame
RAMP = 0.2  # s: the time constant of the circle's speed-up from rest


def circle(t: float, start: np.ndarray, radius: float, frequency: float):
    """The point the hand should be at, and its velocity, t s after the start: a vertical circle
    in the world's y-z plane through `start`; the angle around it speeds up from rest over the
    first `RAMP` s (a step to full speed would jerk the arm), then turns at `frequency`."""
    w = 2.0 * math.pi * frequency
    fade = math.exp(-t / RAMP)
    angle, rate = w * (t - RAMP * (1.0 - fade)), w * (1.0 - fade)
    offset = np.array([0.0, radius * math.sin(angle), radius * (1.0 - math.cos(angle))])
    velocity = radius * rate * np.array([0.0, math.cos(angle), math.sin(angle)])
    return start + offset, velocity


class HandCircle(PythonController):
    """The hand follows a vertical circle of `radius` in the robot's side plane (world y-z), one
    turn every 1/`frequency` s, starting where it is: a Cartesian spring-damper to the moving
    point and its velocity, turned into joint torques by the Jacobian's transpose."""

    command_interface = "effort"
    radius = Param(0.04, low=0.0, high=0.2, doc="m, of the circle")
    frequency = Param(0.5, low=0.0, high=3.0, doc="turns per second")
    stiffness = Param(400.0, low=0.0, high=5e3, doc="K, N/m, along every axis")
    damping = Param(30.0, low=0.0, high=500.0, doc="D, N s/m")

    def configure(self) -> None:
        self.start = np.zeros(3)
        self.began = 0.0
        self.squares, self.samples = 0.0, 0

    def hand(self) -> tuple[np.ndarray, np.ndarray]:
        """The hand's world position and its 3 x n position Jacobian (the claimed joints)."""
        position, rotation = self.dynamics.pose(HAND)
        point = position + rotation @ HAND_POINT
        return point, self.dynamics.jacobian(HAND, point)[:3, self.dofs]

    def activate(self, state) -> None:
        self.start, _ = self.hand()
        self.began = state.time
        self.squares, self.samples = 0.0, 0

    def update(self, state, t: float, dt: float):
        x, jacobian = self.hand()
        x_r, v_r = circle(t - self.began, self.start, self.radius, self.frequency)
        miss = x_r - x
        self.squares += float(miss @ miss)
        self.samples += 1
        pull = self.stiffness * miss + self.damping * (v_r - jacobian @ state.dq)  # N at the hand
        return jacobian.T @ pull + self.dynamics.gravity()[self.dofs]

    def report(self) -> dict:
        """What `mexone sim --json` prints: the hand's RMS distance from the circle (mm)."""
        rms = math.sqrt(self.squares / self.samples) if self.samples else 0.0
        return {"rms_error_mm": round(1e3 * rms, 3)}
