"""Sensors declared the Gazebo way (IMU, force-torque, contact, RGB and depth cameras) and the
humanoid's balance quantities (COM, ZMP, support polygon), published on the bus with ROS names
and types. A core layer beside control: it reads the simulation, it never writes it."""

from mexone.sensors.balance import Balance, BalanceState
from mexone.sensors.build import build_sensors
from mexone.sensors.camera import CameraSensor
from mexone.sensors.contact import ContactSensor
from mexone.sensors.force_torque import ForceTorqueSensor
from mexone.sensors.imu import ImuSensor
from mexone.sensors.suite import SENSOR_CLASSES, SensorSuite

__all__ = ["Balance", "BalanceState", "build_sensors", "CameraSensor", "ContactSensor",
           "ForceTorqueSensor", "ImuSensor", "SENSOR_CLASSES", "SensorSuite"]
