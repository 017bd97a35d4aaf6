"""Lab: one simulation with its topics and controllers, assembled the way every front end
(`mexone sim`, `mexone run`, the GUI, the ROS bridge) needs it."""

from __future__ import annotations

import functools
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from numbers import Real
from pathlib import Path

import mujoco
import numpy as np

from mexone.bus.msgs import Clock, Header, TFMessage, Time, TransformStamped
from mexone.bus.topics import Bus
from mexone.control.autotune import auto_config, with_transmissions
from mexone.control.config import ControlConfig, load_control_config
from mexone.control.hardware import SimHardware, build_actuators
from mexone.control.manager import ControllerManager
from mexone.description.loader import load_model
from mexone.description.model import RobotModel
from mexone.errors import ArgumentTypeError, InputError, warn_renamed
from mexone.physics.compile import CompileOptions, Spawn, SpecEdit
from mexone.physics.simulation import Simulation
from mexone.physics.world import World, default_world
from mexone.ranges import CONTROL_PERIOD, RTF
from mexone.robots import mex_one
from mexone.sensors import SensorSuite, build_sensors

__all__ = ["Lab", "CLOCK_RATE", "TF_RATE", "robot_namespace", "cached_lab", "AUTO", "no_controllers_note"]


def _conjugate(q: np.ndarray) -> np.ndarray:
    return np.array([q[0], -q[1], -q[2], -q[3]])

CLOCK_RATE = 1000.0  #: Hz of /clock, as gazebo_ros publishes it (only while someone listens)
TF_RATE = 50.0  #: Hz of /tf, robot_state_publisher's default (only while someone listens)


def robot_namespace(robot: RobotModel, config: ControlConfig | None = None,
                    override: str | None = None, name: str | None = None) -> str:
    """The robot's ROS namespace: the one asked for, else the controller YAML's, else the
    URDF's gazebo_ros_control robotNamespace, else its name (`name`, a spawned model's, or the
    robot's: "/mex_rb"). The one home of the rule (sim, run --ros, /gazebo/spawn_urdf_model)."""
    for candidate in (override, config.namespace if config else None, robot.ros_namespace,
                      name or robot.name):
        if candidate and candidate.strip().strip("/"):
            return "/" + candidate.strip().strip("/")
    return "/robot"


@dataclass
class Lab:
    """One simulation with its bus (ROS-named topics), its controller manager and its sensors,
    assembled the way every front end needs it: `Lab.create(...)`."""

    sim: Simulation
    bus: Bus
    manager: ControllerManager | None  # ros_control's controller manager (None: no controllers)
    namespace: str
    sensors: SensorSuite
    _timers: dict = field(default_factory=dict, repr=False)  # lazy publishers that run now
    no_controllers: str | None = None  # why no controller drives the robot, for the GUI and CLI

    @classmethod
    def create(cls, model: RobotModel | Path | str | None = None,
               controllers: ControlConfig | Path | str | bool | None = None,
               world: World | None = None, spawn: Spawn = Spawn(),
               options: CompileOptions = CompileOptions(), target_rtf: float | None = None,
               control_period: float | None = None, namespace: str | None = None,
               start: Sequence[str] | None = None, edits: Sequence[SpecEdit] = ()) -> Lab:
        """model None: the built-in Mex-One (else a RobotModel or a model file's path, str or
        Path). controllers None: the built-in robot's YAML (or none for other robots); True: the
        built-in robot's YAML (another robot has none: pass one, or "auto"); False: no
        controllers; "auto": a position controller per moving joint with gains from the robot's
        physics (control/autotune.py); a path (str or Path) or ControlConfig: that one. `start`:
        the controllers to start (default: every one, except alternatives for joints an earlier
        one drives, which load stopped); the rest are loaded, stopped. `edits` change the MuJoCo
        spec before it compiles (props in the world for an experiment). A value of a type not
        listed here is an ArgumentTypeError (a TypeError) naming the parameter."""
        _check_arguments(model=model, controllers=controllers, world=world, spawn=spawn,
                         options=options, target_rtf=target_rtf, control_period=control_period,
                         namespace=namespace, start=start, edits=edits)
        if target_rtf is not None:
            target_rtf = RTF.check(target_rtf, "Lab.create: target_rtf")
        if control_period is not None:
            control_period = CONTROL_PERIOD.check(control_period, "Lab.create: control_period")
        builtin = model is None
        robot = model if isinstance(model, RobotModel) else load_model(model or mex_one.urdf_path())
        asked = controllers
        if controllers is None:
            controllers = mex_one.controllers_path() if builtin else False
        elif controllers is True:
            if not builtin:
                raise ArgumentTypeError(
                    "Lab.create: controllers=True means the built-in robot's controllers, and "
                    f"'{robot.name}' is another robot", hint="pass its controller YAML, a "
                    "ControlConfig, or 'auto' for gains from its physics")
            controllers = mex_one.controllers_path()
        world = world or default_world()
        config = None
        if controllers == AUTO:
            robot = with_transmissions(robot)
            config = auto_config(robot, world.step, dict(spawn.joints),
                                 floating=not (robot.fixed_to_world or options.fixed_base),
                                 namespace=robot_namespace(robot, None, namespace).strip("/"))
        elif controllers is not False:
            config = controllers if isinstance(controllers, ControlConfig) \
                else load_control_config(controllers)
        edits = [build_sensors, *([build_actuators] if config is not None else []), *edits]
        sim = Simulation(robot, world, spawn, options, target_rtf, edits)
        bus = Bus()
        ns = robot_namespace(robot, config, namespace)
        manager = None
        if config is not None:
            manager = ControllerManager(sim, bus, config, SimHardware(sim), ns, control_period)
        lab = cls(sim, bus, manager, ns, SensorSuite(sim, bus, ns, namespace))
        if manager is not None:  # the sensors first: a controller's activate may read them
            manager.use_sensors(lab.sensors)
            manager.start_default(start)
        if manager is None:
            lab.no_controllers = no_controllers_note(robot, asked)
        bus.on_subscribers("/clock", lambda n: lab._lazy("clock", n, CLOCK_RATE, lab._publish_clock))
        bus.on_subscribers("/tf", lambda n: lab._lazy("tf", n, TF_RATE, lab._publish_tf))
        return lab

    @property
    def controllers(self) -> ControllerManager | None:
        """The former name of `manager` (it read `lab.manager.controllers`), for one
        release."""
        warn_renamed("Lab.controllers", "Lab.manager")
        return self.manager

    def _lazy(self, key: str, listeners: int, rate: float, publish) -> None:
        """Run a publisher only while someone listens: a 1 kHz /clock costs a Python call per
        physics step, which nobody should pay for unless they asked."""
        timers = self._timers
        if listeners and key not in timers:
            timers[key] = self.sim.add_periodic(1.0 / rate, publish)
        elif not listeners and key in timers:
            self.sim.remove_periodic(timers.pop(key))

    def _publish_clock(self, sim: Simulation) -> None:
        self.bus.publish("/clock", Clock(Time.from_nsec(sim.time_ns)))

    def _publish_tf(self, sim: Simulation) -> None:
        """Every joint's transform (parent -> child link) and world -> the floating base."""
        self.bus.publish("/tf", TFMessage(self.transforms()))

    def base_transform(self) -> TransformStamped | None:
        """world -> the robot's base link, where the simulation has it (None if the base link has
        no body of its own); the one home of that transform (the bus's /tf, the ROS bridge's)."""
        sim = self.sim
        body = sim.compiled.bodies.get(sim.robot.base_link)
        if body is None:
            return None
        return TransformStamped(Header(0, Time.from_nsec(sim.time_ns), "world"),
                                sim.robot.base_link, tuple(sim.data.xpos[body]),
                                tuple(sim.data.xquat[body]))

    def transforms(self) -> list[TransformStamped]:
        """Every link's transform now, as robot_state_publisher and the base's odometry send them on /tf."""
        sim = self.sim
        stamp = Time.from_nsec(sim.time_ns)
        data, bodies = sim.data, sim.compiled.bodies
        base = self.base_transform()
        out = [] if base is None else [base]
        for joint in sim.robot.joints.values():
            if joint.parent not in bodies or joint.child not in bodies:
                continue
            p, c = bodies[joint.parent], bodies[joint.child]
            rot = data.xmat[p].reshape(3, 3)
            pos = rot.T @ (data.xpos[c] - data.xpos[p])
            quat = np.zeros(4)
            mujoco.mju_mulQuat(quat, _conjugate(data.xquat[p]), data.xquat[c])
            out.append(TransformStamped(Header(0, stamp, joint.parent), joint.child,
                                        tuple(pos), tuple(quat)))
        return out


AUTO = "auto"  #: Lab.create(controllers=AUTO): controllers with gains from the robot's physics

_PATH = (str, os.PathLike)
_ACCEPTED = {  # Lab.create's parameters: (types, what to say); None is accepted where listed
    "model": ((type(None), RobotModel, *_PATH), "None (the built-in Mex-One), a RobotModel or a "
                                                "model file's path (str or Path)"),
    "controllers": ((type(None), bool, ControlConfig, *_PATH),
                    "None, True, False, 'auto', a controller YAML's path (str or Path) or a "
                    "ControlConfig"),
    "world": ((type(None), World), "None (the default world) or a World"),
    "spawn": ((Spawn,), "a Spawn"),
    "options": ((CompileOptions,), "a CompileOptions"),
    "namespace": ((type(None), str), "None or a str"),
}


def _check_arguments(**values) -> None:
    """Lab.create's types, checked before anything loads: one line naming the parameter."""
    def wrong(name: str, value, accepted: str) -> ArgumentTypeError:
        return ArgumentTypeError(f"Lab.create: {name} must be {accepted}, not "
                                 f"{type(value).__name__} {value!r:.60}")

    for name, (types, accepted) in _ACCEPTED.items():
        value = values[name]
        if not isinstance(value, types):
            raise wrong(name, value, accepted)
        if isinstance(value, _PATH) and not os.fspath(value):
            raise InputError(f"Lab.create: {name} is an empty path", hint=f"pass {accepted}")
    for name in ("target_rtf", "control_period"):  # their ranges: Range.check in Lab.create
        value = values[name]
        if value is not None and (isinstance(value, bool) or not isinstance(value, Real)):
            raise wrong(name, value, "None or a number of seconds" if name == "control_period"
                        else "None or a number (1: real time, 0: as fast as possible)")
    start = values["start"]
    if start is not None and (isinstance(start, (str, bytes)) or not isinstance(start, Sequence)
                              or not all(isinstance(n, str) for n in start)):
        raise wrong("start", start, "None or a list of controller names (a list, even of one)")
    edits = values["edits"]
    if isinstance(edits, (str, bytes)) or not isinstance(edits, Sequence) \
            or not all(callable(e) for e in edits):
        raise wrong("edits", edits, "a list of functions f(spec, robot)")


def no_controllers_note(robot: RobotModel, asked) -> str:
    """One line on why nothing drives the robot and what to do about it."""
    if asked is False:
        return "No controllers (--no-controllers): the joints are free."
    if not robot.transmissions:
        return (f"'{robot.name}' has no <transmission>, so no controllers drive it and it goes "
                "limp: run with --controllers auto (gains from its physics), or write a YAML with "
                "'mexone controllers'")
    return (f"'{robot.name}' has {len(robot.transmissions)} <transmission>s but no controller YAML "
            "was given: run with --controllers YAML or --controllers auto")


@functools.lru_cache(maxsize=4)
def cached_lab(model: str | None = None, controllers: str | None = None) -> Lab:
    """One Lab per (model, controllers) per process, for workers that run many trials (sweeps,
    benchmarks): compiling costs more than a trial. Callers reset it before each use."""
    lab = Lab.create(model, controllers)
    return lab
