"""IMU (gazebo_ros_imu_sensor / gazebo_ros_imu; ros2_control's IMUSensor + imu_sensor_broadcaster):
sensor_msgs/Imu in the sensor's frame.

Orientation relative to the world (REP-145), angular velocity, and proper linear acceleration
(MuJoCo's accelerometer: +9.81 m/s^2 up at rest), with Gazebo's noise per axis and covariances
on the message's diagonals (the variance of the declared noise, 0 where there is none).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from mexone.bus.msgs import Header, Imu, Quaternion, Vector3
from mexone.description.model import RobotModel
from mexone.description.sensors import IMU_CHANNELS, Noise, SensorSpec
from mexone.sensors.base import Sensor, register_sensor
from mexone.sensors.build import add_mujoco_sensors, add_site
from mexone.sensors.noise import NoiseModel

__all__ = ["ImuSensor", "ImuState"]


@dataclass(frozen=True)
class ImuState:
    """ros2_control's IMU state interfaces, in the sensor's frame (noise included); read-only
    arrays, valid for the instant."""

    orientation: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))
    """(x, y, z, w) relative to the world"""
    angular_velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """rad/s"""
    linear_acceleration: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """m/s^2, proper acceleration: +g up at rest"""


@register_sensor("imu")
class ImuSensor(Sensor):
    """Gazebo's IMU (with its noise model): state `orientation`, `angular_velocity`,
    `linear_acceleration`; broadcasts sensor_msgs/Imu."""

    state_type = ImuState
    message_type = Imu
    broadcaster = "imu_sensor_broadcaster"
    plot = {"angular_velocity": "rad/s", "linear_acceleration": "m/s²"}
    pane = ("linear acceleration", "linear_acceleration")
    linear = True

    @classmethod
    def build(cls, spec: mujoco.MjSpec, body: mujoco.MjsBody, sensor: SensorSpec,
              robot: RobotModel) -> None:
        site = add_site(body, sensor)
        add_mujoco_sensors(spec, sensor, mujoco.mjtObj.mjOBJ_SITE, site,
                           (("acc", mujoco.mjtSensor.mjSENS_ACCELEROMETER),
                            ("gyro", mujoco.mjtSensor.mjSENS_GYRO),
                            ("quat", mujoco.mjtSensor.mjSENS_FRAMEQUAT)))

    def setup(self) -> None:
        model = self.sim.model
        name = self.spec.name
        acc = int(model.sensor_adr[model.sensor(f"{name}/acc").id])
        gyro = int(model.sensor_adr[model.sensor(f"{name}/gyro").id])
        quat = int(model.sensor_adr[model.sensor(f"{name}/quat").id])
        rows = np.r_[quat + 1:quat + 4, quat, gyro:gyro + 3, acc:acc + 3]  # x y z w, gyro, acc
        self.measure.linear(rows, np.eye(len(rows)), self.bind(
            orientation=slice(0, 4), angular_velocity=slice(4, 7), linear_acceleration=slice(7, 10),
            _rates=slice(4, 10)))
        self.noise = NoiseModel([self.spec.noise.get(c, Noise()) for c in IMU_CHANNELS], name)
        self._needs_read = self.noise.active
        var = self.noise.variance.tolist()
        self.gyro_cov = [var[0], 0.0, 0.0, 0.0, var[1], 0.0, 0.0, 0.0, var[2]]
        self.acc_cov = [var[3], 0.0, 0.0, 0.0, var[4], 0.0, 0.0, 0.0, var[5]]

    _rates: np.ndarray  # bound by setup (Measure.linear): angular velocity and acceleration, 6

    def read(self, state: ImuState) -> None:
        if self.noise.active:  # angular velocity and linear acceleration: one view of 6
            self.noise.add_to(self._rates)

    def message(self, state: ImuState) -> Imu:
        x, y, z, w, gx, gy, gz, ax, ay, az = self._linear_view.tolist()
        self.seq = seq = self.seq + 1
        return Imu(Header(seq, self.measure.stamp(), self._frame_id), Quaternion(x, y, z, w),
                   [0.0] * 9, Vector3(gx, gy, gz), self.gyro_cov[:], Vector3(ax, ay, az),
                   self.acc_cov[:])
