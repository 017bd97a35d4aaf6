"""JointPositionController (effort_controllers, position_controllers, and the JointGroup variants).

torque = PID(setpoint - q, -qdot), control_toolbox's PID with D on the measured velocity, as
ros_controllers' JointPositionController computes it. The whole PID runs in MuJoCo (see
hardware.py), so this class only moves setpoints and gains: nothing runs per step. An ideal servo
(`ideal_servo: true`) teleports the joint every control period, as Gazebo 7's position interface
did, and only when asked.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from mexone.bus.msgs import JointControllerState
from mexone.control.controllers.base import ControllerContext, ControllerInterface, register
from mexone.control.hardware import TELEPORT_NONE, TELEPORT_POSITION
from mexone.control.spec import ControllerSpec, PidGains
from mexone.errors import InputError

__all__ = ["PositionController"]


@register("effort_controllers/JointPositionController", "EffortJointInterface")
@register("position_controllers/JointPositionController", "PositionJointInterface")
@register("effort_controllers/JointGroupPositionController", "EffortJointInterface", False)
@register("position_controllers/JointGroupPositionController", "PositionJointInterface", False)
class PositionController(ControllerInterface):
    kind = "position"
    unit = "rad"
    holds_position = True
    tracks_position = True

    def __init__(self, spec: ControllerSpec, ctx: ControllerContext) -> None:
        super().__init__(spec, ctx)
        self.ideal = spec.ideal_servo
        gains = [self.pid_for(j) for j in self.joints]
        if None in gains and not self.ideal:
            raise InputError(f"controller '{spec.name}' has no PID gains", file=spec.source,
                             line=spec.line, hint="add pid: {p: ..., d: ...}, or ideal_servo: true "
                                                  "to teleport the joint as Gazebo 7 did")
        self._gains: list[PidGains] | None = None if self.ideal else [g for g in gains if g is not None]

    @property
    def setpoint(self) -> np.ndarray:
        return self.hw.command.position[self.rows].copy()

    @property
    def gains(self) -> list[PidGains] | None:
        return None if self._gains is None else list(self._gains)

    @property
    def periodic(self) -> bool:
        return self.ideal

    @property
    def has_state(self) -> bool:
        return self.type.single_joint and self.holds_position

    def state_message(self, dt: float) -> JointControllerState:
        row = self.rows[0]
        return self._state(self.hw.command.position[row], self.hw.position(row),
                           self.hw.velocity(row), dt)

    def command_range(self, index: int) -> tuple[float, float]:
        lo, hi = self.hw.lower[self.rows[index]], self.hw.upper[self.rows[index]]
        return (lo, hi) if np.isfinite(lo) and np.isfinite(hi) and hi > lo else (-math.pi, math.pi)

    def set_gains(self, gains: Sequence[PidGains]) -> None:
        """Retune live: the setpoint and the accumulated integral stay."""
        if self._gains is None:
            raise InputError(f"{self.name} is an ideal servo: it has no gains")
        if len(gains) != len(self.rows):
            raise InputError(f"{self.name} takes gains for {len(self.rows)} joints, not {len(gains)}")
        self._gains = list(gains)
        if self.running:
            self._write_gains()

    def _write_gains(self) -> None:
        c, rows, gains = self.hw.command, self.rows, self._gains
        if gains is None:  # an ideal servo: teleported, no gains
            return
        c.kp[rows] = [g.p for g in gains]
        c.kd[rows] = [g.d for g in gains]
        c.ki[rows] = [g.i for g in gains]
        c.i_min[rows] = [g.i_clamp_min for g in gains]
        c.i_max[rows] = [g.i_clamp_max for g in gains]
        c.antiwindup[rows] = [g.antiwindup for g in gains]
        self.hw.gains_changed(rows)

    def starting(self, t: float) -> None:
        """ros_controllers' starting(): hold the current position; the I term starts at zero."""
        super().starting(t)
        hw, rows = self.hw, self.rows
        hw.release(rows)
        hw.command.position[rows] = hw.state.position[rows]
        if self.ideal:
            hw.command.teleport[rows] = TELEPORT_POSITION
        else:
            hw.command.teleport[rows] = TELEPORT_NONE
            self._write_gains()

    def apply(self, values: Any, t: float) -> None:  # np.ndarray here; a trajectory in a subclass
        rows = self.rows
        self.follow(self.clamp(values, self.hw.lower[rows], self.hw.upper[rows], "joint limits"),
                    np.zeros(len(rows)))

    def follow(self, position: np.ndarray, velocity: np.ndarray) -> None:
        """Track a (possibly moving) reference; positions within the joint limits."""
        hw, rows = self.hw, self.rows
        hw.command.position[rows] = np.clip(position, hw.lower[rows], hw.upper[rows])
        hw.command.velocity[rows] = velocity
