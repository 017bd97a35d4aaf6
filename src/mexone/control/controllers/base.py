"""ControllerInterface: what every ros_control controller type shares, and the registry of types.

A controller claims joints, buffers the latest command from its topic (`on_command`, any thread:
subscribers only buffer), and in `update` (the simulation thread, inside the manager's
read -> update -> write loop) turns it into joint commands on the hardware. Front ends read
what they need from the attributes here (`joints`, `setpoint`, `gains`, `unit`,
`command_range`) and ask its capabilities (`holds_position`, `takes_trajectories`,
`tracks_position`, `drives_joints`, `tunable`, `reloadable`) what it can do: never its `kind`
string, its class or its type name.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from mexone.bus.msgs import Float64, Float64MultiArray, Header, JointControllerState
from mexone.bus.topics import Bus
from mexone.control.hardware import SimHardware
from mexone.control.spec import ControllerSpec, PidGains
from mexone.errors import InputError
from mexone.physics.simulation import Simulation
from mexone.ranges import number_text

__all__ = ["ControllerInterface", "ControllerType", "ControllerContext", "CONTROLLER_TYPES", "register",
           "controller_type"]

log = logging.getLogger("mexone.control")


@dataclass(frozen=True)
class ControllerType:
    """One ros_control type name: the class that implements it and the interface it claims."""

    name: str  # e.g. "effort_controllers/JointPositionController"
    cls: type[ControllerInterface]
    interface: str  # hardware_interface it claims, "" for state controllers
    single_joint: bool  # `joint:` (True) or `joints:` (the JointGroup* and trajectory types)

    @property
    def kind(self) -> str:
        """The class's label (position, velocity, effort, trajectory, state): control/'s own; front ends ask
        its capabilities."""
        return self.cls.kind


CONTROLLER_TYPES: dict[str, ControllerType] = {}  # the registry: filled by register()


def register(name: str, interface: str,
             single_joint: bool = True) -> Callable[[type[ControllerInterface]], type[ControllerInterface]]:
    """Class decorator: `cls` implements ros_control type `name`."""

    def add(cls: type[ControllerInterface]) -> type[ControllerInterface]:
        CONTROLLER_TYPES[name] = ControllerType(name, cls, interface, single_joint)
        return cls

    return add


def controller_type(name: str) -> ControllerType:
    try:
        return CONTROLLER_TYPES[name]
    except KeyError:
        raise InputError(f"unknown controller type '{name}'",
                         hint="valid types: " + ", ".join(sorted(CONTROLLER_TYPES))) from None


@dataclass
class ControllerContext:
    """What the manager hands every controller (ros2_control: the node and the interfaces)."""

    sim: Simulation
    hw: SimHardware
    bus: Bus
    namespace: str
    pid_gains: dict[str, PidGains]  # gazebo_ros_control/pid_gains/<joint>
    sensors: Callable[[], Mapping[str, Any]] | None = None  # state.sensors of Python controllers
    faults: list[str] = field(default_factory=list)  # controllers that faulted this cycle


class ControllerInterface:
    """ros_control's controller interface: the base of every controller type (a shipped
    ros_controllers type or the runner of a Python controller), which the manager loads, starts,
    updates and stops (see the module's doc). Not the student's class: that is
    `mexone.control.PythonController` (`mexone.Controller`)."""

    kind: ClassVar[str] = ""  # position, velocity, effort, trajectory, state: control/'s own label
    unit: str = ""  # of its commands: rad, rad/s, N m (a class's, or per instance: a Python one's)
    sliders: ClassVar[bool] = True  # a GUI slider per joint makes sense
    # ----- capabilities: what front ends ask of a controller ----------------------------------
    holds_position: ClassVar[bool] = False  # takes joint-position setpoints (`command`) and holds them
    takes_trajectories: ClassVar[bool] = False  # follows control_msgs trajectories (FollowJointTrajectory)
    tracks_position: ClassVar[bool] = False  # its reference is a joint position (either of the above)
    drives_joints: ClassVar[bool] = True  # commands its joints (a state broadcaster does not)
    reloadable: ClassVar[bool] = False  # its code can be imported again in place (`reload`)

    def __init__(self, spec: ControllerSpec, ctx: ControllerContext) -> None:
        self.spec = spec
        self.name = spec.name
        self.type = self.type_of(spec)
        self.ctx = ctx
        self.hw = ctx.hw
        self.joints = list(spec.joints)
        self.rows = self.hw.rows(self.joints) if self.joints else np.zeros(0, dtype=int)
        self.running = False
        # the command topic's message class (None: it takes none, as a Python controller)
        self.msg_type: type | None = Float64 if self.type.single_joint else Float64MultiArray
        self._pending: Any = None  # the latest command (values() made it), for the next update
        self.every_period = False  # the manager's: update runs every period (periodic or timed)
        self._warned: set[str] = set()

    @classmethod
    def type_of(cls, spec: ControllerSpec) -> ControllerType:
        """The registry entry of `spec`'s type (a student's type overrides this)."""
        return controller_type(spec.type)

    # ----- what front ends read ---------------------------------------------------------------
    @property
    def timed(self) -> bool:
        """Whether it keeps its own update_rate (the manager marks it `due`)."""
        return False

    @property
    def interface(self) -> str:
        """The hardware interface it claims (EffortJointInterface, ...; "" for a state broadcaster)."""
        return self.type.interface

    @property
    def setpoint(self) -> np.ndarray:
        """What each joint is commanded now, in `unit`."""
        return np.zeros(len(self.rows))

    @property
    def gains(self) -> list[PidGains] | None:
        """PID gains per joint, if this controller has any to tune."""
        return None

    @property
    def tunable(self) -> bool:
        """Whether it has PID gains to retune live (`set_gains`)."""
        return self.gains is not None

    def declared_params(self) -> dict[str, Any]:
        """Its live parameters by name (`mexone.control.Param`), set with `set_param`; none for
        the shipped types, whose PID gains are `gains`."""
        return {}

    @property
    def params(self) -> dict[str, Any]:
        """Its declared parameters' values now."""
        return {}

    @property
    def code_file(self) -> str | None:
        """The file its code was imported from, if it is a user's (a Python controller)."""
        return None

    def set_gains(self, gains: Sequence[PidGains]) -> None:
        """Retune live: one PidGains per joint (a controller without gains refuses)."""
        raise InputError(f"{self.name} has no PID gains to set")

    def command_range(self, index: int) -> tuple[float, float]:
        """The commandable range of joint `index` (for sliders), in `unit`."""
        return -1.0, 1.0

    @property
    def periodic(self) -> bool:
        """Whether update must run every control period (not only when a command arrives)."""
        return False

    @property
    def has_state(self) -> bool:
        """Whether it publishes control_msgs/JointControllerState on `<name>/state` (the
        single-joint position and velocity controllers of ros_controllers do)."""
        return False

    def state_message(self, dt: float) -> JointControllerState:
        """The controller's `state` message now (simulation thread; stamp set by the caller)."""
        raise InputError(f"{self.name} publishes no state")

    def _state(self, set_point: float | np.ndarray, value: float | np.ndarray,
               value_dot: float | np.ndarray, dt: float) -> JointControllerState:
        row = int(self.rows[0])
        gains = (self.gains or [PidGains(0.0)])[0]
        return JointControllerState(Header(), float(set_point), float(value), float(value_dot),
                                    float(set_point - value), dt, float(self.hw.effort(row)),
                                    gains.p, gains.i, gains.d, gains.i_clamp_max, gains.antiwindup)

    # ----- lifecycle (simulation thread) ------------------------------------------------------
    def starting(self, t: float) -> None:
        """ros_control's starting(): the controller is about to run (its joints hold where they are)."""
        self._pending = None

    def stopping(self) -> None:
        """ros_control's stopping(): its joints are released (the motors apply nothing)."""
        self.hw.release(self.rows)

    def update(self, t: float, dt: float) -> None:
        """One cycle of the loop (simulation thread): apply the command buffered since the last one."""
        pending, self._pending = self._pending, None
        if pending is not None:
            self.apply(pending, t)

    def apply(self, values: Any, t: float) -> None:
        """Turn a buffered command into joint commands."""

    # ----- commands (any thread) --------------------------------------------------------------
    def on_command(self, msg: object) -> bool:
        """Check and buffer `msg`; True if there is something for the next update."""
        values = self.values(msg)
        if values is None:
            return False
        self._pending = values
        return True

    def values(self, msg: object) -> Any:
        """The numbers of a command message, or None (warned once) if it cannot be used."""
        if isinstance(msg, Float64):
            values = np.array([msg.data], dtype=float)
        elif isinstance(msg, Float64MultiArray):
            values = np.asarray(msg.data, dtype=float)
        else:
            takes = self.msg_type.__name__ if self.msg_type is not None else "no message"
            raise InputError(f"{self.name} takes {takes}, not {type(msg).__name__}")
        if values.shape != (len(self.rows),):
            self.warn_once("size", f"command has {values.size} values for {len(self.rows)} joints; "
                                   "ignored")
            return None
        if not np.isfinite(values).all():
            shown = ", ".join(number_text(v) for v in values)
            self.warn_once("nan", f"command ({shown}) is not finite; ignored (the "
                                  "simulation never sees a NaN)")
            return None
        return values

    def warn_once(self, key: str, text: str) -> None:
        """Log `text` as this controller's warning, once per `key` (a command stream repeats its mistake)."""
        if key not in self._warned:
            self._warned.add(key)
            log.warning("%s: %s", self.name, text)

    def clamp(self, values: np.ndarray, lower: np.ndarray, upper: np.ndarray, what: str) -> np.ndarray:
        """values within [lower, upper], warning once (naming the joints) when they were not."""
        clamped = np.clip(values, lower, upper)
        if not np.array_equal(clamped, values):
            bad = np.flatnonzero(clamped != values)
            parts = [f"{self.joints[i]} {values[i]:g} -> {clamped[i]:g}" for i in bad]
            self.warn_once(what, f"command beyond the {what}, clamped: {', '.join(parts)}")
        return clamped

    def pid_for(self, joint: str) -> PidGains | None:
        """Gains of one joint: the controller's pid:, its gains:, else gazebo_ros_control's."""
        spec = self.spec
        return (spec.gains or {}).get(joint) or spec.pid or self.ctx.pid_gains.get(joint)


Controller = ControllerInterface  # its name before issue 40, kept for code written against it
