"""Control layer: ros_control YAML, the controller types, the hardware interface, the manager.

The names below are imported when first used: a student's `from mexone.control import
PythonController, Param` (in a controller's own process, control/worker_main.py) loads the
student API and not the manager, the hardware or MuJoCo."""

import importlib

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

_HOMES = {
    "load_control_config": "config", "parse_control_config": "config",
    "CONTROLLER_TYPES": "controllers", "Controller": "controllers", "ControllerType": "controllers",
    "SimHardware": "hardware", "build_actuators": "hardware",
    "BEST_EFFORT": "manager", "STRICT": "manager", "ControllerInfo": "manager",
    "ControllerManager": "manager", "PidArray": "pid",
    "ControlConfig": "spec", "ControllerSpec": "spec", "PidGains": "spec",
    "Param": "student", "PythonController": "student", "State": "student",
}


def __getattr__(name: str):
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'mexone.control' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"mexone.control.{home}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
