"""Control layer: ros_control YAML, the controller types, the hardware interface, the manager."""

from mexone.control.config import load_control_config, parse_control_config
from mexone.control.controllers import ControllerInterface, ControllerType
from mexone.control.hardware import SimHardware, build_actuators
from mexone.control.manager import ControllerInfo, ControllerManager
from mexone.control.pid import PidArray
from mexone.control.spec import ControlConfig, ControllerSpec, PidGains
from mexone.control.student import Param, PythonController, State

__all__ = [
    "ControllerInterface",
    "ControllerType",
    "ControlConfig",
    "ControllerSpec",
    "PidGains",
    "load_control_config",
    "parse_control_config",
    "ControllerInfo",
    "ControllerManager",
    "SimHardware",
    "build_actuators",
    "PidArray",
    "PythonController",
    "Param",
    "State",
]


def __getattr__(name: str) -> object:
    """The former names (issue 40), for one release with a warning: `Controller` (the
    ros_control base, not the student's class `mexone.Controller`); CONTROLLER_TYPES, STRICT and
    BEST_EFFORT live in their modules (mexone.control.controllers, mexone.control.manager)."""
    if name == "Controller":
        from mexone.errors import warn_renamed

        warn_renamed("mexone.control.Controller", "mexone.control.ControllerInterface")
        return ControllerInterface
    if name in ("CONTROLLER_TYPES", "STRICT", "BEST_EFFORT"):
        from mexone.control import controllers, manager

        return getattr(controllers if name == "CONTROLLER_TYPES" else manager, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
