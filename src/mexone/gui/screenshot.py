"""Screenshot: a PNG of what the pressing page shows, saved on the server.

First choice is the page's own picture, overlays, plots' markers and gizmos included: viser
asks that browser to render its view and send it back (`get_render`). A browser that does not
answer in time or sends a blank picture (a headless one without WebGL) gets MuJoCo's offscreen
render instead (EGL, as cameras and `mexone render` use it) from the same eye, target and
vertical field of view: the robot and the world, no overlays. Files are
`mexone_screenshot_NNN.png` in the folder mexone was started in, created exclusively ('xb'),
so an existing file is never replaced, whoever made it.
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np

from mexone.errors import MexoneError
from mexone.physics.simulation import Simulation
from mexone.sensors.camera import _release_gl_context

__all__ = ["Screenshots", "camera_from_view", "next_free", "page_picture"]

PREFIX = "mexone_screenshot_"
MAX_FILES = 10_000


def camera_from_view(position, look_at) -> tuple[np.ndarray, float, float, float]:
    """(lookat, distance, azimuth, elevation) of MuJoCo's free camera that sees what a page
    camera at `position` looking at `look_at` sees (angles in degrees)."""
    eye, target = np.asarray(position, dtype=float), np.asarray(look_at, dtype=float)
    forward = target - eye
    distance = float(np.linalg.norm(forward))
    if not np.isfinite(forward).all() or distance < 1e-6:
        raise ValueError("Screenshot: the page's camera has no direction")
    azimuth = math.degrees(math.atan2(forward[1], forward[0]))
    elevation = math.degrees(math.asin(max(-1.0, min(1.0, forward[2] / distance))))
    return target, distance, azimuth, elevation


def page_picture(rgba: np.ndarray | None) -> np.ndarray | None:
    """A page's render (h, w, 4 RGBA, transparent where nothing is drawn) on the page's white,
    as (h, w, 3) uint8; None if it shows nothing (all one colour: no WebGL)."""
    if rgba is None or rgba.ndim != 3 or rgba.shape[2] not in (3, 4) or rgba.size == 0:
        return None
    rgba = np.asarray(rgba, dtype=np.float32)
    rgb = rgba[..., :3]
    if rgba.shape[2] == 4:
        alpha = rgba[..., 3:4] / 255.0
        rgb = rgb * alpha + 255.0 * (1.0 - alpha)
    picture = np.clip(np.rint(rgb), 0, 255).astype(np.uint8)
    if (picture == picture[0, 0]).all():
        return None
    return picture


def next_free(folder: Path) -> Path:
    """The first mexone_screenshot_NNN.png not in `folder` (the write still uses 'xb')."""
    for n in range(1, MAX_FILES):
        path = folder / f"{PREFIX}{n:03d}.png"
        if not path.exists():
            return path
    raise MexoneError(f"{folder} holds {MAX_FILES} screenshots already", hint="move some away")


class Screenshots:
    """One renderer, made in the simulation thread on first use, remade when the model changes."""

    def __init__(self, folder: Path, size: tuple[int, int] = (1280, 720)):
        self.folder, self.size = folder, size
        self._renderer: mujoco.Renderer | None = None
        self._model = None

    def render(self, sim: Simulation, position, look_at, fov: float) -> np.ndarray:
        """(h, w, 3) uint8 from this view (simulation thread); fov: vertical, radians."""
        lookat, distance, azimuth, elevation = camera_from_view(position, look_at)
        model = sim.model
        width = min(self.size[0], model.vis.global_.offwidth)
        height = min(self.size[1], model.vis.global_.offheight)
        if self._renderer is None or self._model is not model or \
                (self._renderer.width, self._renderer.height) != (width, height):
            self.close()
            self._renderer = mujoco.Renderer(model, height, width)
            self._model = model
        camera = mujoco.MjvCamera()
        camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        camera.lookat[:] = lookat
        camera.distance, camera.azimuth, camera.elevation = distance, azimuth, elevation
        option = mujoco.MjvOption()
        option.geomgroup[:] = 0
        option.geomgroup[0] = option.geomgroup[1] = 1  # the world and the visual geometry
        fovy = model.vis.global_.fovy
        model.vis.global_.fovy = math.degrees(fov)  # the free camera's field of view
        try:
            self._renderer.update_scene(sim.data, camera, option)
            image = self._renderer.render()
        finally:
            model.vis.global_.fovy = fovy
            _release_gl_context()
        return image

    def save(self, sim: Simulation, position, look_at, fov: float) -> Path:
        """Render and write a new numbered PNG; returns its path (simulation thread)."""
        return self.write(self.render(sim, position, look_at, fov))

    def write(self, image: np.ndarray) -> Path:
        """Write an (h, w, 3) uint8 picture as the next numbered PNG; returns its path."""
        from PIL import Image

        self.folder.mkdir(parents=True, exist_ok=True)
        while True:
            path = next_free(self.folder)
            try:
                with path.open("xb") as out:  # another writer may have taken the name
                    Image.fromarray(image).save(out, format="PNG")
                return path
            except FileExistsError:
                continue

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
