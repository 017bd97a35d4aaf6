"""The View panel: Gazebo's View menu. The robot's overlays (centre of mass, inertia, joint axes,
collisions, contacts: gui/scene.py), see-through and wireframe links, and the overlays other
panels draw (Balance: the Sensors panel's; Walk plan: gui/walkplan.py's), each a checkbox.
"""

from __future__ import annotations

from mexone.gui.panels import Panel, register_panel
from mexone.gui.scene import OVERLAYS
from mexone.gui.sensors import BALANCE
from mexone.gui.walkplan import WALK_PLAN

__all__ = ["ViewPanel", "INSIDE"]

INSIDE = ("Center of Mass", "Inertia")  # overlays inside the links: the links go see-through


@register_panel
class ViewPanel(Panel):
    """The overlays' checkboxes (see the module's doc)."""

    name = "view"
    order = 2

    def build(self) -> None:
        gui = self.server.gui
        with gui.add_folder("View"):
            self.overlay_boxes = {}
            for overlay in OVERLAYS:
                box = self.overlay_boxes[overlay] = gui.add_checkbox(overlay, False)
                box.on_update(lambda e, name=overlay: self.do(
                    lambda: self.show_overlay(name, bool(e.target.value))))
            self.transparent = gui.add_checkbox("Transparent", False,
                                                hint="on by itself while Center of Mass or "
                                                     "Inertia shows (they sit inside the links)")
            self.transparent.on_update(lambda e: self.do(self._update_transparency))
            wireframe = gui.add_checkbox("Wireframe", False)
            wireframe.on_update(lambda e: self.do(
                lambda: self.host.scene.set_wireframe(bool(e.target.value))))
            balance = gui.add_checkbox(BALANCE, False, hint="COM projection (green), ZMP (red), "
                                                            "support polygon (blue), foot forces")
            balance.on_update(lambda e: self.do(
                lambda: self._show_in("sensors", bool(e.target.value))))
            self.walk_plan_box = gui.add_checkbox(
                WALK_PLAN, False, hint="a walk's footsteps (blue), planned ZMP (orange) and COM "
                                       "(green), measured ZMP (red)")
            self.walk_plan_box.on_update(lambda e: self.do(
                lambda: self._show_in("walk_plan", bool(e.target.value))))

    def _show_in(self, panel: str, on: bool) -> None:
        """Another panel's overlay (`show(on)`), if that panel is on this page."""
        other = self.host.panel(panel)
        if other is not None:
            other.show(on)

    def show_overlay(self, name: str, on: bool) -> None:
        """Simulation thread: one of the scene's overlays on or off."""
        self.host.scene.show(name, on)
        self._update_transparency()

    def _update_transparency(self) -> None:
        inside = any(self.overlay_boxes[k].value for k in INSIDE)
        self.host.scene.set_transparent(bool(self.transparent.value) or inside)
