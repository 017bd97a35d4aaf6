"""Sensors declared the Gazebo way (IMU, force-torque, contact, RGB and depth cameras) and the
humanoid's balance quantities (COM, ZMP, support polygon): state interfaces for controllers
(`SensorSuite.states`) and broadcasters publishing on the bus with ROS names and types. A core
layer beside control: it reads the simulation, it never writes it.

Each sensor type is one plug-in (`Sensor` subclass + `register_sensor`), a package's found
through the `mexone.sensors` entry points as controllers and GUI panels are; see docs/sensors.md.
"""

from mexone.sensors.balance import Balance, BalanceState
from mexone.sensors.base import (
    SENSOR_CLASSES,
    Measure,
    Sensor,
    SensorStates,
    register_sensor,
    sensor_type,
    sensor_types,
)
from mexone.sensors.build import build_sensors
from mexone.sensors.camera import CameraSensor
from mexone.sensors.contact import ContactSensor, ContactSensorState
from mexone.sensors.force_torque import ForceTorqueSensor, ForceTorqueState
from mexone.sensors.imu import ImuSensor, ImuState
from mexone.sensors.suite import SensorSuite

__all__ = ["Balance", "BalanceState", "build_sensors", "CameraSensor", "ContactSensor",
           "ContactSensorState", "ForceTorqueSensor", "ForceTorqueState", "ImuSensor", "ImuState",
           "Measure", "Sensor", "SensorStates", "SENSOR_CLASSES", "SensorSuite", "register_sensor",
           "sensor_type", "sensor_types"]
