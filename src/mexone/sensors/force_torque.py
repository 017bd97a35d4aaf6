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

from mexone.bus.msgs import Header, Vector3, Wrench, WrenchStamped
from mexone.description.model import Pose, RobotModel
from mexone.description.sensors import Noise, SensorSpec
from mexone.description.transforms import rpy_to_matrix
from mexone.sensors.base import Sensor, register_sensor
from mexone.sensors.build import add_mujoco_sensors, add_site, site_name
from mexone.sensors.noise import NoiseModel

__all__ = ["ForceTorqueSensor", "ForceTorqueState"]

_CHANNELS = tuple(f"{g}/{a}" for g in ("force", "torque") for a in "xyz")


@dataclass(frozen=True)
class ForceTorqueState:
    """ros2_control's force-torque state interfaces, as the sensor reports them (its frame,
    measure direction and noise)."""

    force: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """N"""
    torque: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """N m"""


@register_sensor("force_torque")
class ForceTorqueSensor(Sensor):
    """Gazebo's force-torque sensor on a joint (in the child, parent or sensor frame, either
    measure direction): state `force`, `torque`; broadcasts geometry_msgs/WrenchStamped."""

    state_type = ForceTorqueState
    message_type = WrenchStamped
    broadcaster = "force_torque_sensor_broadcaster"
    plot = {"force": "N"}
    pane = ("force-torque sensors, Fz", "force/z")
    linear = True

    @classmethod
    def build(cls, spec: mujoco.MjSpec, body: mujoco.MjsBody, sensor: SensorSpec,
              robot: RobotModel) -> None:
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
        joint = robot.joints[self.spec.joint or ""]  # the reader puts every FT sensor on a joint
        self.parent_body = self.sim.compiled.bodies.get(joint.parent)
        self.noise = NoiseModel([self.spec.noise.get(c, Noise()) for c in _CHANNELS], name)
        spec = self.spec
        # what MuJoCo measures (parent on child, child frame at the joint) -> what the sensor
        # reports: a constant linear map (sign; the sensor frame's rotation and offset) and, for
        # the parent frame, a rotation that moves with the joint (read())
        matrix = np.eye(6)
        if spec.ft_frame == "sensor":
            rot_t = rpy_to_matrix(spec.pose.rpy).T
            x, y, z = spec.pose.xyz  # the sensor's origin in the child frame
            skew = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
            matrix = np.block([[rot_t, np.zeros((3, 3))], [-rot_t @ skew, rot_t]])
        if spec.measure_direction == "child_to_parent":
            matrix = -matrix
        rows = np.r_[self.force:self.force + 3, self.torque:self.torque + 3]
        self.measure.linear(rows, matrix, self.bind(
            force=slice(0, 3), torque=slice(3, 6), _force=slice(0, 3), _torque=slice(3, 6)))
        self._to_parent = spec.ft_frame == "parent" and self.parent_body is not None
        self._needs_read = self._to_parent or self.noise.active

    @property
    def frame(self) -> str:
        """The frame_id of its messages: the frame it measures in."""
        if self.spec.frame:
            return self.spec.frame
        if self.spec.ft_frame == "parent":
            return self.sim.robot.joints[self.spec.joint or ""].parent
        return self.link

    def parent_on_child_world(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(force, torque about the joint, joint position), world frame, noise-free: the wrench
        the parent applies to the child."""
        data = self.measure.data()
        rot = self.sim.data.site_xmat[self.site].reshape(3, 3)
        return (rot @ data[self.force:self.force + 3], rot @ data[self.torque:self.torque + 3],
                self.sim.data.site_xpos[self.site].copy())

    _force: np.ndarray  # bound by setup (Measure.linear): writable views behind the state's
    _torque: np.ndarray

    def read(self, state: ForceTorqueState) -> None:
        if self._to_parent:
            data = self.sim.data
            rot = data.xmat[self.parent_body].reshape(3, 3).T @ data.site_xmat[self.site].reshape(3, 3)
            self._force[:] = rot @ self._force  # the writable views behind the state's
            self._torque[:] = rot @ self._torque
        if self.noise.active:
            self.noise.add_to(self._linear_view)

    def message(self, state: ForceTorqueState) -> WrenchStamped:
        fx, fy, fz, tx, ty, tz = self._linear_view.tolist()
        self.seq = seq = self.seq + 1
        return WrenchStamped(Header(seq, self.measure.stamp(), self._frame_id),
                             Wrench(Vector3(fx, fy, fz), Vector3(tx, ty, tz)))
