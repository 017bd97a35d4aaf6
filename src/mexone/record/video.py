"""Offscreen video of a run with MuJoCo's renderer (EGL, falling back to OSMesa)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mexone.errors import InputError, MexoneError

__all__ = ["VideoWriter", "Camera", "check_video_path", "pick_gl_backend", "ensure_gl_backend"]

VIDEO_SUFFIXES = (".mp4", ".gif")


def pick_gl_backend() -> str:
    """The offscreen OpenGL platform that works here: MUJOCO_GL if it does, else egl, else
    osmesa (each probed in a child process, since MuJoCo binds one at import)."""
    import subprocess
    import sys

    probe = ("import mujoco; m = mujoco.MjModel.from_xml_string('<mujoco/>'); "
             "mujoco.Renderer(m, 8, 8).render()")
    tried = []
    for backend in dict.fromkeys([os.environ.get("MUJOCO_GL", ""), "egl", "osmesa"]):
        if not backend:
            continue
        env = dict(os.environ, MUJOCO_GL=backend, PYOPENGL_PLATFORM=backend)
        ok = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True,
                            timeout=120).returncode == 0
        if ok:
            return backend
        tried.append(backend)
    raise MexoneError(f"no offscreen OpenGL here (tried {', '.join(tried)})",
                      hint="install Debian's libegl1 and libgl1-mesa-dri, or libosmesa6")


def ensure_gl_backend(argv: list[str]) -> None:
    """Re-run this command under the working backend if MuJoCo was imported with another."""
    import sys

    backend = pick_gl_backend()
    if backend != os.environ.get("MUJOCO_GL"):
        env = dict(os.environ, MUJOCO_GL=backend, PYOPENGL_PLATFORM=backend)
        os.execve(sys.executable, [sys.executable, "-m", "mexone", *argv], env)


@dataclass(frozen=True)
class Camera:
    """Follows the robot (track) or looks at the origin; angles in degrees, distance in m. The CLI
    parses `--camera track|fixed|azimuth,elevation,distance` into one (and checks the numbers)."""

    track: bool = True
    azimuth: float = 135.0
    elevation: float = -15.0
    distance: float = 2.2

    def apply(self, cam, data, root_body: int) -> None:
        import mujoco

        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.azimuth, cam.elevation, cam.distance = self.azimuth, self.elevation, self.distance
        cam.lookat[:] = data.xpos[root_body] if self.track else (0.0, 0.0, 0.5)
        if self.track:
            cam.lookat[2] = max(cam.lookat[2], 0.3)


def check_video_path(path: Path) -> None:
    if path.suffix.lower() not in VIDEO_SUFFIXES:
        raise InputError(f"cannot write '{path.suffix or path.name}' video", file=path,
                         hint="name it .mp4 or .gif")


class VideoWriter:
    def __init__(self, path: Path, model, fps: float = 30.0, size: tuple[int, int] = (640, 480)):
        check_video_path(path)
        import imageio.v2 as imageio
        import mujoco

        self.path, self.fps = path, fps
        width, height = size
        self.renderer = mujoco.Renderer(model, height, width)
        self.option = mujoco.MjvOption()
        self.option.geomgroup[:] = 0
        self.option.geomgroup[0] = self.option.geomgroup[1] = 1  # world and visual geometry
        self.camera = mujoco.MjvCamera()
        if path.suffix.lower() == ".gif":
            self.writer = imageio.get_writer(path, mode="I", duration=1.0 / fps, loop=0)
        else:
            self.writer = imageio.get_writer(path, fps=fps, codec="libx264", quality=7,
                                             macro_block_size=8, ffmpeg_log_level="error")
        self.frames = 0

    def capture(self, data, camera: Camera, root_body: int) -> np.ndarray:
        camera.apply(self.camera, data, root_body)
        self.renderer.update_scene(data, self.camera, self.option)
        frame = self.renderer.render()
        self.writer.append_data(frame)
        self.frames += 1
        return frame

    def close(self) -> None:
        self.writer.close()
        self.renderer.close()
