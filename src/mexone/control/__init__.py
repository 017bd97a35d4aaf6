"""Control layer: ros_control YAML, the controller types, the hardware interface, the manager."""

from mexone.control.config import load_control_config, parse_control_config
from mexone.control.controllers import CONTROLLER_TYPES, Controller, ControllerType
from mexone.control.hardware import SimHardware, build_actuators
from mexone.control.manager import BEST_EFFORT, STRICT, ControllerInfo, ControllerManager
from mexone.control.pid import PidArray
from mexone.control.spec import ControlConfig, ControllerSpec, PidGains
from mexone.control.student import Param, PythonController, State

__all__ = [
    "CONTROLLER_TYPES",
    "Controller",
    "ControllerType",
    "ControlConfig",
    "ControllerSpec",
    "PidGains",
    "load_control_config",
    "parse_control_config",
    "ControllerInfo",
    "ControllerManager",
    "STRICT",
    "BEST_EFFORT",
    "SimHardware",
    "build_actuators",
    "PidArray",
    "PythonController",
    "Param",
    "State",
]
