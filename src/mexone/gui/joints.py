"""The Joints panel: a slider per joint of every controller that takes per-joint commands (in
rad or degrees), Home, and the Gains folder of the position controllers' live PID gains.

A slider's move is a command on the controller's topic, as any node's (checked against the
controller's range on the server); the sliders follow what the controllers are commanded,
whoever commanded it, except one a hand moved in the last second.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import viser

from mexone.control.controllers import ControllerInterface
from mexone.control.spec import joint_label
from mexone.errors import InputError
from mexone.gui.panels import Panel, register_panel
from mexone.ranges import GAINS, number_text

__all__ = ["JointsPanel"]

TOUCH_SECONDS = 1.0  # a slider a hand moved this recently is not synced


@register_panel
class JointsPanel(Panel):
    """Sliders, Units, Home, and the Gains folder (see the module's doc)."""

    name = "joints"
    order = 3

    def build(self) -> None:
        gui = self.server.gui
        self.sliders: dict[tuple[str, str], viser.GuiSliderHandle] = {}
        self._touched: dict[tuple[str, str], float] = {}  # when a person last moved a slider
        manager = self.lab.manager
        with gui.add_folder("Joints"):
            if manager is None:
                gui.add_markdown(self.lab.no_controllers or "No controllers loaded.")
                return
            self.units = gui.add_dropdown("Units", ("rad", "deg"), initial_value="rad")
            self.units.on_update(lambda _: self.do(self._rescale_sliders))
            gui.add_button("Home", hint="every position controller to 0").on_click(
                lambda _: self.do(self.home))
            for ctrl in manager.controllers.values():
                if ctrl.takes_trajectories:
                    gui.add_markdown(f"`{ctrl.name}`: send JointTrajectory messages from a routine")
                if ctrl.sliders:
                    for index, joint in enumerate(ctrl.joints):
                        self._add_slider(ctrl, index, joint)
        with gui.add_folder("Gains", expand_by_default=False):
            for ctrl in manager.controllers.values():
                if ctrl.tunable and ctrl.holds_position:
                    self._add_gains(ctrl)

    def _scale(self, ctrl: ControllerInterface) -> float:
        """Slider units per command unit (degrees for angles when asked)."""
        return 180.0 / math.pi if ctrl.unit == "rad" and self.units.value == "deg" else 1.0

    def _add_slider(self, ctrl: ControllerInterface, index: int, joint: str) -> None:
        lo, hi = ctrl.command_range(index)
        slider = self.server.gui.add_slider(f"{joint}", min=round(lo, 4), max=round(hi, 4),
                                            step=0.001, initial_value=0.0,
                                            hint=f"{ctrl.name} ({ctrl.unit})")
        self.sliders[(ctrl.name, joint)] = slider

        def moved(event) -> None:
            if event.client is None:  # our own syncs are not commands
                return
            value = event.target.value  # now: a sync may change the slider before we run
            self._touched[(ctrl.name, joint)] = time.monotonic()

            def send() -> None:
                number = float(value) / self._scale(ctrl)
                lo, hi = ctrl.command_range(index)
                if not (math.isfinite(number) and lo - 1e-9 <= number <= hi + 1e-9):
                    raise InputError(f"{joint}: {number_text(value)} is outside {number_text(lo)} to "
                                     f"{number_text(hi)} {ctrl.unit}")
                self.lab.manager.command(ctrl.name, {joint: number})

            self.do(send)

        slider.on_update(moved)

    def _rescale_sliders(self) -> None:
        manager = self.lab.manager
        for (name, joint), slider in self.sliders.items():
            ctrl = manager.controllers[name]
            index = ctrl.joints.index(joint)
            lo, hi = ctrl.command_range(index)
            f = self._scale(ctrl)
            slider.min, slider.max, slider.step = round(lo * f, 4), round(hi * f, 4), 0.001 * f
            slider.value = float(ctrl.setpoint[index]) * f

    def update(self) -> None:
        """Show what the controllers are commanded, whoever commanded it."""
        if not self.sliders:
            return
        manager = self.lab.manager
        now = time.monotonic()
        for (name, joint), slider in self.sliders.items():
            if now - self._touched.get((name, joint), -1e9) < TOUCH_SECONDS:
                continue  # do not fight a hand on the slider
            ctrl = manager.controllers[name]
            value = round(float(ctrl.setpoint[ctrl.joints.index(joint)]) * self._scale(ctrl), 3)
            if abs(slider.value - value) > 1e-3:
                slider.value = value

    def reset(self, world: bool) -> None:
        for slider in self.sliders.values():
            slider.value = 0.0

    def home(self) -> None:
        """Every position controller's joints to 0."""
        manager = self.lab.manager
        for ctrl in manager.controllers.values():
            if ctrl.running and ctrl.holds_position:
                manager.command(ctrl.name, [0.0] * len(ctrl.joints))

    def _add_gains(self, ctrl: ControllerInterface) -> None:
        gui = self.server.gui
        gains = ctrl.gains[0]
        label = joint_label(ctrl.name)
        with gui.add_folder(label, expand_by_default=False):
            for key in ("p", "i", "d"):
                self.host.fields.add(f"{key} ({label})", float(getattr(gains, key)), GAINS[key],
                                     lambda v, c=ctrl, k=key: self.set_gain(c, k, v))

    def set_gain(self, ctrl: ControllerInterface, key: str, value: float) -> None:
        """Simulation thread: one PID term of every joint of `ctrl`, live."""
        gains = [replace(g, **{key: value}) for g in ctrl.gains]
        self.lab.manager.set_gains(ctrl.name, gains)
