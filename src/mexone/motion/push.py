"""Pushes: an external force on a link for a while, as Gazebo's /gazebo/apply_body_wrench does.

`apply_wrench` is the one function that writes the force into MuJoCo (xfrc_applied, at the
link's centre of mass) and takes it away after `duration`; it runs in the simulation thread
(front ends call it through `sim.work`). Another branch adds the same service to Simulation
itself; when it lands, this function becomes a call to it.
"""

from __future__ import annotations

import math
import weakref

import numpy as np

from mexone.errors import InputError
from mexone.physics.simulation import Simulation

__all__ = ["apply_wrench", "PUSH_SECONDS"]

PUSH_SECONDS = 0.1  # how long a push lasts: impulse / PUSH_SECONDS is the force


def apply_wrench(sim: Simulation, link: str, force, torque=(0.0, 0.0, 0.0),
                 duration: float = PUSH_SECONDS) -> None:
    """Add a world-frame force (N) and torque (N m) at `link`'s centre of mass from now for
    `duration` s of sim time. Simulation thread only."""
    body = sim.compiled.bodies.get(link)
    if body is None:
        raise InputError(f"no link named '{link}'", hint="links: " + ", ".join(sim.compiled.bodies))
    wrench = np.r_[np.asarray(force, dtype=float), np.asarray(torque, dtype=float)]
    if wrench.shape != (6,) or not np.isfinite(wrench).all():
        raise InputError(f"push on '{link}': force and torque must be three finite numbers each")
    if not (duration > 0 and math.isfinite(duration)):
        raise InputError(f"push on '{link}': duration {duration} must be a finite number > 0 s")
    if sim not in _pushes:  # a reset (which zeroes xfrc_applied) ends every push
        _pushes[sim] = []
        sim.on_reset(lambda: _end_all(sim))
    sim.data.xfrc_applied[body] += wrench
    timer = None

    def release(s: Simulation) -> None:
        s.data.xfrc_applied[body] -= wrench
        s.remove_periodic(timer)
        _pushes[s].remove(timer)

    timer = sim.add_periodic(duration, release)
    _pushes[sim].append(timer)


_pushes: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # sim -> its pushes' timers


def _end_all(sim: Simulation) -> None:
    for timer in _pushes[sim]:
        sim.remove_periodic(timer)
    _pushes[sim].clear()
