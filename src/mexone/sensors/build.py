"""The sensors' part of the MuJoCo model (a physics.compile SpecEdit): each declared sensor's
plug-in adds what it needs (`Sensor.build`): a site with MuJoCo's own sensors on it for an IMU
or a force-torque sensor, a MuJoCo camera for an RGB or depth camera.

MuJoCo computes these only when asked (the suite turns its per-step sensor pass off and asks at
each sensor's update), so a declared sensor nobody reads costs nothing.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mexone.description.findings import Finding
from mexone.description.model import Pose, RobotModel
from mexone.description.sensors import SensorSpec
from mexone.description.transforms import rpy_to_matrix
from mexone.errors import InputError, ModelError
from mexone.sensors.base import ENTRY_POINT_GROUP, sensor_type, sensor_types

__all__ = ["build_sensors", "lint_sensors", "sensor_link", "site_name", "camera_name", "add_site",
           "add_mujoco_sensors", "OPTICAL_FROM_LINK", "quat"]

# A Gazebo camera looks along its link's +x with +z up; MuJoCo's looks along -z with +y up.
# Columns: the MuJoCo camera's x (right), y (up), z (back) in the link frame.
OPTICAL_FROM_LINK = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def site_name(spec: SensorSpec) -> str:
    return f"sensor/{spec.name}"


def camera_name(spec: SensorSpec) -> str:
    return f"sensor/{spec.name}"


def sensor_link(robot: RobotModel, spec: SensorSpec) -> str:
    """The link a sensor sits on (a sensor on a joint, as force-torque: the joint's child),
    checked."""
    if spec.joint is not None or spec.type == "force_torque":
        joint = robot.joints.get(spec.joint or "")
        if joint is None:
            raise ModelError(f"{spec.type} sensor '{spec.name}' names joint '{spec.joint}', which "
                             "the robot does not have", file=robot.source, line=spec.line,
                             hint="joints: " + ", ".join(robot.joints))
        return joint.child
    if spec.link not in robot.links or spec.link == "world":
        raise ModelError(f"sensor '{spec.name}' names link '{spec.link}', which the robot does "
                         "not have", file=robot.source, line=spec.line,
                         hint="links: " + ", ".join(n for n in robot.links if n != "world"))
    return spec.link


def quat(rotation: np.ndarray) -> np.ndarray:
    """MuJoCo's (w, x, y, z) of a rotation matrix."""
    out = np.zeros(4)
    mujoco.mju_mat2Quat(out, np.ascontiguousarray(rotation).ravel())
    return out


def add_site(body: mujoco.MjsBody, sensor: SensorSpec, pose: Pose | None = None) -> str:
    """A hidden site for `sensor` on `body` at `pose` (default: the sensor's own); its name."""
    pose = sensor.pose if pose is None else pose
    site = body.add_site(name=site_name(sensor), pos=pose.xyz,
                         quat=quat(rpy_to_matrix(pose.rpy)))
    site.group = 5  # hidden in MuJoCo's viewers by default
    return site.name


def add_mujoco_sensors(spec: mujoco.MjSpec, sensor: SensorSpec, objtype: mujoco.mjtObj,
                       objname: str, kinds: tuple[tuple[str, mujoco.mjtSensor], ...]) -> None:
    """MuJoCo sensors named `<sensor>/<suffix>` on one object (read back with `Measure`)."""
    for suffix, kind in kinds:
        spec.add_sensor(name=f"{sensor.name}/{suffix}", type=kind, objtype=objtype,
                        objname=objname)


def lint_sensors(robot: RobotModel) -> list[Finding]:
    """What `mexone check` says about the declared sensors (the rules that need the sensor
    plug-ins, above the description layer): a type no plug-in simulates is an error."""
    known = sensor_types()
    return [Finding("sensor-type-unknown", "error", f'sensor "{s.name}"',
                    f"mexone does not simulate sensor type '{s.type}' (types: "
                    f"{', '.join(sorted(known))}; a package adds one through the '{ENTRY_POINT_GROUP}' "
                    "entry points)", s.line)
            for s in robot.sensors if s.type not in known]


def build_sensors(spec: mujoco.MjSpec, robot: RobotModel) -> None:
    """A physics.compile SpecEdit: every declared sensor's plug-in edits the spec."""
    for sensor in robot.sensors:
        link = sensor_link(robot, sensor)
        body = spec.body(link)
        if body is None:
            raise ModelError(f"sensor '{sensor.name}' sits on link '{link}', which has no body in "
                             "the simulated model", file=robot.source, line=sensor.line)
        try:
            cls = sensor_type(sensor.type)
        except InputError as exc:
            raise ModelError(f"sensor '{sensor.name}': {exc.what}", file=robot.source,
                             line=sensor.line, hint=exc.hint) from None
        cls.build(spec, body, sensor, robot)
