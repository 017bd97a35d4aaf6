"""Control layer: ros_control YAML, the controller types, the hardware interface, the manager.

The names below are imported when first used: a student's `from mexone.control import
PythonController, Param` (in a controller's own process, control/worker_main.py) loads the
student API and not the manager, the hardware or MuJoCo."""

import importlib

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

_HOMES = {
    "load_control_config": "config", "parse_control_config": "config",
    "ControllerInterface": "controllers", "ControllerType": "controllers",
    "CONTROLLER_TYPES": "controllers",
    "SimHardware": "hardware", "build_actuators": "hardware",
    "BEST_EFFORT": "manager", "STRICT": "manager", "ControllerInfo": "manager",
    "ControllerManager": "manager", "PidArray": "pid",
    "ControlConfig": "spec", "ControllerSpec": "spec", "PidGains": "spec",
    "Param": "student", "PythonController": "student", "State": "student",
}


def __getattr__(name: str) -> object:
    """Each name from its module when first used. The former names (issue 40), for one release:
    `Controller` (the ros_control base, not the student's class `mexone.Controller`) with a
    warning; CONTROLLER_TYPES, STRICT and BEST_EFFORT live in their modules
    (mexone.control.controllers, mexone.control.manager)."""
    if name == "Controller":
        from mexone.errors import warn_renamed

        warn_renamed("mexone.control.Controller", "mexone.control.ControllerInterface")
        return __getattr__("ControllerInterface")
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"mexone.control.{home}"), name)
    if name in __all__:
        globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
