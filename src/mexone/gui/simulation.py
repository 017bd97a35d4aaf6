"""The Simulation panel: Gazebo's play/pause, step, reset and real-time factor, the camera that
follows the robot, and Screenshot.

The buttons hand their work to the simulation thread; stepping, pausing and resetting are the
page's own (`PanelHost.step_n`, `toggle_pause`, `reset_model`, `reset_world`), which Load and the
other panels use too. The Pause button shows what the simulation is doing, whoever paused it.

Screenshot: a PNG of what the pressing page shows (gui/screenshot.py), or MuJoCo's render of the
same view if the page sends none in time.
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path

import numpy as np
import viser

from mexone.gui.panels import Panel, register_panel
from mexone.gui.screenshot import Screenshots, page_picture
from mexone.ranges import RTF, STEPS

__all__ = ["SimulationPanel", "PAGE_RENDER_SECONDS", "MAX_PAGE_RENDER"]

log = logging.getLogger(__name__)

PAGE_RENDER_SECONDS = 10.0  # a page that sends no picture by then gets MuJoCo's render instead
MAX_PAGE_RENDER = 4096  # px a side at most asked of a page for a screenshot


@register_panel
class SimulationPanel(Panel):
    """Play/Pause, Step, Step N, the resets, the real-time factor, Follow and Screenshot."""

    name = "simulation"
    order = 1
    period = 1

    def __init__(self, host):
        super().__init__(host)
        self.follow_offset: dict[int, np.ndarray] = {}  # client -> camera position - robot
        self.screenshots = Screenshots(host.settings.record_folder or Path.cwd())
        self.last_screenshot: Path | None = None

    def build(self) -> None:
        host, gui = self.host, self.server.gui
        self.follow_offset.clear()
        with gui.add_folder("Simulation"):
            self.play = gui.add_button("Pause", icon=viser.Icon.PLAYER_PAUSE)
            self.play.on_click(lambda _: self.do(host.toggle_pause))
            self._show_paused(self.lab.sim.paused)
            step = gui.add_button("Step", hint="one physics step")
            step.on_click(lambda _: self.do(lambda: host.step_n(1)))
            self.steps = host.fields.add("Steps", 100, STEPS, lambda v: None)
            step_n = gui.add_button("Step N")
            step_n.on_click(lambda _: self.do(lambda: host.step_n(host.fields.held(self.steps)[0])))
            gui.add_button("Reset model").on_click(lambda _: self.do(host.reset_model))
            gui.add_button("Reset world").on_click(lambda _: self.do(host.reset_world))
            self.rtf = host.fields.add("Real-time factor", host.target_rtf, RTF, self.set_rtf,
                                       hint="0 = as fast as possible")
            self.follow = gui.add_checkbox("Follow robot", False)
            self.follow.on_update(lambda _: self.follow_offset.clear())
            self.paused_after_reset = gui.add_checkbox("Start paused", host.pause_after_reset,
                                                       hint="after a reset, wait for Play "
                                                            "(mexone sim --paused)")
            self.paused_after_reset.on_update(
                lambda e: setattr(host, "pause_after_reset", bool(e.target.value)))
            shot = gui.add_button("Screenshot", icon=viser.Icon.CAMERA,
                                  hint="a PNG of this view as the page draws it (MuJoCo's render "
                                       "if the page sends none), saved as "
                                       "mexone_screenshot_NNN.png in the folder mexone started in")
            shot.on_click(lambda e: self._screenshot_clicked(e.client))

    def set_rtf(self, value: float) -> None:
        """Simulation thread: pace the simulation at `value` times real time (0: unpaced)."""
        self.host.target_rtf = value
        sim = self.lab.sim
        sim.target_rtf = value or None
        if not sim.paused:
            sim.resume()  # restarts the pacing from now at the new rate

    def _show_paused(self, paused: bool) -> None:
        self.play.label, self.play.icon = ("Play", viser.Icon.PLAYER_PLAY) if paused else \
            ("Pause", viser.Icon.PLAYER_PAUSE)
        self._paused = paused

    def update(self) -> None:
        """Every frame: the Pause button says what the simulation does; Follow's camera."""
        if self.lab.sim.paused != self._paused:
            self._show_paused(self.lab.sim.paused)
        if self.follow.value:
            self._follow()

    def _follow(self) -> None:
        """Keep each page's view on the robot: the camera keeps the offset it had when Follow
        was ticked (the page's own camera reports lag behind a fast robot)."""
        base = np.array(self.lab.sim.data.xpos[self.lab.sim.compiled.root_body])
        for client_id, client in self.server.get_clients().items():
            offset = self.follow_offset.get(client_id)
            if offset is None:
                offset = np.asarray(client.camera.position) - np.asarray(client.camera.look_at)
                self.follow_offset[client_id] = offset
            with client.atomic():
                client.camera.look_at = tuple(base)
                client.camera.position = tuple(base + offset)

    def unload(self) -> None:
        self.screenshots.close()  # its renderer belongs to the old model

    def stop(self) -> None:
        self.screenshots.close()

    # ----- screenshots ------------------------------------------------------------------------
    def _screenshot_clicked(self, client) -> None:
        if client is None:
            return
        camera = client.camera
        view = (np.asarray(camera.position), np.asarray(camera.look_at), float(camera.fov))
        # the page reports its canvas size: a page could claim any, so at most MAX_PAGE_RENDER
        size = tuple(min(int(v), MAX_PAGE_RENDER) for v in (camera.image_height, camera.image_width))
        # asking the page blocks until it answers: never in viser's or the simulation's thread
        threading.Thread(target=self.page_screenshot, args=(client, size, view), daemon=True,
                         name="screenshot").start()

    def page_screenshot(self, client, size: tuple[int, int], view) -> None:
        """The page's own picture if it sends one, else MuJoCo's render of the same view."""
        picture = None
        if min(size) > 0:
            try:
                picture = page_picture(client.camera.get_render(
                    *size, transport_format="png", timeout=PAGE_RENDER_SECONDS))
            except Exception as exc:  # noqa: BLE001 - a closed or silent page: use the fallback
                log.info("screenshot: the page sent no picture (%s); rendering it here", exc)
        if picture is None:
            self.do(lambda: self.screenshot(*view))
        else:
            self.do(lambda: self._saved(self.screenshots.write(picture)))

    def screenshot(self, position, look_at, fov: float) -> Path:
        """Simulation thread: render this view offscreen and save a new numbered PNG."""
        return self._saved(self.screenshots.save(self.lab.sim, position, look_at, fov))

    def _saved(self, path: Path) -> Path:
        self.last_screenshot = path
        self.host.notify("Screenshot", f"saved {path.name} in {path.parent}", color="green")
        return path
