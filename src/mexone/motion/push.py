"""Pushes: an external force on a link for a while, as Gazebo's /gazebo/apply_body_wrench does.

`apply_wrench` pushes at the link's centre of mass through `Simulation.apply_wrench` (the one
place that writes forces into MuJoCo; a reset ends every push); it runs in the simulation
thread (front ends call it through `sim.work`).
"""

from __future__ import annotations

import math

from mexone.errors import InputError
from mexone.physics.simulation import Simulation

__all__ = ["apply_wrench", "PUSH_SECONDS"]

PUSH_SECONDS = 0.1  # how long a push lasts: impulse / PUSH_SECONDS is the force


def apply_wrench(sim: Simulation, link: str, force, torque=(0.0, 0.0, 0.0),
                 duration: float = PUSH_SECONDS) -> None:
    """Add a world-frame force (N) and torque (N m) at `link`'s centre of mass from now for
    `duration` s of sim time. Simulation thread only."""
    if not (duration > 0 and math.isfinite(duration)):
        raise InputError(f"push on '{link}': duration {duration} must be a finite number > 0 s")
    com = sim.data.xipos[sim.body_id(link)].copy()
    sim.apply_wrench(link, force, torque, point=com, duration=duration)
