"""What a controller YAML says, as plain data: gains, one controller's spec, the whole config.

Kept apart from the YAML reader (config.py) and the controller classes (controllers/) so both can
use these types without importing each other.
"""

from __future__ import annotations

import builtins
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mexone.ranges import GAIN_D, GAIN_I, GAIN_P, I_CLAMP, number_text

if TYPE_CHECKING:
    from mexone.control.controllers import ControllerInterface

__all__ = ["PidGains", "ControllerSpec", "ControlConfig", "controller_name", "joint_label",
           "POSITION_SUFFIX"]

POSITION_SUFFIX = "_position_controller"


def controller_name(joint: str) -> str:
    """The position controller of one joint, named as the seed's YAML names it."""
    return joint + POSITION_SUFFIX


def joint_label(controller: str) -> str:
    """A controller's name without that convention's suffix (l_knee_position_controller ->
    l_knee), for labels; other names unchanged."""
    return controller.removesuffix(POSITION_SUFFIX)


@dataclass(frozen=True)
class PidGains:
    """control_toolbox::Pid parameters; i_clamp 0 means no integral action, as in ROS."""

    p: float
    i: float = 0.0
    d: float = 0.0
    i_clamp_min: float = 0.0
    i_clamp_max: float = 0.0
    antiwindup: bool = False

    def problem(self) -> str | None:
        """What is wrong with these gains for a controller, or None (the one rule, used by the
        manager for live changes and by the YAML checks)."""
        values = {"p": self.p, "i": self.i, "d": self.d, "i_clamp_min": self.i_clamp_min,
                  "i_clamp_max": self.i_clamp_max}
        bad = [k for k, v in values.items() if not math.isfinite(v)]
        if bad:
            return f"{', '.join(bad)} not finite"
        negative = [k for k in ("p", "i", "d") if values[k] < 0]
        if negative:
            return f"negative {', '.join(negative)} (a PID gain < 0 pushes away from the setpoint)"
        for key, valid in (("p", GAIN_P), ("i", GAIN_I), ("d", GAIN_D), ("i_clamp_min", I_CLAMP),
                           ("i_clamp_max", I_CLAMP)):
            if not valid.contains(values[key]):
                return f"{key} {number_text(values[key])} must be {valid.describe()}"
        if self.i_clamp_min > self.i_clamp_max:
            return (f"i_clamp_min {number_text(self.i_clamp_min)} > i_clamp_max "
                    f"{number_text(self.i_clamp_max)}")
        return None

    @property
    def integrates(self) -> bool:
        """Whether the I term can ever act (ROS: i != 0 and a non-zero clamp)."""
        return self.i != 0 and (self.i_clamp_min != 0 or self.i_clamp_max != 0)


@dataclass(frozen=True)
class ControllerSpec:
    name: str
    type: str
    joints: tuple[str, ...] = ()
    pid: PidGains | None = None
    publish_rate: float | None = None
    line: int | None = None
    gains: dict[str, PidGains] | None = None  # per joint (joint_trajectory_controller's gains:)
    ideal_servo: bool = False  # teleport the joint as Gazebo 7's position interface did
    source: Path | None = None
    # a student's Python controller (mexone.control.resolve.Plugin): its class, parameters and
    # running settings; None for the shipped types
    plugin: Any = field(default=None, compare=False, repr=False)

    @property
    def kind(self) -> str:
        """position, velocity, effort, trajectory, state (from the controller registry) or
        python (a student's controller): control/'s own label; front ends ask the class's
        capabilities (`controller_class`)."""
        return self.controller_class.kind

    @property
    def controller_class(self) -> builtins.type[ControllerInterface]:
        """The ControllerInterface class that runs this entry (the registry's, or the Python
        controllers' runner): its capabilities say what it can do before it is loaded."""
        from mexone.control.controllers import PythonRunner, controller_type

        return PythonRunner if self.plugin is not None else controller_type(self.type).cls

    @property
    def interface(self) -> str:
        """The hardware interface its type claims."""
        if self.plugin is not None:
            return self.plugin.interface
        from mexone.control.controllers import controller_type

        return controller_type(self.type).interface


@dataclass
class ControlConfig:
    namespace: str | None
    controllers: dict[str, ControllerSpec] = field(default_factory=dict)
    pid_gains: dict[str, PidGains] = field(default_factory=dict)  # gazebo_ros_control/pid_gains
    source: Path | None = None
    # the file as `rosparam load` puts it on the parameter server (routines' get_param reads it)
    parameters: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)
