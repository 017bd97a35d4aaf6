"""The page's Sensors panel and the View menu's Balance overlay.

Sensors: each camera live (downscaled for the page, rendered a few times a second and only
while its box is ticked), IMU and foot-force plots (panes of the Plots panel's kind, over the
same SignalLog), a contact light per sole, force arrows at the feet. Balance: the COM's
ground projection, the measured ZMP and the support polygon, with whether the robot is
statically stable. Everything is read in the simulation thread, between
frames; nothing here writes the simulation.
"""

from __future__ import annotations

import time

import numpy as np
import viser

from mexone.gui.panels import Panel, register_panel
from mexone.gui.plots import Pane
from mexone.sensors import CameraSensor, ForceTorqueSensor, Sensor

__all__ = ["SensorPanel", "BALANCE", "sensor_panes"]

BALANCE = "Balance"  # the View menu's entry
CAMERA_FPS = 5.0  # images sent to the page per second of wall time
PAGE_WIDTH = 320  # pixels of a camera image on the page
NEWTONS_PER_METRE = 500.0  # force arrows: 500 N draws 1 m
WINDOW = 10.0  # s of sim time the sensor plots show
PLOT_FRAMES = 5  # frames between redraws of the sensor plots


def _depth_colours(depth: np.ndarray) -> np.ndarray:
    """Near bright, far dark, nothing (NaN) black."""
    finite = np.isfinite(depth)
    out = np.zeros((*depth.shape, 3), dtype=np.uint8)
    if finite.any():
        lo, hi = np.nanmin(depth), np.nanmax(depth)
        level = 1.0 - (depth[finite] - lo) / max(hi - lo, 1e-6)
        out[finite] = (np.stack([level, 0.6 * level, 0.2 + 0.8 * level], axis=-1) * 255).astype(np.uint8)
    return out


def sensor_panes(sensors) -> list[tuple[str, list[str]]]:
    """(title, signal names) of the Sensors panel's plots, from each sensor type's `pane`: a
    type's field/axis over all its sensors ("force-torque sensors, Fz"), or, for a field that
    is a vector of its own (field/"linear_acceleration"), the first sensor's three axes."""
    by_type: dict[type, list] = {}
    for sensor in sensors:
        if sensor.pane is not None and sensor.state_type is not None:
            by_type.setdefault(type(sensor), []).append(sensor)
    out = []
    for kind, group in by_type.items():
        title, path = kind.pane
        if "/" in path:
            out.append((title, [f"{s.spec.name}/{path}" for s in group]))
        else:
            first = group[0]
            out.append((f"{first.spec.name}: {title}",
                        [n for n, _ in first.signals() if n.startswith(f"{first.spec.name}/{path}/")]))
    return out


@register_panel
class SensorPanel(Panel):
    """The Sensors folder and the Balance overlay (see the module's doc)."""

    name = "sensors"
    order = 7
    period = 1

    def build(self) -> None:
        self.log = self.host.log
        self._frames = 0
        suite = self.lab.sensors
        self.cameras = {n: s for n, s in suite.sensors.items() if isinstance(s, CameraSensor)}
        self.fts = {n: s for n, s in suite.sensors.items() if isinstance(s, ForceTorqueSensor)}
        # every other sensor type's view: a markdown line each (contact lights, ...)
        self.viewed = [s for s in suite.sensors.values() if type(s).view is not Sensor.view]
        self.images: dict[str, viser.GuiImageHandle] = {}
        self.show_camera: dict[str, viser.GuiCheckboxHandle] = {}
        self._last_image = -1.0
        self._build_panel()
        self._build_overlay()

    # ----- panel ---------------------------------------------------------------------------
    def _build_panel(self) -> None:
        gui = self.server.gui
        with gui.add_folder("Sensors", expand_by_default=False) as folder:
            if not self.lab.sensors.sensors:
                gui.add_markdown("This robot declares no sensors (`<gazebo><sensor>` in its URDF).")
            for name, camera in self.cameras.items():
                self.show_camera[name] = gui.add_checkbox(f"{name} camera", False,
                                                          hint="renders while ticked")
                h = round(PAGE_WIDTH * camera.camera.height / camera.camera.width)
                blank = np.zeros((h, PAGE_WIDTH, 3), dtype=np.uint8)
                self.images[name] = gui.add_image(blank, label=f"{name} (rgb)", format="jpeg",
                                                  jpeg_quality=70)
                if camera.spec.type == "depth":
                    self.images[name + "/depth"] = gui.add_image(blank, label=f"{name} (depth)",
                                                                 format="jpeg", jpeg_quality=70)
            self.contact_view = gui.add_markdown("")
            self.panes = [Pane(self.server, self.log, folder, title, names, 1.8)
                          for title, names in sensor_panes(self.lab.sensors.sensors.values())]

    def _build_overlay(self) -> None:
        scene = self.server.scene
        self.com_marker = scene.add_icosphere("/balance/com", radius=0.015, color=(40, 180, 60),
                                              visible=False)
        self.zmp_marker = scene.add_icosphere("/balance/zmp", radius=0.012, color=(220, 40, 40),
                                              visible=False)
        self.polygon = scene.add_line_segments("/balance/support", np.zeros((1, 2, 3), np.float32),
                                               (40, 90, 220), thickness=4.0, thickness_units="screen",
                                               visible=False)
        self.arrows = scene.add_line_segments("/balance/forces", np.zeros((1, 2, 3), np.float32),
                                              (250, 140, 20), thickness=6.0, thickness_units="screen",
                                              visible=False)
        self.stability = ""

    def show(self, on: bool) -> None:
        """The Balance overlay on or off (View > Balance)."""
        for handle in (self.com_marker, self.zmp_marker, self.polygon, self.arrows):
            handle.visible = on

    def status_line(self) -> str | None:
        """Whether the robot is statically stable, while the Balance overlay shows."""
        return self.stability if self.com_marker.visible and self.stability else None

    # ----- per frame (simulation thread) --------------------------------------------------------
    def update(self) -> None:
        self._frames += 1
        now_wall = time.monotonic()
        if self.com_marker.visible:
            self._update_balance()
        if self.viewed:
            lines = [sensor.view() for sensor in self.viewed]
            text = " &nbsp; ".join(line for line in lines if line)
            if text != self.contact_view.content:  # a standing robot's lights stay as they are
                self.contact_view.content = text
        if now_wall - self._last_image >= 1.0 / CAMERA_FPS:
            self._last_image = now_wall
            self._update_images()
        if self._frames % PLOT_FRAMES == 0:
            self.update_plots()

    def update_plots(self) -> None:
        for pane in self.panes:
            pane.update(WINDOW)

    def _update_balance(self) -> None:
        state = self.lab.sensors.balance.state()
        ground = self.lab.sensors.balance.ground_z + 0.002
        self.com_marker.position = (state.com[0], state.com[1], ground)
        if state.zmp is not None:
            self.zmp_marker.position = (state.zmp[0], state.zmp[1], ground)
        poly = state.polygon
        if len(poly) >= 2:
            ring = np.c_[poly, np.full(len(poly), ground)]
            self.polygon.points = np.stack([ring, np.roll(ring, -1, axis=0)], axis=1).astype(np.float32)
        segments = []
        for ft in self.fts.values():
            force, _torque, at = ft.parent_on_child_world()
            segments.append([at, at - force / NEWTONS_PER_METRE])  # what the foot pushes back with
        if segments:
            self.arrows.points = np.array(segments, dtype=np.float32)
        stable = state.statically_stable
        self.stability = (f"**statically stable**: {'yes' if stable else 'no'} (COM projection "
                          f"{'inside' if stable else 'outside'} the support polygon)")

    def _update_images(self) -> None:
        for name, camera in self.cameras.items():
            if not self.show_camera[name].value:
                continue
            step = max(1, camera.camera.width // PAGE_WIDTH)
            self.images[name].image = camera.render(depth=False)[::step, ::step]
            if camera.spec.type == "depth":
                self.images[name + "/depth"].image = _depth_colours(
                    camera.render(depth=True)[::step, ::step])
