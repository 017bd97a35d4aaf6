"""IMU (gazebo_ros_imu_sensor / gazebo_ros_imu): sensor_msgs/Imu in the sensor's frame.

Orientation relative to the world (REP-145), angular velocity, and proper linear acceleration
(MuJoCo's accelerometer: +9.81 m/s^2 up at rest), with Gazebo's noise per axis and covariances
on the message's diagonals (the variance of the declared noise, 0 where there is none).
"""

from __future__ import annotations

import numpy as np

from mexone.bus.msgs import Imu, Quaternion, Vector3
from mexone.description.sensors import IMU_CHANNELS, Noise
from mexone.sensors.base import Output, Sensor, topic_name
from mexone.sensors.noise import NoiseModel

__all__ = ["ImuSensor"]


class ImuSensor(Sensor):
    def __post_init__(self) -> None:
        model = self.sim.model
        name = self.spec.name
        self.acc = int(model.sensor_adr[model.sensor(f"{name}/acc").id])
        self.gyro = int(model.sensor_adr[model.sensor(f"{name}/gyro").id])
        self.quat = int(model.sensor_adr[model.sensor(f"{name}/quat").id])
        self.noise = NoiseModel([self.spec.noise.get(c, Noise()) for c in IMU_CHANNELS], name)
        var = self.noise.variance
        self.gyro_cov = [var[0], 0.0, 0.0, 0.0, var[1], 0.0, 0.0, 0.0, var[2]]
        self.acc_cov = [var[3], 0.0, 0.0, 0.0, var[4], 0.0, 0.0, 0.0, var[5]]
        self.outputs = [Output(topic_name(self.namespace, self.spec.topic or self.spec.name), Imu)]

    def read(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(w x y z orientation, angular velocity, linear acceleration), noise added."""
        data = self.measure.data()
        gyro, acc = data[self.gyro:self.gyro + 3], data[self.acc:self.acc + 3]
        if self.noise.active:
            values = self.noise.apply(np.concatenate((gyro, acc)))
            gyro, acc = values[:3], values[3:]
        return data[self.quat:self.quat + 4].copy(), gyro.copy(), acc.copy()

    def publish(self, sim) -> None:
        quat, gyro, acc = self.read()
        msg = Imu(self.header(), Quaternion(quat[1], quat[2], quat[3], quat[0]), [0.0] * 9,
                  Vector3(*gyro.tolist()), list(self.gyro_cov),
                  Vector3(*acc.tolist()), list(self.acc_cov))
        self.bus.publish(self.outputs[0].topic, msg)
