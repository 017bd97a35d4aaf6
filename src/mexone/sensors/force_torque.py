"""Force-torque sensor on a joint (SDF force_torque / gazebo_ros_ft_sensor; ros2_control's
ForceTorqueSensor + force_torque_sensor_broadcaster): geometry_msgs/WrenchStamped.

Sign and frame, as SDF defines them: `measure_direction` parent_to_child is the wrench the parent
link applies to the child through the joint (what MuJoCo's force and torque sensors measure, and
what gazebo_ros_ft_sensor publishes); child_to_parent (SDF's default) is its opposite. `frame`
child (default) expresses it in the child link's frame at the joint, parent in the parent link's
frame at the joint, sensor in the sensor's <pose> frame at the sensor's origin. A robot standing
on an ankle sensor therefore reads +M g (the weight above the ankle) along the child's z with
child_to_parent, and -M g with parent_to_child.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from mexone.bus.msgs import Vector3, Wrench, WrenchStamped
from mexone.description.model import Pose
from mexone.description.sensors import Noise
from mexone.description.transforms import rpy_to_matrix
from mexone.sensors.base import Sensor, register_sensor
from mexone.sensors.build import add_mujoco_sensors, add_site, site_name
from mexone.sensors.noise import NoiseModel

__all__ = ["ForceTorqueSensor", "ForceTorqueState"]

_CHANNELS = tuple(f"{g}/{a}" for g in ("force", "torque") for a in "xyz")


@dataclass
class ForceTorqueState:
    """ros2_control's force-torque state interfaces, as the sensor reports them (its frame,
    measure direction and noise)."""

    force: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """N"""
    torque: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """N m"""


@register_sensor("force_torque")
class ForceTorqueSensor(Sensor):
    state_type = ForceTorqueState
    message_type = WrenchStamped
    broadcaster = "force_torque_sensor_broadcaster"
    plot = {"force": "N"}
    pane = ("force-torque sensors, Fz", "force/z")

    @classmethod
    def build(cls, spec, body, sensor, robot) -> None:
        site = add_site(body, sensor, Pose())  # at the joint, in the child's frame
        add_mujoco_sensors(spec, sensor, mujoco.mjtObj.mjOBJ_SITE, site,
                           (("force", mujoco.mjtSensor.mjSENS_FORCE),
                            ("torque", mujoco.mjtSensor.mjSENS_TORQUE)))

    def setup(self) -> None:
        model, robot = self.sim.model, self.sim.robot
        name = self.spec.name
        self.force = int(model.sensor_adr[model.sensor(f"{name}/force").id])
        self.torque = int(model.sensor_adr[model.sensor(f"{name}/torque").id])
        self.site = model.site(site_name(self.spec)).id
        joint = robot.joints[self.spec.joint]
        self.parent_body = self.sim.compiled.bodies.get(joint.parent)
        self.noise = NoiseModel([self.spec.noise.get(c, Noise()) for c in _CHANNELS], name)
        spec = self.spec
        self._sign = -1.0 if spec.measure_direction == "child_to_parent" else 1.0
        self._sensor_rot = rpy_to_matrix(spec.pose.rpy).T if spec.ft_frame == "sensor" else None
        self._sensor_offset = np.asarray(spec.pose.xyz, dtype=float)
        self._to_parent = spec.ft_frame == "parent" and self.parent_body is not None

    @property
    def frame(self) -> str:
        if self.spec.frame:
            return self.spec.frame
        if self.spec.ft_frame == "parent":
            return self.sim.robot.joints[self.spec.joint].parent
        return self.link

    def parent_on_child_world(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(force, torque about the joint, joint position), world frame, noise-free: the wrench
        the parent applies to the child."""
        data = self.measure.data()
        rot = self.sim.data.site_xmat[self.site].reshape(3, 3)
        return (rot @ data[self.force:self.force + 3], rot @ data[self.torque:self.torque + 3],
                self.sim.data.site_xpos[self.site].copy())

    def read(self, state: ForceTorqueState) -> None:
        data = self.measure.data()
        force, torque = data[self.force:self.force + 3], data[self.torque:self.torque + 3]
        if self._to_parent:
            rot = self.sim.data.xmat[self.parent_body].reshape(3, 3).T \
                @ self.sim.data.site_xmat[self.site].reshape(3, 3)
            force, torque = rot @ force, rot @ torque
        elif self._sensor_rot is not None:
            torque = torque - np.cross(self._sensor_offset, force)  # about the sensor's origin
            force, torque = self._sensor_rot @ force, self._sensor_rot @ torque
        if self.noise.active:
            values = self.noise.apply(np.concatenate((force, torque)) * self._sign)
            state.force[:], state.torque[:] = values[:3], values[3:]
        else:
            np.multiply(force, self._sign, out=state.force)
            np.multiply(torque, self._sign, out=state.torque)

    def message(self, state: ForceTorqueState) -> WrenchStamped:
        return WrenchStamped(self.header(), Wrench(Vector3(*state.force.tolist()),
                                                   Vector3(*state.torque.tolist())))
