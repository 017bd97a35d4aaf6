"""Divergence watchdog: stop a simulation that has left physics, and say why.

MuJoCo silently resets a simulation whose accelerations become NaN; we switch that off and
check instead, so the user sees which link went and the likely cause (the seed's Fig. 4.7:
misplaced centre of mass, overlarge inertia; or controller gains, or the time step).

A robot can also leave physics slowly: started inside the ground it is pushed out and flies
up at 47 m/s, under the speed limit. With no motor or applied force at work the mechanical
energy can only fall (damping, friction and contacts dissipate), so a gain is an error too.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from mexone.errors import MexoneError
from mexone.ranges import SPEED, SPIN

__all__ = ["DivergenceError", "Watchdog", "link_speeds"]

MAX_LINEAR_SPEED = SPEED.high  # m/s: no part of a lab robot moves this fast (a 125 m fall)
MAX_ANGULAR_SPEED = SPIN.high  # rad/s: 80 turns a second
# Below this in every generalised velocity (rad/s, m/s) the link speeds are not computed: sane
# robots are far below it, and a diverging one passes it within a few steps of going wrong.
_CHEAP_BOUND = 25.0
_ENERGY_EVERY = 5  # checks between energy balances (each costs a few microseconds)
# Energy a passive robot may gain (contacts settling, integration error) before it is an error:
# what lifting the whole robot this high in Earth's gravity takes (and at least 1 J)
ENERGY_GAIN_HEIGHT = 0.25  # m
_EARTH_G = 9.81
_START_CHECKS = 20  # steps: a check this early after a reset measures from the start of the run
_GAIN_CAUSE = "it started inside the ground or another body, or a contact is too stiff for the time step"


class DivergenceError(MexoneError):
    """The simulation produced NaN or speeds beyond physical sense."""


def link_speeds(model: mujoco.MjModel, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
    """Linear speed of every body's centre of mass and its angular speed (from cvel, which is
    expressed at the subtree centre of mass of the body's tree root)."""
    omega = data.cvel[:, :3]
    offset = data.xipos - data.subtree_com[model.body_rootid]
    linear = data.cvel[:, 3:] + np.cross(omega, offset)
    return np.linalg.norm(linear, axis=1), np.linalg.norm(omega, axis=1)


@dataclass
class Watchdog:
    model: mujoco.MjModel
    data: mujoco.MjData
    link_names: dict[int, str]  # body id -> link name
    cause: Callable[[str], str | None] | None = None  # link name -> likely cause
    # other layers' suspects, asked in order when the model itself is not to blame (the control
    # layer: "controller gains too high for the time step")
    suspects: list[Callable[[], str | None]] = field(default_factory=list)
    # the energy a passive run must stay below, and what it was measured under
    _ceiling: float | None = field(default=None, init=False, repr=False)
    _ceiling_key: tuple[Any, ...] = field(default=(), init=False, repr=False)
    _last_time: float = field(default=-np.inf, init=False, repr=False)
    _checks: int = field(default=0, init=False, repr=False)

    def forget(self) -> None:
        """Someone put energy in on purpose (a teleport with a velocity, a new model): measure
        the ceiling again from now."""
        self._ceiling = None

    def check(self) -> None:
        data = self.data
        self._checks += 1
        qvel = data.qvel
        if float(qvel @ qvel) < _CHEAP_BOUND**2:  # the usual case, in a microsecond (NaN: False)
            if self._checks % _ENERGY_EVERY == 0 or \
                    data.time <= _START_CHECKS * self.model.opt.timestep:  # a run's first checks
                self._check_energy()
            return
        finite = np.isfinite(data.qvel).all() and np.isfinite(data.qpos).all()
        if finite:
            self._check_energy()
        if finite:
            linear, angular = link_speeds(self.model, data)
            worst_lin, worst_ang = int(np.argmax(linear)), int(np.argmax(angular))
            if linear[worst_lin] <= MAX_LINEAR_SPEED and angular[worst_ang] <= MAX_ANGULAR_SPEED:
                return
            if linear[worst_lin] > MAX_LINEAR_SPEED:
                body, what = worst_lin, f"reached {linear[worst_lin]:.3g} m/s"
            else:
                body, what = worst_ang, f"spins at {angular[worst_ang]:.3g} rad/s"
        else:
            body = self._first_nan_body()
            what = "has NaN position or velocity"
        name = self.link_names.get(body, self.model.body(body).name)
        cause = self.cause(name) if self.cause else None
        for suspect in self.suspects:
            cause = cause or suspect()
        cause = cause or "contact or joint forces too stiff for the time step: lower kp or the step"
        raise DivergenceError(f"simulation diverged at t = {data.time:.3f} s: link '{name}' {what}",
                              hint=f"likely cause: {cause}")

    # ----- energy ---------------------------------------------------------------------------
    def _energy(self, data: mujoco.MjData) -> tuple[float, float]:
        """(potential, kinetic) in J."""
        mujoco.mj_energyPos(self.model, data)
        mujoco.mj_energyVel(self.model, data)
        return float(data.energy[0]), float(data.energy[1])

    def _passive(self) -> bool:
        data = self.data
        return not (data.qfrc_actuator.any() or data.qfrc_applied.any()
                    or data.xfrc_applied.any())

    def _check_energy(self) -> None:
        """Kinetic energy beyond what the robot had (or has, as potential energy, however it got
        there: set_joint_positions may lift an arm) is energy nothing gave it."""
        model, data = self.model, self.data
        key = (tuple(model.opt.gravity), float(model.opt.timestep))
        if data.time < self._last_time or key != self._ceiling_key:  # a reset, or new physics
            self._ceiling = None
        self._last_time, self._ceiling_key = data.time, key
        if not self._passive():
            self._ceiling = None  # a motor or a push may add energy: measure again once it stops
            return
        potential, kinetic = self._energy(data)
        if self._ceiling is None:
            if data.time > _START_CHECKS * model.opt.timestep:
                self._ceiling = potential + kinetic
                return
            self._ceiling = sum(self._energy(self._home()))  # the run began at home, at rest
        self._ceiling = max(self._ceiling, potential)
        gain = potential + kinetic - self._ceiling
        if gain <= max(1.0, float(model.body_mass.sum()) * _EARTH_G * ENERGY_GAIN_HEIGHT):
            return
        linear, _ = link_speeds(model, data)
        body = int(np.argmax(linear))
        name = self.link_names.get(body, model.body(body).name)
        cause = (self.cause(name) if self.cause else None) or _GAIN_CAUSE
        raise DivergenceError(
            f"simulation diverged at t = {data.time:.3f} s: the robot gained {gain:.3g} J with no "
            f"motor or force driving it (link '{name}' at z = {data.xipos[body][2]:.2f} m, "
            f"{linear[body]:.3g} m/s)", hint=f"likely cause: {cause}")

    def _home(self) -> mujoco.MjData:
        """Where a reset puts the robot: every joint at home, at rest."""
        scratch = mujoco.MjData(self.model)
        mujoco.mj_kinematics(self.model, scratch)
        mujoco.mj_comPos(self.model, scratch)
        mujoco.mj_crb(self.model, scratch)
        return scratch

    def _first_nan_body(self) -> int:
        bad = ~np.isfinite(self.data.qvel) | ~np.isfinite(self.data.qacc)
        dofs = np.flatnonzero(bad)
        return int(self.model.dof_bodyid[dofs[0]]) if dofs.size else 0
