"""Force-torque sensor on a joint (SDF force_torque / gazebo_ros_ft_sensor):
geometry_msgs/WrenchStamped.

Sign and frame, as SDF defines them: `measure_direction` parent_to_child is the wrench the parent
link applies to the child through the joint (what MuJoCo's force and torque sensors measure, and
what gazebo_ros_ft_sensor publishes); child_to_parent (SDF's default) is its opposite. `frame`
child (default) expresses it in the child link's frame at the joint, parent in the parent link's
frame at the joint, sensor in the sensor's <pose> frame at the sensor's origin. A robot standing
on an ankle sensor therefore reads +M g (the weight above the ankle) along the child's z with
child_to_parent, and -M g with parent_to_child.
"""

from __future__ import annotations

import numpy as np

from mexone.bus.msgs import Vector3, Wrench, WrenchStamped
from mexone.description.sensors import Noise
from mexone.description.transforms import rpy_to_matrix
from mexone.sensors.base import Output, Sensor, topic_name
from mexone.sensors.build import site_name
from mexone.sensors.noise import NoiseModel

__all__ = ["ForceTorqueSensor"]

_CHANNELS = tuple(f"{g}/{a}" for g in ("force", "torque") for a in "xyz")


class ForceTorqueSensor(Sensor):
    def __post_init__(self) -> None:
        model, robot = self.sim.model, self.sim.robot
        name = self.spec.name
        self.force = int(model.sensor_adr[model.sensor(f"{name}/force").id])
        self.torque = int(model.sensor_adr[model.sensor(f"{name}/torque").id])
        self.site = model.site(site_name(self.spec)).id
        joint = robot.joints[self.spec.joint]
        self.parent_body = self.sim.compiled.bodies.get(joint.parent)
        self.noise = NoiseModel([self.spec.noise.get(c, Noise()) for c in _CHANNELS], name)
        self.outputs = [Output(topic_name(self.namespace, self.spec.topic or name), WrenchStamped)]

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

    def read(self) -> tuple[np.ndarray, np.ndarray]:
        """(force, torque) as the sensor reports them: its frame, direction, noise."""
        data = self.measure.data()
        force, torque = data[self.force:self.force + 3].copy(), data[self.torque:self.torque + 3].copy()
        spec = self.spec
        if spec.ft_frame == "parent" and self.parent_body is not None:
            rot = self.sim.data.xmat[self.parent_body].reshape(3, 3).T \
                @ self.sim.data.site_xmat[self.site].reshape(3, 3)
            force, torque = rot @ force, rot @ torque
        elif spec.ft_frame == "sensor":
            rot = rpy_to_matrix(spec.pose.rpy)
            offset = np.asarray(spec.pose.xyz)  # the sensor's origin, in the child frame
            torque = torque - np.cross(offset, force)  # about the sensor's origin
            force, torque = rot.T @ force, rot.T @ torque
        if spec.measure_direction == "child_to_parent":
            force, torque = -force, -torque
        if self.noise.active:
            values = self.noise.apply(np.concatenate((force, torque)))
            force, torque = values[:3], values[3:]
        return force, torque

    def publish(self, sim) -> None:
        force, torque = self.read()
        msg = WrenchStamped(self.header(), Wrench(Vector3(*force.tolist()), Vector3(*torque.tolist())))
        self.bus.publish(self.outputs[0].topic, msg)
