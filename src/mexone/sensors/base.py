"""What every simulated sensor type shares, and the registry that makes one module a sensor type.

A sensor type is ONE plug-in (a `Sensor` subclass registered with `register_sensor`), as a
ros2_control semantic component plus its broadcaster:

- `build`: its MjSpec edit (sites, MuJoCo sensors, cameras) before the model compiles;
- `state_type` and `read`: its state interfaces, a small dataclass of numpy arrays with
  ros2_control's field names, filled lazily once per instant (`Sensor.state()`): only sensors
  somebody reads cost anything;
- `message_type` and `message`: what its broadcaster publishes, built from that state, at the
  sensor's update rate, only while someone listens to its topic (as gazebo_ros plugins and
  ros2_control's broadcasters do);
- `plot`: its plot signals (`<name>/<field>/<axis>`), and `pane`/`view`: its GUI view.

MuJoCo's sensors are evaluated on demand (`Measure`), once per instant however many sensors ask.
"""

from __future__ import annotations

import importlib
import logging
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from typing import Any, ClassVar, cast

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from mexone.bus.msgs import Header, Time
from mexone.bus.topics import Bus, Topic, resolve_name
from mexone.description.model import RobotModel
from mexone.description.sensors import SensorSpec
from mexone.errors import InputError
from mexone.physics.simulation import Simulation

__all__ = ["Output", "Measure", "Sensor", "SensorStates", "topic_name", "register_sensor",
           "SENSOR_CLASSES", "sensor_type", "sensor_types", "AXES", "ENTRY_POINT_GROUP",
           "BUILTIN_SENSORS"]

log = logging.getLogger(__name__)

ENTRY_POINT_GROUP = "mexone.sensors"
BUILTIN_SENSORS = ("mexone.sensors.imu", "mexone.sensors.force_torque", "mexone.sensors.contact",
                   "mexone.sensors.camera")

_SENSOR_OFF = int(mujoco.mjtDisableBit.mjDSBL_SENSOR)
# looked up once: the sensor pass runs between steps, where every attribute lookup counts
_sensor_pos, _sensor_vel, _sensor_acc = mujoco.mj_sensorPos, mujoco.mj_sensorVel, mujoco.mj_sensorAcc
AXES = {3: "xyz", 4: "xyzw", 6: ("x", "y", "z", "rx", "ry", "rz")}  # plot signals per array size


def topic_name(namespace: str, name: str) -> str:
    """A plugin's topic: absolute as given, else in the robot's namespace (spawn_model's
    -robot_namespace puts every plugin there)."""
    return resolve_name(name, namespace)


def sensor_namespace(spec: SensorSpec, robot_namespace: str, override: str | None = None) -> str:
    """Where a sensor's relative topics go, as Gazebo decides: spawn_model's -robot_namespace
    (`override`) puts every plugin there; else the plugin's own <robotNamespace>; else a
    gazebo_ros plugin publishes from the root (so rrbot's cameraName "rrbot/camera1" gives
    /rrbot/camera1/image_raw); a sensor without a plugin (mexone's extension: Gazebo would not
    publish it) goes in the robot's namespace."""
    if override and override.strip("/"):
        return "/" + override.strip("/")
    if spec.namespace and spec.namespace.strip("/"):
        return "/" + spec.namespace.strip("/")
    return "/" if spec.plugin else robot_namespace


@dataclass(frozen=True)
class Output:
    topic: str
    type: type
    heavy: bool = False  # images and clouds: rendered for subscribers, never just for recorders


class Measure:
    """MuJoCo's sensor values at the current instant (keyed by Simulation.steps, which never
    repeats; a reset invalidates), computed on the first request (the
    simulation steps with MuJoCo's sensor pass turned off), and the light sensors' state arrays.

    Sensor types whose state is a fixed linear function of MuJoCo's sensordata (reordering,
    signs, sums, constant rotations) register it with `linear`; `refresh` then fills every such
    array with one matrix-vector product per instant, and their state arrays are views into one
    buffer. Python work per reading is what makes sensors cost: this keeps it to a few calls
    however many sensors are read.
    """

    def __init__(self, sim: Simulation) -> None:
        self.sim = sim
        self._at = self._contacts_at = self._stamp_at = self._refreshed_at = -1
        self._stamp = Time()
        self._contacts: tuple[list[Any], ...] = ([], [], [], [], [])
        self._cone_model: mujoco.MjModel | None = None
        self._elliptic = False
        self._force6 = np.zeros(6)
        self._terms: list[tuple[int, np.ndarray, np.ndarray]] = []  # (offset, rows, matrix)
        self._size = 0
        self._matrix: np.ndarray | None = None
        self.buffer = np.zeros(0)
        self._views: list[tuple[Callable[[np.ndarray], None], int, int]] = []
        sim.on_reset(self.invalidate)
        sim.on_model_change(self._model_changed)
        self._model_changed()

    def _model_changed(self) -> None:
        """A model added or removed (and at the start): our sensors' addresses stay (attached
        models come after), sensordata may grow, and a new model would step with the sensor
        pass on. What the pass touches is looked up here once: each call into MuJoCo's
        bindings costs, at 100 Hz between steps."""
        self.sim.model.opt.disableflags |= _SENSOR_OFF
        self._opt = self.sim.model.opt
        self._sensordata = self.sim.data.sensordata
        self._matrix = None
        self.invalidate()

    def invalidate(self) -> None:
        """Forget this instant's readings (the state changed under them: a reset, a teleport)."""
        self._at = self._contacts_at = self._stamp_at = self._refreshed_at = -1

    def stamp(self) -> Time:
        """This instant's sim time as a message stamp, one (immutable) object for every message
        of the instant."""
        sim = self.sim
        if self._stamp_at != sim.steps:
            self._stamp = Time.from_nsec(sim.time_ns)
            self._stamp_at = sim.steps
        return self._stamp

    def contacts(self) -> tuple[list[Any], ...]:
        """This instant's contacts as plain lists, read once for every contact sensor: (geom
        pairs, frames (9 each: normal, two tangents, world), positions, distances, each
        contact's (normal, tangent, tangent) force on geom2 in its frame). Elliptic cones
        (mexone's default) read those forces straight from efc_force; others ask
        mj_contactForce. Plain Python floats: at a handful of contacts, numpy per contact costs
        more than the arithmetic."""
        sim = self.sim
        if self._contacts_at != sim.steps:
            self._contacts_at = sim.steps
            model, data = sim.model, sim.data
            contact, ncon = data.contact, data.ncon
            if not ncon:
                self._contacts = ([], [], [], [], [])
                return self._contacts
            if self._cone_model is not model:  # once per compiled model: enum reads are slow
                self._cone_model = model
                self._elliptic = int(model.opt.cone) == int(mujoco.mjtCone.mjCONE_ELLIPTIC)
            # data.contact is already the ncon contacts: no slicing (each numpy call counts here)
            adrs, dims = contact.efc_address.tolist(), contact.dim.tolist()
            if self._elliptic:
                efc = data.efc_force.tolist()
                local = [(efc[a], efc[a + 1], efc[a + 2]) if d == 3 and a >= 0
                         else self._contact_force(i)
                         for i, (a, d) in enumerate(zip(adrs, dims, strict=True))]
            else:
                local = [self._contact_force(i) for i in range(ncon)]
            self._contacts = (contact.geom.tolist(), contact.frame.tolist(), contact.pos.tolist(),
                              contact.dist.tolist(), local)
        return self._contacts

    def _contact_force(self, i: int) -> tuple[float, float, float]:
        mujoco.mj_contactForce(self.sim.model, self.sim.data, i, self._force6)
        return tuple(self._force6[:3].tolist())

    def data(self) -> np.ndarray:
        """MuJoCo's sensordata after this instant's sensor pass."""
        sim = self.sim
        if self._at != sim.steps:
            self._sensor_pass(sim)
        return self._sensordata

    def _sensor_pass(self, sim: Simulation) -> None:
        model, data, opt = sim.model, sim.data, self._opt
        flags = opt.disableflags
        opt.disableflags = flags & ~_SENSOR_OFF
        try:  # the state the last step computed (positions, velocities, accelerations)
            _sensor_pos(model, data)
            _sensor_vel(model, data)
            _sensor_acc(model, data)
        finally:
            opt.disableflags = flags
        self._at = sim.steps

    def linear(self, rows: ArrayLike, matrix: ArrayLike, bind: Callable[[np.ndarray], None]) -> None:
        """Register out = matrix @ sensordata[rows] (matrix: len(out) x len(rows)); `bind(view)`
        receives out's view into the shared buffer once the buffer exists (before the first
        refresh), to make it the state's arrays."""
        index = np.asarray(rows, dtype=int)
        weights = np.asarray(matrix, dtype=float).reshape(-1, len(index))
        self._terms.append((self._size, index, weights))
        self._views.append((bind, self._size, self._size + len(weights)))
        self._size += len(weights)
        self._matrix = None

    def _build(self) -> np.ndarray:
        nsensordata = self.sim.model.nsensordata
        self._matrix = whole = np.zeros((self._size, nsensordata))
        for offset, rows, matrix in self._terms:
            for j, row in enumerate(rows):
                whole[offset:offset + len(matrix), row] += matrix[:, j]
        self.buffer = np.zeros(self._size)
        for bind, start, stop in self._views:
            bind(self.buffer[start:stop])
        return whole

    def refresh(self) -> None:
        """Every registered linear state at this instant (once per instant)."""
        sim = self.sim
        now = sim.steps
        if self._refreshed_at == now:
            return
        matrix = self._matrix
        if matrix is None:
            matrix = self._build()
        if self._at != now:
            self._sensor_pass(sim)
        matrix.dot(self._sensordata, out=self.buffer)  # the method: no dispatch layer
        self._refreshed_at = now


@dataclass
class Sensor:
    """One declared sensor in a running simulation. Subclasses (one per sensor type) set the
    class attributes and override `build`, `setup`, `read` and `message`."""

    type_name: ClassVar[str] = ""  # the SDF <sensor type="...">; set by register_sensor
    state_type: ClassVar[type | None] = None  # its state interfaces; None: no state (cameras)
    message_type: ClassVar[type | None] = None  # the message of its main topic
    broadcaster: ClassVar[str] = ""  # the ros2_control broadcaster that would publish it
    plot: ClassVar[dict[str, str]] = {}  # state field -> unit: the plot signals it offers
    pane: ClassVar[tuple[str, str] | None] = None  # GUI: (title, "field/axis") per sensor type
    linear: ClassVar[bool] = False  # its state comes from Measure.linear (read() then only
    # adds what is not linear: noise, a rotation that moves)

    spec: SensorSpec
    sim: Simulation
    bus: Bus
    namespace: str
    measure: Measure
    link: str
    outputs: list[Output] = field(default_factory=list)
    seq: int = 0

    # ----- the type's model edit (before the model compiles) ---------------------------------
    @classmethod
    def build(cls, spec: mujoco.MjSpec, body: mujoco.MjsBody, sensor: SensorSpec,
              robot: RobotModel) -> None:
        """Add what this type needs to the MjSpec (a site, MuJoCo sensors, a camera) on `body`,
        the MuJoCo body of the sensor's link. Nothing by default."""

    # ----- runtime -------------------------------------------------------------------------------
    def __post_init__(self) -> None:
        self._state = self.state_type() if self.state_type is not None else None
        self._at = -1
        self.setup()
        if not self.outputs and self.message_type is not None:
            self.outputs = [Output(topic_name(self.namespace, self.spec.topic or self.spec.name),
                                   self.message_type)]
        self._frame_id = self.frame  # fixed once set up: the messages' frame_id
        # the main topic (a sensor without outputs never publishes: its broadcaster never runs)
        self._topic: Topic = self.bus.topic(self.outputs[0].topic, self.outputs[0].type) \
            if self.outputs else cast(Topic, None)
        if not hasattr(self, "_needs_read"):  # setup may say a reading needs no read() call
            self._needs_read = type(self).read is not Sensor.read

    def setup(self) -> None:
        """Find this sensor's MuJoCo data (ids, addresses); name its outputs if it has several."""

    def read(self, state: Any) -> None:
        """Fill `state` (this type's state_type) with the values at the current instant (for a
        `linear` type: finish what Measure.refresh filled in, if anything: noise, a rotation
        that moves; a linear type that leaves this alone costs no call)."""

    def bind(self, **slices: slice) -> Callable[[np.ndarray], None]:
        """For Measure.linear: make the state's fields views into the buffer, field -> slice of
        the registered output. The state's views are read-only (what a controller reads is
        shared with every other reader of the instant: writing into it raises); a name starting
        with `_` is a writable view set on the sensor, for its own read() (noise, a rotation),
        as is `_linear_view`, the whole output. Set once: no cost per reading."""

        def bind(view: np.ndarray) -> None:
            state = self._state
            for name, part in slices.items():
                if name.startswith("_"):
                    setattr(self, name, view[part])
                else:
                    shown = view[part]
                    shown.flags.writeable = False
                    object.__setattr__(state, name, shown)  # a frozen state dataclass too
            self._linear_view = view

        return bind

    def message(self, state: Any) -> object:
        """The broadcaster's message for the main topic, built from `state`."""
        raise NotImplementedError

    def state(self) -> Any:
        """The state interfaces at this instant, read on the first request of the instant (the
        same object each time: copy an array to keep it past the instant)."""
        if self._state is None:
            raise KeyError(f"{self.type_name} sensor '{self.spec.name}' has no state interfaces")
        now = self.sim.steps  # an instant: steps never repeat (a reset invalidates)
        if self._at != now:
            if self.linear and self.measure._refreshed_at != now:
                self.measure.refresh()
            if self._needs_read:
                self.read(self._state)
            self._at = now
        return self._state

    def invalidate(self) -> None:
        """Forget this instant's reading (the state changed under it)."""
        self._at = -1

    @property
    def frame(self) -> str:
        """The frame_id of its messages."""
        return self.spec.frame or self.link

    @property
    def rate(self) -> float:
        """Hz; 0 (Gazebo: as fast as possible) is every physics step."""
        return self.spec.update_rate or 1.0 / self.sim.timestep

    def header(self, frame: str | None = None) -> Header:
        """A message header now: the next seq, this instant's stamp, the frame."""
        self.seq = seq = self.seq + 1
        return Header(seq, self.measure.stamp(), frame or self._frame_id)

    def wanted(self, output: Output) -> bool:
        """Whether an output has listeners (a camera renders for subscribers only)."""
        topic = self.bus.topics.get(output.topic)
        if output.heavy:  # recorders alone do not make a camera render
            return topic is not None and bool(topic.subscriptions)
        return self.bus.wanted(output.topic)

    def publish(self, sim: Simulation) -> None:
        """The broadcaster's tick: the main topic's message from this instant's state."""
        state = self._state if self._at == sim.steps else self.state()  # read this instant?
        self.bus.deliver(self._topic, self.message(state))

    # ----- plots and the page --------------------------------------------------------------------
    def signals(self) -> list[tuple[str, str]]:
        """(signal name, unit) of every plot signal: `<name>/<field>/<axis>` (`<name>/<field>`
        for a single value), in `values` order."""
        state = self._state
        out = []
        for name, unit in self.plot.items():
            size = np.size(getattr(state, name))
            if size == 1:
                out.append((f"{self.spec.name}/{name}", unit))
            else:
                out += [(f"{self.spec.name}/{name}/{a}", unit) for a in AXES.get(size, range(size))]
        return out

    def values(self) -> np.ndarray:
        """The plot signals' values now (`signals` order)."""
        state = self.state()
        return np.concatenate([np.ravel(getattr(state, name)) for name in self.plot]) \
            if self.plot else np.zeros(0)

    def view(self) -> str | None:
        """A line of markdown for the page's Sensors panel (None: nothing to show)."""
        return None


SENSOR_CLASSES: dict[str, type[Sensor]] = {}  #: SDF sensor type -> its plug-in


def register_sensor(type_name: str) -> Callable[[type[Sensor]], type[Sensor]]:
    """Class decorator: make `cls` the plug-in of SDF sensor type `type_name` (declared in a
    URDF's `<gazebo reference=...><sensor type="type_name">`): the model builder calls its
    `build`, the suite runs it. A package's sensor types are found through the
    `mexone.sensors` entry-point group (`name = "package.module"`: importing it registers)."""

    def add(cls: type[Sensor]) -> type[Sensor]:
        cls.type_name = cls.type_name or type_name
        SENSOR_CLASSES[type_name] = cls
        return cls

    return add


_loaded_entry_points = False


def sensor_types() -> dict[str, type[Sensor]]:
    """Every sensor plug-in by type: the shipped ones and the entry points' (imported once). A
    package's type that fails to import is logged and left out."""
    global _loaded_entry_points
    for module in BUILTIN_SENSORS:
        importlib.import_module(module)
    if not _loaded_entry_points:
        _loaded_entry_points = True
        for ep in entry_points(group=ENTRY_POINT_GROUP):
            try:
                importlib.import_module(ep.value)
            except Exception as exc:  # noqa: BLE001 - someone else's package: the lab goes on
                log.warning("sensor type %s (%s) did not load: %s", ep.name, ep.value, exc)
    return SENSOR_CLASSES


def sensor_type(type_name: str) -> type[Sensor]:
    """The plug-in of sensor type `type_name`; an InputError listing the types if none."""
    cls = SENSOR_CLASSES.get(type_name) or sensor_types().get(type_name)
    if cls is None:
        raise InputError(f"mexone does not simulate sensor type '{type_name}'",
                         hint="types: " + ", ".join(sorted(sensor_types())) + f" (a package adds one "
                              f"through the '{ENTRY_POINT_GROUP}' entry points)")
    return cls


class SensorStates(Mapping[str, Any]):
    """name -> the sensor's state object at this instant (see `Sensor.state`): what controllers
    read as `state.sensors[name]`. Only the sensors looked up are read."""

    def __init__(self, sensors: Mapping[str, Sensor]) -> None:
        self._sensors = {n: s for n, s in sensors.items() if s.state_type is not None}

    def __getitem__(self, name: str) -> Any:
        try:
            sensor = self._sensors[name]
        except KeyError:
            raise KeyError(f"no sensor named '{name}' with state interfaces (sensors: "
                           f"{', '.join(self._sensors) or 'none'})") from None
        if sensor._at == sensor.sim.steps:  # read already this instant: no call
            return sensor._state
        return sensor.state()

    def __iter__(self) -> Iterator[str]:
        return iter(self._sensors)

    def __len__(self) -> int:
        return len(self._sensors)

    def __contains__(self, name: object) -> bool:
        return name in self._sensors

    def kinds(self) -> dict[str, str]:
        """name -> sensor type, for listings."""
        return {n: s.type_name for n, s in self._sensors.items()}
