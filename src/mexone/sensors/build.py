"""The sensors' part of the MuJoCo model: a site per IMU and force-torque sensor with MuJoCo's own
sensors on it, and a MuJoCo camera per RGB or depth camera (a physics.compile SpecEdit).

MuJoCo computes these only when asked (the suite turns its per-step sensor pass off and asks at
each sensor's update), so a declared sensor nobody reads costs nothing.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mexone.description.model import Pose, RobotModel
from mexone.description.sensors import SensorSpec
from mexone.description.transforms import rpy_to_matrix
from mexone.errors import ModelError

__all__ = ["build_sensors", "sensor_link", "site_name", "camera_name", "OPTICAL_FROM_LINK"]

# A Gazebo camera looks along its link's +x with +z up; MuJoCo's looks along -z with +y up.
# Columns: the MuJoCo camera's x (right), y (up), z (back) in the link frame.
OPTICAL_FROM_LINK = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def site_name(spec: SensorSpec) -> str:
    return f"sensor/{spec.name}"


def camera_name(spec: SensorSpec) -> str:
    return f"sensor/{spec.name}"


def sensor_link(robot: RobotModel, spec: SensorSpec) -> str:
    """The link a sensor sits on (a force-torque sensor: its joint's child), checked."""
    if spec.type == "force_torque":
        joint = robot.joints.get(spec.joint or "")
        if joint is None:
            raise ModelError(f"force_torque sensor '{spec.name}' names joint '{spec.joint}', which "
                             "the robot does not have", file=robot.source, line=spec.line,
                             hint="joints: " + ", ".join(robot.joints))
        return joint.child
    if spec.link not in robot.links or spec.link == "world":
        raise ModelError(f"sensor '{spec.name}' names link '{spec.link}', which the robot does "
                         "not have", file=robot.source, line=spec.line,
                         hint="links: " + ", ".join(n for n in robot.links if n != "world"))
    return spec.link


def _quat(rotation: np.ndarray) -> np.ndarray:
    out = np.zeros(4)
    mujoco.mju_mat2Quat(out, np.ascontiguousarray(rotation).ravel())
    return out


def _add_sensor(spec: mujoco.MjSpec, name: str, kind: mujoco.mjtSensor, site: str) -> None:
    spec.add_sensor(name=name, type=kind, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=site)


def build_sensors(spec: mujoco.MjSpec, robot: RobotModel) -> None:
    """A physics.compile SpecEdit for every sensor the robot declares."""
    for sensor in robot.sensors:
        link = sensor_link(robot, sensor)
        body = spec.body(link)
        if body is None:
            raise ModelError(f"sensor '{sensor.name}' sits on link '{link}', which has no body in "
                             "the simulated model", file=robot.source, line=sensor.line)
        pose = sensor.pose if sensor.type != "force_torque" else Pose()  # FT: at the joint
        rotation = rpy_to_matrix(pose.rpy)
        if sensor.type in ("imu", "force_torque"):
            site = body.add_site(name=site_name(sensor), pos=pose.xyz, quat=_quat(rotation))
            site.group = 5  # hidden in MuJoCo's viewers by default
            kinds = {"imu": (("acc", mujoco.mjtSensor.mjSENS_ACCELEROMETER),
                             ("gyro", mujoco.mjtSensor.mjSENS_GYRO),
                             ("quat", mujoco.mjtSensor.mjSENS_FRAMEQUAT)),
                     "force_torque": (("force", mujoco.mjtSensor.mjSENS_FORCE),
                                      ("torque", mujoco.mjtSensor.mjSENS_TORQUE))}[sensor.type]
            for suffix, kind in kinds:
                _add_sensor(spec, f"{sensor.name}/{suffix}", kind, site.name)
        elif sensor.type in ("camera", "depth"):
            cam = body.add_camera(name=camera_name(sensor), pos=pose.xyz,
                                  quat=_quat(rotation @ OPTICAL_FROM_LINK))
            cam.fovy = float(np.degrees(sensor.camera.vertical_fov))  # MuJoCo: degrees, always
