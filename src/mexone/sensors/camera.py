"""Cameras (gazebo_ros_camera, gazebo_ros_openni_kinect): sensor_msgs/Image, CameraInfo and, for
depth cameras, a 32FC1 depth image in metres and a PointCloud2, all in the camera's optical
frame (REP-103: z forward, x right, y down), rendered offscreen by MuJoCo.

The pinhole model is the renderer's own: square pixels, fx = fy = (width / 2) / tan(hfov / 2),
principal point at the image centre ((width - 1) / 2, (height - 1) / 2 in pixel-centre
coordinates). Gazebo's (width + 1) / 2 is half a pixel off the image it renders; this is not.
Nothing is rendered while nobody subscribes to an image, depth or cloud topic.
"""

from __future__ import annotations

import os
import time

import mujoco
import numpy as np

from mexone.bus.msgs import CameraInfo, Header, Image, PointCloud2, PointField
from mexone.description.model import RobotModel
from mexone.description.sensors import CameraSpec, SensorSpec
from mexone.description.transforms import rpy_to_matrix
from mexone.physics.simulation import Simulation
from mexone.sensors.base import Output, Sensor, register_sensor, topic_name
from mexone.sensors.build import OPTICAL_FROM_LINK, camera_name, quat
from mexone.sensors.noise import NoiseModel

__all__ = ["CameraSensor", "camera_info", "cloud_from_depth"]

_XYZ = [PointField("x", 0, PointField.FLOAT32, 1), PointField("y", 4, PointField.FLOAT32, 1),
        PointField("z", 8, PointField.FLOAT32, 1)]


def camera_info(header: Header, camera: CameraSpec) -> CameraInfo:
    f, cx, cy = camera.focal, (camera.width - 1) / 2.0, (camera.height - 1) / 2.0
    return CameraInfo(header, camera.height, camera.width, "plumb_bob", [0.0] * 5,
                      [f, 0.0, cx, 0.0, f, cy, 0.0, 0.0, 1.0],
                      [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                      [f, 0.0, cx, 0.0, 0.0, f, cy, 0.0, 0.0, 0.0, 1.0, 0.0])


def cloud_from_depth(depth: np.ndarray, camera: CameraSpec) -> np.ndarray:
    """(height, width, 3) points in the optical frame from a depth image (NaN stays NaN)."""
    h, w = depth.shape
    f, cx, cy = camera.focal, (w - 1) / 2.0, (h - 1) / 2.0
    u = np.arange(w, dtype=np.float32)[None, :]
    v = np.arange(h, dtype=np.float32)[:, None]
    return np.stack([(u - cx) * depth / f, (v - cy) * depth / f, depth], axis=-1)


def _release_gl_context() -> None:
    """Unbind the renderer's EGL context from this thread after a frame.

    mujoco.Renderer leaves its context current on the thread that rendered, and EGL refuses to
    make it current anywhere else, so closing (or garbage-collecting) it from another thread
    failed with EGL_BAD_ACCESS. Unbound, it can be freed from any thread.
    """
    if os.environ.get("MUJOCO_GL") != "egl":
        return
    from mujoco import egl

    if egl.EGL_DISPLAY is not None:
        egl.EGL.eglMakeCurrent(egl.EGL_DISPLAY, egl.EGL.EGL_NO_SURFACE, egl.EGL.EGL_NO_SURFACE,
                               egl.EGL.EGL_NO_CONTEXT)


@register_sensor("depth")
@register_sensor("camera")
class CameraSensor(Sensor):
    """An RGB or depth camera: no state interfaces (images are topics, rendered for
    subscribers only)."""

    @classmethod
    def build(cls, spec: mujoco.MjSpec, body: mujoco.MjsBody, sensor: SensorSpec,
              robot: RobotModel) -> None:
        rotation = rpy_to_matrix(sensor.pose.rpy)
        cam = body.add_camera(name=camera_name(sensor), pos=sensor.pose.xyz,
                              quat=quat(rotation @ OPTICAL_FROM_LINK))
        cam.fovy = float(np.degrees((sensor.camera or CameraSpec()).vertical_fov))  # MuJoCo: degrees, always

    def setup(self) -> None:
        spec, ns = self.spec, self.namespace
        self.camera = spec.camera or CameraSpec()  # the reader gives every camera one
        self.cam_id = self.sim.model.camera(camera_name(spec)).id
        topics = {"image": "image_raw", "camera_info": "camera_info"}
        if spec.type == "depth":
            topics |= {"depth": "depth/image_raw", "depth_camera_info": "depth/camera_info",
                       "points": "points"}
        topics |= {k: v for k, v in spec.topics.items() if k in topics}
        base = spec.name if not spec.topics else ""  # no plugin: under the sensor's name
        self.topics = {k: topic_name(ns, f"{base}/{v}" if base else v) for k, v in topics.items()}
        self.outputs = [Output(t, {"camera_info": CameraInfo, "depth_camera_info": CameraInfo,
                                   "points": PointCloud2}.get(k, Image), heavy=True)
                        for k, t in self.topics.items()]  # all for subscribers only
        self._by_key = {k: o for k, o in zip(self.topics, self.outputs, strict=True)}
        self.renderer: mujoco.Renderer | None = None
        self.noise = NoiseModel([self.camera.noise], spec.name)
        self.render_seconds: list[float] = []  # wall time per rendered frame (benchmarks)

    def _renderer(self) -> mujoco.Renderer:
        if self.renderer is None:  # created in the simulation thread, on first use
            self.renderer = mujoco.Renderer(self.sim.model, self.camera.height, self.camera.width)
        return self.renderer

    def render(self, depth: bool) -> np.ndarray:
        """The camera's view now: rgb (h, w, 3) uint8, or depth (h, w) float32 in metres."""
        renderer = self._renderer()
        start = time.perf_counter()
        if depth:
            renderer.enable_depth_rendering()
        try:
            renderer.update_scene(self.sim.data, camera=self.cam_id)
            image = renderer.render()
        finally:
            if depth:
                renderer.disable_depth_rendering()
            _release_gl_context()
        self.render_seconds.append(time.perf_counter() - start)
        if depth:
            image = image.astype(np.float32)
            low, high = self.spec.range or (self.camera.near, self.camera.far)
            image[(image <= max(low, self.camera.near)) | (image >= min(high, self.camera.far))] = np.nan
        elif self.noise.active:
            noisy = self.noise.apply(image.astype(np.float64).ravel() / 255.0)
            image = (np.clip(noisy, 0.0, 1.0) * 255.0).round().astype(np.uint8).reshape(image.shape)
        return image

    def publish(self, sim: Simulation) -> None:
        wants = {k for k, o in self._by_key.items() if self.wanted(o)}
        if not wants:
            return
        stamp = self.header()
        cam = self.camera
        if "image" in wants:
            rgb = self.render(depth=False)
            self.bus.publish(self.topics["image"], Image(stamp, cam.height, cam.width, "rgb8", 0,
                                                         3 * cam.width, rgb.tobytes()))
        if "camera_info" in wants:
            self.bus.publish(self.topics["camera_info"], camera_info(stamp, cam))
        if wants & {"depth", "points"}:
            depth = self.render(depth=True)
            if "depth" in wants:
                self.bus.publish(self.topics["depth"], Image(stamp, cam.height, cam.width, "32FC1",
                                                             0, 4 * cam.width, depth.tobytes()))
            if "points" in wants:
                points = cloud_from_depth(depth, cam).astype(np.float32)
                self.bus.publish(self.topics["points"], PointCloud2(
                    stamp, cam.height, cam.width, list(_XYZ), False, 12, 12 * cam.width,
                    points.tobytes(), False))
        if "depth_camera_info" in wants:
            self.bus.publish(self.topics["depth_camera_info"], camera_info(stamp, cam))

    def close(self) -> None:
        """Release the renderer (its GL context): before the model changes, or at the end."""
        if self.renderer is not None:
            self.renderer.close()
            self.renderer = None
