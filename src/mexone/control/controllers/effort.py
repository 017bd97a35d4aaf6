"""JointEffortController and JointGroupEffortController: the command is the joint torque."""

from __future__ import annotations

import numpy as np

from mexone.control.controllers.base import ControllerInterface, register

__all__ = ["EffortController"]


@register("effort_controllers/JointEffortController", "EffortJointInterface")
@register("effort_controllers/JointGroupEffortController", "EffortJointInterface", False)
class EffortController(ControllerInterface):
    kind = "effort"
    unit = "N m"

    @property
    def setpoint(self) -> np.ndarray:
        return self.hw.command.effort[self.rows].copy()

    def command_range(self, index: int) -> tuple[float, float]:
        limit = self.hw.effort_limit[self.rows[index]]
        return (-limit, limit) if np.isfinite(limit) else (-10.0, 10.0)

    def starting(self, t: float) -> None:
        super().starting(t)
        self.hw.release(self.rows)

    def apply(self, values: np.ndarray, t: float) -> None:
        limit = self.hw.effort_limit[self.rows]
        self.hw.command.effort[self.rows] = self.clamp(values, -limit, limit, "URDF effort limit")
