"""Control layer: ros_control YAML, control_toolbox PID, ros_controllers types, the manager."""

from mexone.control.config import (
    CONTROLLER_TYPES,
    ControlConfig,
    ControllerSpec,
    PidGains,
    load_control_config,
    parse_control_config,
)
from mexone.control.manager import ControllerInfo, ControllerManager
from mexone.control.pid import PidArray

__all__ = [
    "CONTROLLER_TYPES",
    "ControlConfig",
    "ControllerSpec",
    "PidGains",
    "load_control_config",
    "parse_control_config",
    "ControllerInfo",
    "ControllerManager",
    "PidArray",
]
