"""Divergence watchdog: stop a simulation that has left physics, and say why.

MuJoCo silently resets a simulation whose accelerations become NaN; we switch that off and
check instead, so the user sees which link went and the likely cause (the seed's Fig. 4.7:
misplaced centre of mass, overlarge inertia; or controller gains, or the time step).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import mujoco
import numpy as np

from mexone.errors import MexoneError

__all__ = ["DivergenceError", "Watchdog", "link_speeds"]

MAX_LINEAR_SPEED = 50.0  # m/s: no part of a lab robot moves this fast (a 125 m fall)
MAX_ANGULAR_SPEED = 500.0  # rad/s: 80 turns a second
# Below this in every generalised velocity (rad/s, m/s) the link speeds are not computed: sane
# robots are far below it, and a diverging one passes it within a few steps of going wrong.
_CHEAP_BOUND = 25.0


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

    def check(self) -> None:
        data = self.data
        finite = np.isfinite(data.qvel).all() and np.isfinite(data.qpos).all()
        if finite and np.abs(data.qvel).max() < _CHEAP_BOUND:
            return  # the usual case, in a microsecond; link speeds only when joints are fast
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

    def _first_nan_body(self) -> int:
        bad = ~np.isfinite(self.data.qvel) | ~np.isfinite(self.data.qacc)
        dofs = np.flatnonzero(bad)
        return int(self.model.dof_bodyid[dofs[0]]) if dofs.size else 0
