"""Pushes: an external force on a link for a while, as Gazebo's /gazebo/apply_body_wrench does.

The one writer of MuJoCo's xfrc_applied is `Simulation.apply_wrench` (the GUI's push tool uses
it too); `apply_wrench` here is its routine-and-benchmark spelling with the push length the
issue measures by. Simulation thread only (front ends call it through `sim.work`).
"""

from __future__ import annotations

from mexone.physics.simulation import Simulation

__all__ = ["apply_wrench", "PUSH_SECONDS"]

PUSH_SECONDS = 0.1  # how long a push lasts: impulse / PUSH_SECONDS is the force


def apply_wrench(sim: Simulation, link: str, force, torque=(0.0, 0.0, 0.0),
                 duration: float = PUSH_SECONDS) -> None:
    """Add a world-frame force (N) and torque (N m) at `link`'s centre of mass from now for
    `duration` s of sim time (a reset ends it)."""
    sim.apply_wrench(link, force, torque, duration=duration)
