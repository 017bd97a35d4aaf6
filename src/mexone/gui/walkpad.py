"""The walk pad: buttons that send geometry_msgs/Twist on /<ns>/cmd_vel, as a ROS teleop node
would, for the walk_cmd_vel routine (start it in the Routines panel). A held command is sent
again every 0.1 s of sim time (the walker stops on a command older than 0.5 s); Stop sends a
zero Twist.
"""

from __future__ import annotations

from mexone.gui.panels import Panel, register_panel
from mexone.msgs import Twist, Vector3

__all__ = ["WalkPad", "PAD", "SEND_PERIOD"]

SEND_PERIOD = 0.1  # s of sim time between Twists while a button's command is held

# button -> (forward m/s, left m/s, turn left rad/s): about the gait's largest steps
PAD = {"Forward": (0.15, 0.0, 0.0), "Back": (-0.1, 0.0, 0.0), "Left": (0.0, 0.06, 0.0),
       "Right": (0.0, -0.06, 0.0), "Turn left": (0.0, 0.0, 0.4),
       "Turn right": (0.0, 0.0, -0.4), "Stop": (0.0, 0.0, 0.0)}


@register_panel
class WalkPad(Panel):
    """The Walk (cmd_vel) folder (see the module's doc)."""

    name = "walk_pad"
    order = 91

    def build(self) -> None:
        lab, gui = self.lab, self.server.gui
        self.topic = f"{lab.namespace}/cmd_vel"
        self.command = (0.0, 0.0, 0.0)
        self.pending_stop = False
        lab.sim.add_periodic(SEND_PERIOD, self.tick)
        with gui.add_folder("Walk (cmd_vel)", expand_by_default=False):
            gui.add_markdown(f"Twist on `{self.topic}`: run the **walk_cmd_vel** routine")
            for name, command in PAD.items():
                button = gui.add_button(name)
                button.on_click(lambda _, c=command: self.do(lambda: self.set(c)))

    def set(self, command: tuple[float, float, float]) -> None:
        """Hold `command` (simulation thread); a zero one is sent once."""
        self.command = command
        self.pending_stop = not any(command)

    def tick(self, _sim=None) -> None:
        """Send the held command (simulation thread, every SEND_PERIOD)."""
        if any(self.command) or self.pending_stop:
            vx, vy, wz = self.command
            self.lab.bus.publish(self.topic, Twist(Vector3(vx, vy, 0.0), Vector3(0.0, 0.0, wz)))
            self.pending_stop = False
