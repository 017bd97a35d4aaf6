"""JointVelocityController (effort_controllers and velocity_controllers, and the JointGroup variant).

effort_controllers: torque = PID(v_cmd - qdot) as control_toolbox computes it, D on the error's
finite difference. With P alone (the usual case) the law runs in MuJoCo's servo (kd = p on the
velocity error, integrated implicitly); with I or D terms it runs here every control period with
control_toolbox's recurrence (PidArray.command), because those terms act on the velocity error's
integral and rate, which no MuJoCo actuator state holds. velocity_controllers without gains: an
ideal velocity servo (Gazebo's SetVelocity), every control period.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from mexone.bus.msgs import JointControllerState
from mexone.control.controllers.base import ControllerContext, ControllerInterface, register
from mexone.control.hardware import TELEPORT_VELOCITY
from mexone.control.pid import PidArray
from mexone.control.spec import ControllerSpec, PidGains
from mexone.errors import InputError

__all__ = ["VelocityController"]


@register("effort_controllers/JointVelocityController", "EffortJointInterface")
@register("velocity_controllers/JointVelocityController", "VelocityJointInterface")
@register("velocity_controllers/JointGroupVelocityController", "VelocityJointInterface", False)
class VelocityController(ControllerInterface):
    kind = "velocity"
    unit = "rad/s"

    def __init__(self, spec: ControllerSpec, ctx: ControllerContext) -> None:
        super().__init__(spec, ctx)
        found = [self.pid_for(j) for j in self.joints]
        gains: list[PidGains] | None = [g for g in found if g is not None]
        if None in found:
            if self.interface == "EffortJointInterface":
                raise InputError(f"controller '{spec.name}' has no PID gains", file=spec.source,
                                 line=spec.line, hint="add pid: {p: ..., d: ...}")
            gains = None
        self.pid = PidArray(gains) if gains else None
        self._gains = gains
        self.target = np.zeros(len(self.rows))
        self._last_t: float | None = None  # of the last PID computation (its dt)

    @property
    def setpoint(self) -> np.ndarray:
        return self.target.copy()

    @property
    def gains(self) -> list[PidGains] | None:
        return None if self._gains is None else list(self._gains)

    @property
    def native(self) -> bool:
        """P alone: MuJoCo's servo runs the whole law."""
        return self.pid is not None and not self.pid.integrates and not np.any(self.pid.d != 0)

    @property
    def periodic(self) -> bool:
        return not self.native

    @property
    def has_state(self) -> bool:
        return self.type.single_joint

    def state_message(self, dt: float) -> JointControllerState:
        row = self.rows[0]
        return self._state(self.target[0], self.hw.velocity(row), 0.0, dt)

    def command_range(self, index: int) -> tuple[float, float]:
        limit = self.hw.velocity_limit[self.rows[index]]
        return (-limit, limit) if np.isfinite(limit) else (-5.0, 5.0)

    def set_gains(self, gains: Sequence[PidGains]) -> None:
        if self.pid is None:
            raise InputError(f"{self.name} is an ideal velocity servo: it has no gains")
        self._gains = new = list(gains)
        self.pid = PidArray(new)
        if self.running:
            self._configure()

    def _configure(self) -> None:
        hw, rows = self.hw, self.rows
        hw.release(rows)
        if self.pid is None:
            hw.command.teleport[rows] = TELEPORT_VELOCITY
        elif self.native:
            hw.command.kd[rows] = self.pid.p
            hw.gains_changed(rows)
        self._write_target()

    def starting(self, t: float) -> None:
        super().starting(t)
        self.target[:] = 0.0
        self._last_t = None
        if self.pid is not None:
            self.pid.reset()
        self._configure()

    def apply(self, values: np.ndarray, t: float) -> None:
        limit = self.hw.velocity_limit[self.rows]
        self.target = self.clamp(values, -limit, limit, "URDF velocity limit")
        self._write_target()

    def _write_target(self) -> None:
        self.hw.command.velocity[self.rows] = self.target

    def update(self, t: float, dt: float) -> None:
        super().update(t, dt)
        if self.native or self.pid is None:
            return  # MuJoCo's servo, or the ideal servo's teleport, does the rest
        if self._last_t is not None:
            dt = t - self._last_t  # the manager may also run us off-period, for a new command
        if dt <= 0:
            return
        self._last_t = t
        error = self.target - self.hw.state.velocity[self.rows]
        self.hw.command.effort[self.rows] = self.pid.command(error, None, dt)
