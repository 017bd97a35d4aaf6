"""The Physics panel: gravity and the time step, applied at once (`Simulation.set_gravity`,
`set_timestep`: each checked against its one range, ranges.py), and self-collision, which
Reset world applies (the contacts' bits change with the robot at rest, not mid-fall).
"""

from __future__ import annotations

from dataclasses import replace

from mexone.gui.panels import Panel, register_panel
from mexone.ranges import GRAVITY, TIMESTEP

__all__ = ["PhysicsPanel"]


@register_panel
class PhysicsPanel(Panel):
    """Gravity, Time step and Self-collision (see the module's doc)."""

    name = "physics"
    order = 9

    def build(self) -> None:
        gui, host = self.server.gui, self.host
        model = self.lab.sim.model
        with gui.add_folder("Physics", expand_by_default=False):
            self.gravity = host.fields.add("Gravity (m/s²)", [float(g) for g in model.opt.gravity],
                                           GRAVITY, lambda g: self.lab.sim.set_gravity(g),
                                           hint="x, y, z")
            self.timestep = host.fields.add("Time step (s)", float(model.opt.timestep), TIMESTEP,
                                            lambda dt: self.lab.sim.set_timestep(dt))
            self.self_collide = gui.add_checkbox("Self-collision", host.options.self_collision
                                                 is not False, hint="applies at Reset world")

    def reset(self, world: bool) -> None:
        """Reset world: self-collision as the box says, now and for the next Load."""
        if world:
            on = None if self.self_collide.value else False
            self.lab.sim.set_self_collision(on)
            self.host.options = replace(self.host.options, self_collision=on)
