"""A student's own controller: `PythonController`, its declared `Param`s and the `State` it reads.

ros_control's controller plug-in, in Python: a class with the lifecycle configure -> activate ->
update (every period, in lockstep with the manager's read -> update -> write) ->
deactivate, claiming one command interface ("effort", "position" or "velocity") on its joints and
reading the joints' state, the whole robot's state, the sensors and the robot's dynamics. The
framework (control/controllers/python.py) does everything around `update`: it builds the
`State`, checks what `update` returns, clamps it and writes it to the hardware, and turns the
student's mistakes (an exception, a NaN, an overrun, an update that never returns) into one line
naming their file and line while the lab runs on. A class the YAML names runs in a process of
its own (control/worker.py); one handed over in Python runs in the lab's.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, cast

import numpy as np
from numpy.typing import ArrayLike

from mexone.errors import InputError, warn_renamed
from mexone.ranges import Range, number_text

if TYPE_CHECKING:
    from mexone.dynamics import Dynamics
    from mexone.sensors import SensorSuite

__all__ = ["PythonController", "Param", "State", "BaseState", "sensor_states", "COMMAND_INTERFACES",
           "declared_lengths", "Exports"]

# command_interface -> ros_control's hardware interface (what a <transmission> offers)
COMMAND_INTERFACES = {"effort": "EffortJointInterface", "position": "PositionJointInterface",
                      "velocity": "VelocityJointInterface"}
_UNITS = {"effort": "N m", "position": "rad", "velocity": "rad/s"}

_MISSING = object()


class Param:
    """A declared parameter: its type comes from the default (float, int, bool or str), numbers
    are checked against [low, high], and the YAML's value (or a live change from the page or
    dynamic_reconfigure) is validated the same way, with the YAML's file:line. Reads as
    `self.<name>` inside the controller."""

    def __init__(self, default: float | int | bool | str, low: float | None = None,
                 high: float | None = None, doc: str = "", unit: str = "",
                 choices: tuple[str, ...] | None = None):
        if not isinstance(default, bool | int | float | str):
            raise TypeError(f"Param default must be a float, int, bool or str, not "
                            f"{type(default).__name__}")
        self.value_type: type = type(default)  # float, int, bool or str
        self.low, self.high, self.doc, self.unit = low, high, doc, unit
        self.choices = tuple(choices) if choices else None
        self.name = ""
        self.default = default
        if self.numeric:
            self.range = Range(self.name or "parameter", unit,
                               -math.inf if low is None else float(low),
                               math.inf if high is None else float(high),
                               integer=self.value_type is int)
            if low is not None and high is not None and low > high:
                raise TypeError(f"Param low {low} > high {high}")
            if not self.range.contains(float(default)):  # a YAML without it would run with it
                raise TypeError(f"Param default {number_text(cast(float, default))} is not "  # numeric
                                f"{self.describe()}")
        elif self.choices is not None and default not in self.choices:
            raise TypeError(f"Param default {default!r} is not {self.describe()}")

    @property
    def kind(self) -> type:
        """The former name of `value_type` (issue 40: `kind` is a controller's family in
        mexone.control); kept for one release, with a warning."""
        warn_renamed("Param.kind", "Param.value_type")
        return self.value_type

    @property
    def numeric(self) -> bool:
        """Whether the parameter is a number (int or float): a page shows it as a number field."""
        return self.value_type in (int, float)

    def __set_name__(self, owner: type | None, name: str) -> None:
        self.name = name
        if self.numeric:
            self.range = Range(name, self.unit, self.range.low, self.range.high,
                               integer=self.value_type is int)

    def __get__(self, obj: PythonController | None, owner: type | None = None) -> Any:
        if obj is None:
            return self
        return obj.params.get(self.name, self.default)

    def __set__(self, obj: PythonController, value: object) -> None:
        obj.params[self.name] = self.check(value)

    def describe(self) -> str:
        """What a valid value is, in words (for errors, the page and `mexone controllers`)."""
        if self.value_type is bool:
            return "true or false"
        if self.value_type is str:
            return "one of " + ", ".join(self.choices) if self.choices else "a string"
        kind = "a whole number" if self.value_type is int else "a finite number"
        parts = []
        if self.low is not None:
            parts.append(f">= {number_text(self.low)}")
        if self.high is not None:
            parts.append(f"<= {number_text(self.high)}")
        unit = f" ({self.unit})" if self.unit else ""
        return f"{kind} {' and '.join(parts)}{unit}".replace("  ", " ").strip()

    def check(self, value: Any, what: str | None = None, **where: Any) -> Any:
        """`value` converted to this parameter's type, or an InputError (one line, located by
        `where`: file=, line=) saying what a valid value is."""
        label = what or self.name
        if self.value_type is bool:
            if isinstance(value, bool):
                return value
        elif self.value_type is str:
            if isinstance(value, str) and (self.choices is None or value in self.choices):
                return value
        elif not isinstance(value, bool) and isinstance(value, int | float | np.integer | np.floating):
            number = float(value)
            if self.range.contains(number):
                return int(number) if self.value_type is int else number
        shown = number_text(value) if isinstance(value, int | float) and not isinstance(value, bool) \
            else repr(value)[:60]
        raise InputError(f"{label} {shown} must be {self.describe()}", **where)


@dataclass
class BaseState:
    """The floating base in the world frame: position (3), quaternion w x y z (4), linear and
    angular velocity (3 each). None on a robot fixed to the world."""

    position: np.ndarray
    quaternion: np.ndarray
    linear_velocity: np.ndarray
    angular_velocity: np.ndarray


def sensor_states(suite: SensorSuite | None) -> Mapping[str, Any]:
    """`state.sensors`: the sensors' state interfaces of `suite` (a mexone.sensors SensorSuite,
    or None), by name (`SensorSuite.states`: each read only when looked up, once an instant)."""
    return {} if suite is None else suite.states


class State:
    """What a controller reads in `update`, filled in the hardware's read phase: `q`, `dq`,
    `effort` of the claimed joints (rad, rad/s, N m: arrays owned by the framework, valid during
    the call: copy what you keep), `all_q`/`all_dq` (MuJoCo's qpos, nq long, and qvel, nv long:
    index qvel-sized vectors with `self.dofs`), `time` (s of sim time), `base` (BaseState or
    None) and `sensors` (name -> the sensor's state: mexone.sensors ImuState, ForceTorqueState,
    ContactSensorState). `base` and `sensors` are computed only when read. `inputs` (name ->
    read-only array) are the chained controllers' exports this controller's YAML binds to its
    declared `inputs` (NaN while the exporter is stopped). Every array is read-only: a
    controller reads the simulation, it never writes it."""

    __slots__ = ("q", "dq", "effort", "time", "_data", "_base_joint", "_sensor_source",
                 "_sensors", "_base", "inputs", "messages", "_all_q", "_all_dq")

    def __init__(self, n: int, data: Any, base_joint: tuple[int, int] | None,
                 sensor_source: Callable[[], Mapping[str, Any]] | None = None) -> None:
        self.q, self.dq, self.effort = np.zeros(n), np.zeros(n), np.zeros(n)
        self.time = 0.0
        self._base_joint = base_joint  # qpos/qvel address of the free joint, or None
        self._sensor_source = sensor_source  # () -> mapping, or None
        self._sensors: Mapping[str, Any] | None = None
        self._base: BaseState | None = None
        self.inputs: Mapping[str, np.ndarray] = {}
        self.messages: Mapping[str, object | None] = {}
        self._bind(data)

    def _bind(self, data: Any) -> None:  # MuJoCo's MjData (untyped) or a stand-in
        """Read from `data` (MuJoCo's MjData, or anything with qpos and qvel arrays): all_q and
        all_dq become read-only views of them."""
        self._data = data
        self._all_q = _read_only(data.qpos if data is not None else np.zeros(0))
        self._all_dq = _read_only(data.qvel if data is not None else np.zeros(0))

    def _refresh(self, time: float) -> None:
        self.time = time
        self._sensors = None
        self._base = None

    @property
    def all_q(self) -> np.ndarray:
        """The whole robot's joint positions (MuJoCo's qpos: the free joint's 7 numbers first on a
        floating robot), not only the controller's; read-only."""
        return self._all_q

    @property
    def all_dq(self) -> np.ndarray:
        """The whole robot's joint velocities (MuJoCo's qvel); read-only."""
        return self._all_dq

    @property
    def base(self) -> BaseState | None:
        """The floating base's pose and twist (a BaseState), or None for a robot fixed to the world."""
        if self._base is None and self._base_joint is not None:
            qa, va = self._base_joint
            q, dq = self._all_q, self._all_dq
            self._base = BaseState(q[qa:qa + 3].copy(), q[qa + 3:qa + 7].copy(),
                                   dq[va:va + 3].copy(), dq[va + 3:va + 6].copy())
        return self._base

    @property
    def sensors(self) -> Mapping[str, Any]:
        """The sensors' state interfaces by name (state.sensors["imu"].orientation, ...)."""
        if self._sensors is None:
            self._sensors = self._sensor_source() if self._sensor_source is not None else {}
        return self._sensors


def strided_view(array: np.ndarray, index: np.ndarray) -> np.ndarray | None:
    """A view of array[index] when the indices are evenly spaced and increasing (a limb's joints
    usually are), else None."""
    if len(index) == 0:
        return None
    if len(index) == 1:
        return array[int(index[0]):int(index[0]) + 1]
    step = int(index[1] - index[0])
    if step <= 0 or not np.array_equal(np.diff(index), np.full(len(index) - 1, step)):
        return None
    return array[int(index[0]):int(index[-1]) + 1:step]


def _read_only(array: np.ndarray) -> np.ndarray:
    view = array.view()
    view.flags.writeable = False
    return view


class PythonController:
    """A controller of your own, run by the controller manager like ros_control's plug-ins.

    Subclass it, set `command_interface`, declare parameters with `Param`, and write `update`.
    Before `configure` the framework sets `name`, `joints`, `dofs` (each joint's index into
    nv-long vectors: columns of M and Jacobians, entries of g), `effort_limits` (each joint's
    URDF effort limit, N m: what the framework clamps to), `params` and `log`; `dynamics`
    is the robot's dynamics at the live state (mexone.dynamics.Dynamics), computed when first
    read in an update. See docs/controllers.md.

    Chained controllers (ros2_control's chaining): `exports` declares the state interfaces this
    controller writes (name -> length; in `update`, `self.exports[name][:] = ...` on the
    framework's arrays, NaN until written), `inputs` those it reads (name -> length), which its
    YAML entry binds to other controllers' exports (`inputs: {tilt: estimator/tilt}`) and
    `state.inputs[name]` shows. The manager updates an exporter before its readers.
    `optional_inputs` names inputs the class can run without: left unbound in the YAML, they are
    absent from `state.inputs` (a walking part computing from the simulator's truth until an
    estimator is chained in).

    Topics: `topics` declares the bus topics this controller takes, name (under the robot's
    namespace: `cmd_vel` is `/<ns>/cmd_vel`, what ROS 1, ROS 2, the page and routines publish)
    -> message class (mexone.bus.msgs). Each update, `state.messages[name]` is the newest
    message that arrived since the last update, or None: nothing of the bus reaches your code
    between updates (no callback, no thread), so it runs the same in the simulation's process
    and in a worker process.
    """

    command_interface: ClassVar[str] = "effort"  # "effort" | "position" | "velocity"
    exports: Any = {}  # the class declares name -> length; an instance holds name -> array
    inputs: ClassVar[Mapping[str, int]] = {}
    optional_inputs: ClassVar[tuple[str, ...]] = ()
    topics: ClassVar[Mapping[str, type]] = {}
    _declared: ClassVar[dict[str, Param]] = {}

    name: str
    joints: list[str]
    dofs: np.ndarray
    effort_limits: np.ndarray
    params: dict[str, Any]
    log: logging.LoggerAdapter[logging.Logger]

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        declared: dict[str, Param] = {}
        for klass in reversed(cls.__mro__):
            for key, value in vars(klass).items():
                if isinstance(value, Param):
                    declared[key] = value
        cls._declared = declared
        if cls.command_interface not in COMMAND_INTERFACES:
            raise TypeError(f"{cls.__name__}.command_interface must be one of "
                            f"{', '.join(COMMAND_INTERFACES)}, not {cls.command_interface!r}")
        for attribute in ("exports", "inputs"):
            declared_lengths(cls, attribute)  # a malformed declaration fails at the class
        declared_topics(cls)

    @classmethod
    def declared_params(cls) -> dict[str, Param]:
        """The parameters this class declares (name -> Param), base classes' included."""
        return dict(cls._declared)

    @classmethod
    def check_entry(cls, name: str, joints: tuple[str, ...], plugin: Any,
                    timestep: float, robot: Any = None) -> None:
        """What `mexone check --controllers` asks of this class's YAML entry (`plugin`: the
        resolved entry, control/resolve.py's Plugin; `timestep`: the physics step, s; `robot`:
        the RobotModel the YAML drives, given to a class whose check_entry takes it), with no
        simulation: raise InputError (its line: the YAML key's) for what configure() would
        refuse that the YAML alone shows. Nothing by default."""

    @property
    def dynamics(self) -> Dynamics:
        """The robot's dynamics at the state of this update (mexone.dynamics.Dynamics)."""
        binding = self.__dict__.get("_mexone_binding")
        if binding is None:
            raise AttributeError("dynamics is set by the controller manager (not yet loaded)")
        return binding.dynamics()

    # ----- the lifecycle: override what you need ---------------------------------------------------
    def configure(self) -> None:
        """Once, after the parameters were validated: precompute what you can."""

    def activate(self, state: State) -> None:
        """ros_control's starting(): the controller takes over its joints at `state`."""

    def update(self, state: State, t: float, dt: float) -> ArrayLike | None:
        """Every period (in lockstep with the simulation): return one command per joint in the claimed
        interface's unit (N m, rad, rad/s), or None to keep the last command."""
        return None

    def deactivate(self) -> None:
        """ros_control's stopping()."""


class Exports(dict[str, np.ndarray]):
    """A controller's exports: its readers hold views of these very arrays, so they are written
    into, never replaced."""

    def __setitem__(self, key: str, value: np.ndarray) -> None:
        raise TypeError(f"exports[{key!r:.40}] is the framework's array, which its readers see: "
                        f"write into it (self.exports[{key!r:.40}][:] = value)")


def declared_lengths(cls: type[PythonController], attribute: str) -> dict[str, int]:
    """A class's `exports` or `inputs` declaration checked: name -> length (a name without '/',
    a whole number >= 1), or a TypeError naming the class."""
    value = getattr(cls, attribute, {})
    if not isinstance(value, Mapping):
        raise TypeError(f"{cls.__name__}.{attribute} must be a dict of name -> length, not "
                        f"{type(value).__name__}")
    out = {}
    for name, length in value.items():
        if not isinstance(name, str) or not name.isidentifier():
            raise TypeError(f"{cls.__name__}.{attribute}: {name!r:.40} is not a name (letters, "
                            "digits, _)")
        if isinstance(length, bool) or not isinstance(length, int) or length < 1:
            raise TypeError(f"{cls.__name__}.{attribute}['{name}'] must be a whole number >= 1 "
                            f"(its length), not {length!r:.40}")
        out[name] = length
    return out


def declared_topics(cls: type[PythonController]) -> dict[str, type]:
    """A class's `topics` declaration checked: relative topic name (letters, digits, _ and /
    between them) -> message class, or a TypeError naming the class."""
    value = getattr(cls, "topics", {})
    if not isinstance(value, Mapping):
        raise TypeError(f"{cls.__name__}.topics must be a dict of topic name -> message class, not "
                        f"{type(value).__name__}")
    out = {}
    for name, msg_type in value.items():
        if not isinstance(name, str) or not all(part.isidentifier() for part in name.split("/")):
            raise TypeError(f"{cls.__name__}.topics: {name!r:.40} is not a topic name relative to the "
                            "robot's namespace (e.g. 'cmd_vel')")
        if not isinstance(msg_type, type):
            raise TypeError(f"{cls.__name__}.topics['{name}'] must be a message class (mexone.bus.msgs), "
                            f"not {msg_type!r:.40}")
        out[name] = msg_type
    return out


def unit_of(interface: str) -> str:
    return _UNITS[interface]
