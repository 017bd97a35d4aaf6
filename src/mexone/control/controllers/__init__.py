"""The ros_controllers types, one module each, and the registry every front end reads.

``CONTROLLER_TYPES`` maps a ros_control type name (what a YAML says) to a ``ControllerType``:
the class, the hardware interface it claims and whether it takes one joint or a list. The YAML
loader, ``mexone check``, the GUI and the ROS bridge all read it; a new type is one module here.
"""

from mexone.control.controllers.base import (
    CONTROLLER_TYPES,
    ControllerContext,
    ControllerInterface,
    ControllerType,
    controller_type,
    register,
)
from mexone.control.controllers.effort import EffortController
from mexone.control.controllers.joint_state import JointStateController
from mexone.control.controllers.position import PositionController
from mexone.control.controllers.python import PythonRunner
from mexone.control.controllers.trajectory import TrajectoryController
from mexone.control.controllers.velocity import VelocityController

__all__ = [
    "CONTROLLER_TYPES",
    "ControllerInterface",
    "ControllerContext",
    "ControllerType",
    "controller_type",
    "register",
    "EffortController",
    "JointStateController",
    "PositionController",
    "PythonRunner",
    "TrajectoryController",
    "VelocityController",
]


def __getattr__(name: str) -> object:
    if name == "Controller":  # the former name (issue 40): one release, with a warning
        from mexone.errors import warn_renamed

        warn_renamed("mexone.control.controllers.Controller", "ControllerInterface")
        return ControllerInterface
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
