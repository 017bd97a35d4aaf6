"""ControllerManager: ros_control's controller_manager, and the control loop.

Controllers are loaded from the configuration, claim joints through the hardware interface (one
running controller per joint), and listen on ``/<ns>/<name>/command``. Subscribers only buffer.
The loop is ros2_control's read -> update -> write, run by the simulation thread before a step
whenever it is due (`wake_ns`): when a command is waiting, and every control period while a
running controller needs its period (trajectories, ideal servos, velocity PIDs with I or D). The
PIDs themselves run in MuJoCo, so with nothing waiting the loop costs nothing.

    topic --on_command--> controller buffer --update--> hw.command --write--> MuJoCo --mj_step
"""

from __future__ import annotations

import builtins
import contextlib
import logging
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from mexone.bus.msgs import Float64, Float64MultiArray, Header, JointControllerState, Time
from mexone.bus.topics import Bus, Subscription
from mexone.control.config import chain_order, check_chains
from mexone.control.controllers import (
    CONTROLLER_TYPES,
    ControllerContext,
    ControllerInterface,
    PythonRunner,
    controller_type,
)
from mexone.control.controllers.isolated import IsolatedRunner
from mexone.control.controllers.python import ControllerHang, period_ns
from mexone.control.hardware import SimHardware
from mexone.control.notes import gazebo_differences
from mexone.control.resolve import validate_params
from mexone.control.spec import ControlConfig, ControllerSpec, PidGains
from mexone.control.student import declared_lengths, sensor_states
from mexone.control.worker import resolve
from mexone.errors import InputError, warn_renamed
from mexone.physics.simulation import NS, Periodic, Simulation

if TYPE_CHECKING:
    from mexone.sensors import SensorSuite

__all__ = ["ControllerManager", "ControllerInfo", "STRICT", "BEST_EFFORT"]

log = logging.getLogger("mexone.control")

BEST_EFFORT, STRICT = 1, 2  # controller_manager_msgs/SwitchController strictness
STATE_RATE = 100.0  # Hz of `<ctrl>/state`: ros_controllers publish every 10th update at 1 kHz


@dataclass(frozen=True)
class ControllerInfo:
    name: str
    type: str
    state: str  # "running" or "stopped"
    joints: tuple[str, ...]
    interface: str
    update_rate: float | None = None  # Hz a Python controller updates at (None: shipped types)
    update_time: float | None = None  # s of wall time per update (Python controllers)
    fault: str | None = None  # why a Python controller was stopped
    params: dict[str, Any] | None = None  # a Python controller's declared parameters now
    deadline_misses: int | None = None  # updates over their deadline since it started (Python)
    update_time_max: float | None = None  # s, the longest update since it started (Python)


class ControllerManager:
    """ros_control's controller_manager for one robot: loads controllers from the configuration,
    starts, stops and switches them (one running controller per joint), and runs the control
    loop (see the module's doc). `Lab.manager` is the lab's."""

    def __init__(self, sim: Simulation, bus: Bus, config: ControlConfig, hw: SimHardware,
                 namespace: str, control_period: float | None = None):
        self.sim, self.bus, self.config, self.hw = sim, bus, config, hw
        self.namespace = namespace
        self._explicit_period = control_period
        if control_period is not None and control_period < sim.timestep * (1 - 1e-9):
            raise InputError(f"control period {control_period} s is shorter than the physics "
                             f"step {sim.timestep} s")
        self.controllers: dict[str, ControllerInterface] = {}
        self._subs: dict[str, Subscription] = {}
        self._ctx = ControllerContext(sim, hw, bus, namespace, config.pid_gains)
        self._periodic: list[ControllerInterface] = []  # running controllers that need every period
        self._running: list[ControllerInterface] = []
        self._timed: list[PythonRunner] = []  # running Python controllers (own update rates)
        self._every: Sequence[ControllerInterface] = []  # running controllers that update every period
        self._waiting = False  # a command was buffered since the last update
        self._half_step_ns = 0
        self._direct = False  # only Python controllers reading MuJoCo directly run every period
        self._fast = False  # _direct and no shipped controller's period: update's fast path
        self._dt = self.control_period  # cached for the loop; _schedule refreshes it
        self._period_ns = round(self._dt * NS)
        self._next_period_ns = 0
        self._state_topics: set[str] = set()
        self._state_timer: Periodic | None = None
        self._state_seq = 0
        self.updates = 0
        self.wake_ns: float = math.inf
        sim.add_control(self)
        sim.on_reset(self.restart)
        sim.on_timestep_change(self.on_timestep_change)
        sim.on_model_change(self._rebind)  # after the hardware's own rebind (registered first)
        sim.watchdog.suspects.append(self._suspect)
        for note in gazebo_differences(config):
            log.warning("%s: %s", note.spec.name, note.text)

    # ----- the loop (simulation thread) ------------------------------------------------------------
    @property
    def control_period(self) -> float:
        """The controllers' period: the physics step unless the configuration asked for more."""
        return max(self._explicit_period or 0.0, self.sim.timestep)

    def update(self, sim: Simulation) -> None:
        """read -> every running controller's update -> write, after the loop's one schedule:
        the control period's next instant, which Python controllers are due now (each at its
        own rate), and when to wake next (the earliest of those; a command buffered meanwhile by
        another thread has set -inf, which stays). When only Python controllers that read
        MuJoCo themselves run and no command waits (the common case with a student's
        controller), there is no read, and each one's command goes out through its own hardware
        writer, so no full write either: what that costs per update is the framework's cost of
        a Python controller (benchmarks/RESULTS.md), so keep it to plain attribute work."""
        now = sim._time_ns
        self.wake_ns = math.inf  # first: a command buffered from now on wakes us again
        wake: float = math.inf  # every controller scheduled first: a hang below must not lose a wake
        if self._periodic:
            if now >= self._next_period_ns - self._half_step_ns:
                self._next_period_ns = now + self._period_ns
            wake = self._next_period_ns
        half = self._half_step_ns
        timed = self._timed
        for runner in timed:
            next_ns = runner.next_ns
            if now >= next_ns - half:  # due (a wake at the same instant, by a command or a
                runner.due = True  # switch, is not: it ran already)
                next_ns += runner.period_ns
                if next_ns < now + half:  # fell behind (a step longer than the period)
                    next_ns = now + runner.period_ns
                runner.next_ns = next_ns
            if next_ns < wake:
                wake = next_ns
        if wake < self.wake_ns:
            self.wake_ns = wake
        self.updates += 1
        t = now / NS
        waiting = self._waiting
        fast = self._fast and not waiting
        if not fast:
            self._waiting = False
            if waiting or not self._direct:  # else only Python controllers that read MuJoCo run
                self.hw.read()
        try:
            if fast:
                for runner in timed:
                    runner.update(t, 0.0)  # a Python controller takes its own dt
            else:  # an idle controller (no command waiting, no period) has nothing to do
                dt = self._dt
                for ctrl in self._running if waiting else self._every:
                    if ctrl.every_period or ctrl._pending is not None:
                        ctrl.update(t, dt)
        except ControllerHang:  # the watchdog's interrupt landed just after a student's update
            log.error("a controller's update was interrupted after it returned; no harm done")
        if self._ctx.faults:
            self._stop_faulted()
        elif not waiting and self._every is timed:  # only Python controllers ran: each wrote
            return  # its own joints' commands (its hardware writer)
        self.hw.write()

    def _rebind(self) -> None:
        """Models were added or removed: MuJoCo addresses moved; Python controllers follow."""
        for ctrl in self.controllers.values():
            if isinstance(ctrl, PythonRunner):
                ctrl.rebind()
        self._schedule()

    def _stop_faulted(self) -> None:
        """Stop the controllers that faulted (their joints hold); the lab runs on."""
        names, self._ctx.faults[:] = list(self._ctx.faults), []
        running = [n for n in dict.fromkeys(names) if n in self.controllers
                   and self.controllers[n].running]
        if running:
            self.switch(stop=running)

    def use_sensors(self, suite: SensorSuite) -> None:
        """Python controllers read `state.sensors` from `suite` (a mexone.sensors.SensorSuite)."""
        self._ctx.sensors = lambda: sensor_states(suite)
        for ctrl in self.controllers.values():
            if isinstance(ctrl, PythonRunner):
                ctrl.state._sensor_source = self._ctx.sensors

    def _wake(self) -> None:
        self.wake_ns = -math.inf

    def on_timestep_change(self, timestep: float) -> None:
        """The physics step changed: the period follows it; the PIDs in MuJoCo already do."""
        self._next_period_ns = self.sim.time_ns
        self._schedule()

    def _suspect(self) -> str | None:
        if any(c.drives_joints for c in self._running):
            return "controller gains too high for the time step: lower p and d, or the step"
        return None

    # ----- loading ---------------------------------------------------------------------------------
    def topic(self, name: str) -> str:
        """The command topic of controller `name` (/<ns>/<name>/command)."""
        return f"{self.namespace}/{name}/command"

    def load(self, name: str) -> ControllerInterface:
        """Create controller `name` from the configuration (stopped)."""
        if name in self.controllers:
            raise InputError(f"controller '{name}' is already loaded")
        spec = self.config.controllers.get(name)
        if spec is None:
            raise InputError(f"no controller named '{name}' in the configuration",
                             hint="controllers: " + ", ".join(self.config.controllers))
        missing = [j for j in spec.joints if j not in self.hw.robot.joints]
        if missing:
            raise InputError(f"controller '{name}' names joint '{missing[0]}', which the robot "
                             "does not have", file=spec.source, line=spec.line,
                             hint="joints: " + ", ".join(self.hw.joints))
        try:
            ctrl = _runner(spec)(spec, self._ctx) if spec.plugin is not None \
                else controller_type(spec.type).cls(spec, self._ctx)
        except InputError as exc:
            raise exc.located(spec.source or "<controllers>", spec.line) from None
        self.controllers[name] = ctrl
        return ctrl

    def define(self, spec: ControllerSpec) -> None:
        """Add or replace the configuration of a controller that is not loaded (ros_control reads
        it from the parameter server when asked to load)."""
        if spec.name in self.controllers:
            raise InputError(f"controller '{spec.name}' is already loaded", hint="unload it first")
        check_chains(replace(self.config, controllers={**self.config.controllers, spec.name: spec}))
        self.config.controllers[spec.name] = spec

    def unload(self, name: str) -> None:
        """Forget a stopped controller (controller_manager's unload_controller)."""
        ctrl = self._get(name)
        if ctrl.running:
            raise InputError(f"cannot unload '{name}': it is running", hint="stop it first")
        del self.controllers[name]
        if isinstance(ctrl, PythonRunner):
            ctrl.close()

    def load_all(self) -> list[str]:
        """Load every controller of the configuration not loaded yet; the names, in its order."""
        for name in self.config.controllers:
            if name not in self.controllers:
                self.load(name)
        return list(self.config.controllers)

    def _get(self, name: str) -> ControllerInterface:
        ctrl = self.controllers.get(name)
        if ctrl is None:
            raise InputError(f"no controller named '{name}' is loaded",
                             hint="loaded: " + (", ".join(self.controllers) or "none"))
        return ctrl

    # ----- running ---------------------------------------------------------------------------------
    def start(self, *names: str) -> None:
        """Start these controllers (a strict switch)."""
        self.switch(start=names)

    def stop(self, *names: str) -> None:
        """Stop these controllers (a strict switch): their joints are released."""
        self.switch(stop=names)

    def start_all(self) -> None:
        """Load and start every controller of the configuration."""
        self.load_all()
        self.switch(start=[n for n, c in self.controllers.items() if not c.running])

    def start_default(self, names: Iterable[str] | None = None) -> list[str]:
        """Load every configured controller and start `names` (default: all of them in the
        configuration's order, except one that would drive a joint an earlier one drives: a
        YAML may hold alternatives for the same joints; those stay loaded, stopped). Returns
        the controllers left stopped."""
        self.load_all()
        if names is not None:
            self.switch(start=list(names))
            return [n for n, c in self.controllers.items() if not c.running]
        claimed: dict[str, str] = {j: c.name for c in self._running for j in c.joints}
        start, stopped = [], []
        for name, ctrl in self.controllers.items():
            if ctrl.running:
                continue
            clash = next((claimed[j] for j in ctrl.joints if j in claimed), None)
            if clash is not None:
                stopped.append(name)
                log.warning("%s: loaded stopped, as '%s' already drives its joints; start it with "
                            "switch_controller (stopping '%s')", name, clash, clash)
                continue
            claimed.update({j: name for j in ctrl.joints})
            start.append(name)
        self.switch(start=start)
        return stopped

    def hold(self, joints: Iterable[str]) -> None:
        """Restart the running controllers of `joints`, so they hold where the joints are now
        (after set_model_configuration teleported them)."""
        joints = set(joints)
        names = [c.name for c in self._running if joints & set(c.joints)]
        if names:
            self.switch(stop=names)
            self.switch(start=names)

    def switch(self, start: Iterable[str] = (), stop: Iterable[str] = (),
               strictness: int = STRICT) -> None:
        """Stop then start, as controller_manager's switch_controller: STRICT refuses the whole
        switch if a controller is missing or already in the asked state; BEST_EFFORT skips those.
        Two running controllers on one joint are refused either way."""
        start, stop = list(start), list(stop)
        for name in start + stop:
            if name not in self.controllers and name in self.config.controllers:
                self.load(name)
        problems = [f"no controller named '{n}' is loaded" for n in start + stop
                    if n not in self.controllers]
        problems += [f"'{n}' is already running" for n in start
                     if n in self.controllers and self.controllers[n].running and n not in stop]
        problems += [f"'{n}' is not running" for n in stop
                     if n in self.controllers and not self.controllers[n].running]
        if problems and strictness == STRICT:
            raise InputError("cannot switch controllers: " + "; ".join(problems),
                             hint="loaded: " + ", ".join(self.controllers))
        start = [n for n in start if n in self.controllers
                 and (not self.controllers[n].running or n in stop)]
        stop = [n for n in stop if n in self.controllers and self.controllers[n].running]
        claimed = {j: c.name for c in self.controllers.values()
                   if c.running and c.name not in stop for j in c.joints}
        for name in start:
            for joint in self.controllers[name].joints:
                if claimed.get(joint, name) != name:
                    raise InputError(f"cannot start '{name}': joint '{joint}' is driven by "
                                     f"'{claimed[joint]}'", hint="stop that controller first")
                claimed[joint] = name
        self.hw.read()
        for name in stop:
            ctrl = self.controllers[name]
            ctrl.running = False
            ctrl.stopping()
            sub = self._subs.pop(name, None)
            if sub is not None:
                sub.unregister()
        t = self.sim.time
        for name in start:
            ctrl = self.controllers[name]
            ctrl.starting(t)
            ctrl.running = True
            if ctrl.drives_joints and ctrl.msg_type is not None:
                self._subs[name] = self.bus.subscribe(self.topic(name), ctrl.msg_type,
                                                      self._buffer(ctrl), node=name)
            if ctrl.has_state:
                self._watch_state(self.state_topic(name))
        self._schedule()
        if self._ctx.faults:  # a Python controller whose activate failed
            names, self._ctx.faults[:] = list(self._ctx.faults), []
            for name in dict.fromkeys(names):
                faulted = self.controllers.get(name)
                if faulted is not None and faulted.running:
                    faulted.running = False
                    faulted.stopping()
            self._schedule()
        self.hw.write()

    def _buffer(self, ctrl: ControllerInterface) -> Callable[[object], None]:
        def on_message(msg: object) -> None:  # the publisher's thread: buffer only
            if ctrl.on_command(msg):
                self._waiting = True
                self._wake()
        return on_message

    def _schedule(self) -> None:
        order = chain_order(self.controllers) or list(self.controllers)  # exporters first
        self._running = [self.controllers[n] for n in order if self.controllers[n].running]
        self._bind_inputs()
        self._periodic = [c for c in self._running if c.periodic]
        self._timed = [c for c in self._running if isinstance(c, PythonRunner) and c.timed]
        for ctrl in self._running:
            ctrl.every_period = ctrl.periodic or ctrl.timed
        self._every = [c for c in self._running if c.every_period]
        if self._every == self._timed:
            self._every = self._timed  # the same list: update() takes its fast write
        self._direct = self._every is self._timed and all(c.direct for c in self._timed)
        self._fast = self._direct and not self._periodic
        self._waiting = True  # a command buffered before the switch is not lost
        now = self.sim.time_ns
        self._half_step_ns = round(self.sim.timestep * NS / 2)
        self._dt = self.control_period
        self._period_ns = round(self._dt * NS)
        for ctrl in self._timed:
            ctrl.writer = self.hw.writer(ctrl.rows, ctrl.interface_name)
            ctrl.period_ns = period_ns(ctrl, self.control_period, self.sim.timestep)
            ctrl._max_time = ctrl.plugin.max_update_time or ctrl.period_ns / NS
            if ctrl.next_ns < 0:  # just started: its first update is now
                ctrl.next_ns = now
        self._next_period_ns = now
        self._wake()

    def _bind_inputs(self) -> None:
        """Each Python controller's `state.inputs`: read-only views of the running exporters'
        arrays, NaN where the exporter is stopped, missing or faulted."""
        for ctrl in self.controllers.values():
            if not isinstance(ctrl, PythonRunner):
                continue
            wanted = declared_lengths(ctrl.plugin.cls, "inputs")
            bound = {}
            for local, source in ctrl.plugin.inputs.items():
                owner, export = source.split("/")
                exporter = self.controllers.get(owner)
                array = getattr(exporter, "exports", {}).get(export) \
                    if exporter is not None and exporter.running else None
                if array is None or len(array) != wanted[local]:
                    array = np.full(wanted[local], np.nan)
                view = array.view()
                view.flags.writeable = False
                bound[local] = view
            ctrl.state.inputs = bound

    def exports(self) -> dict[str, np.ndarray]:
        """Every Python controller's exported state interfaces, "<controller>/<name>" -> a
        read-only view (chained controllers; NaN until written)."""
        out = {}
        for ctrl in self.controllers.values():
            for key, array in getattr(ctrl, "exports", {}).items():
                view = array.view()
                view.flags.writeable = False
                out[f"{ctrl.name}/{key}"] = view
        return out

    # ----- `state` topics (published only while someone listens) ---------------------------------
    def state_topic(self, name: str) -> str:
        """The JointControllerState topic of controller `name` (/<ns>/<name>/state)."""
        return f"{self.namespace}/{name}/state"

    def _watch_state(self, topic: str) -> None:
        if topic not in self._state_topics:
            self._state_topics.add(topic)
            self.bus.advertise(topic, JointControllerState)
            self.bus.on_subscribers(topic, lambda _count: self._state_wanted())

    def _state_wanted(self) -> None:
        """Subscribers changed (simulation thread): run the 100 Hz publisher only if needed."""
        wanted = any(self.bus.wanted(t) for t in self._state_topics)
        if wanted and self._state_timer is None:
            self._state_timer = self.sim.add_periodic(1.0 / STATE_RATE, self._publish_states)
        elif not wanted and self._state_timer is not None:
            self.sim.remove_periodic(self._state_timer)
            self._state_timer = None

    def _publish_states(self, sim: Simulation) -> None:
        stamp = Time.from_nsec(sim.time_ns)
        for ctrl in self._running:
            if not ctrl.has_state:
                continue
            topic = self.state_topic(ctrl.name)
            if self.bus.wanted(topic):
                self._state_seq += 1
                msg = ctrl.state_message(self.control_period)
                msg.header = Header(self._state_seq, stamp, "")
                self.bus.publish(topic, msg)

    def close(self) -> None:
        """Stop every controller and leave the simulation (its robot was deleted)."""
        self.switch(stop=[c.name for c in self._running])
        if self._state_timer is not None:
            self.sim.remove_periodic(self._state_timer)
            self._state_timer = None
        self.sim.remove_control(self)
        for ctrl in self.controllers.values():
            if isinstance(ctrl, PythonRunner):
                ctrl.close()

    def restart(self) -> None:
        """Stop and start every running controller (after a reset: they hold the new pose)."""
        running = [c.name for c in self.controllers.values() if c.running]
        self.switch(stop=running)
        self.switch(start=running)

    def list_controllers(self) -> list[ControllerInfo]:
        """Every loaded controller: name, type, state, joints, interface and, for a Python
        controller, its rate, time per update, fault and parameters (controller_manager's
        list_controllers)."""
        out = []
        for c in self.controllers.values():
            info = ControllerInfo(c.name, c.type.name, "running" if c.running else "stopped",
                                  tuple(c.joints), c.interface)
            if isinstance(c, PythonRunner):
                info = replace(info, update_rate=NS / c.period_ns if c.running else
                               c.plugin.update_rate, update_time=c.update_time, fault=c.fault,
                               params=c.params, deadline_misses=c.meter.misses,
                               update_time_max=c.meter.worst)
            out.append(info)
        return out

    def list(self) -> builtins.list[ControllerInfo]:
        """The former name of `list_controllers` (it shadowed the built-in), for one release."""
        warn_renamed("ControllerManager.list", "ControllerManager.list_controllers")
        return self.list_controllers()

    # ----- Python controllers: reload and live parameters (simulation thread) -------------------
    def reload(self, name: str) -> None:
        """Import the student's file again and restart controller `name` in place (if it ran, or
        was stopped by a fault). An import, parameter or configure error raises (one line, their
        file:line) and leaves the old controller as it was."""
        old = self._get(name)
        if not isinstance(old, PythonRunner):
            raise InputError(f"controller '{name}' is a shipped type ({old.type.name}): nothing "
                             "to reload", hint="reload re-imports a Python controller's file")
        spec, plugin = old.spec, old.plugin
        if plugin.handed:  # a class handed over in Python: a fresh object of the same class
            cls, origin = plugin.cls, plugin.origin
        else:
            cls, origin = resolve(spec.type, plugin.yaml_dir, list(CONTROLLER_TYPES), fresh=True)
        params = validate_params(cls, plugin.raw, name, plugin.source)
        declared = cls.declared_params()
        for key, value in old.params.items():  # live changes survive when still valid
            if key in declared:
                with contextlib.suppress(InputError):
                    params[key] = declared[key].check(value)
        new_spec = replace(spec, plugin=replace(plugin, cls=cls, origin=origin, params=params))
        new = _runner(new_spec)(new_spec, self._ctx)  # configures: may raise
        restart = old.running or old.fault is not None
        if old.running:
            self.switch(stop=[name])
        self.controllers[name] = new
        self.config.controllers[name] = new_spec
        old.close()
        if restart:
            self.switch(start=[name])
        log.info("%s: reloaded from %s", name, origin)

    def set_param(self, name: str, key: str, value: Any) -> Any:
        """Set a Python controller's declared parameter live (validated as the YAML's)."""
        ctrl = self._get(name)
        if not isinstance(ctrl, PythonRunner):
            raise InputError(f"controller '{name}' ({ctrl.type.name}) has no declared parameters",
                             hint="PID gains: set_gains")
        return ctrl.set_param(key, value)

    @staticmethod
    def list_types() -> builtins.list[str]:
        """Every ros_control type name a YAML may use (controller_manager's list_controller_types)."""
        return list(CONTROLLER_TYPES)

    def by_joint(self) -> dict[str, ControllerInterface]:
        """joint -> the running controller that drives it."""
        return {j: c for c in self._running for j in c.joints}

    # ----- what front ends change and read (simulation thread) -------------------------------------
    def set_gains(self, name: str, gains: PidGains | Sequence[PidGains],
                  joints: Sequence[str] | None = None) -> None:
        """Retune controller `name` live (all its joints, or `joints`); takes effect at once."""
        ctrl = self._get(name)
        current = ctrl.gains
        if current is None:
            raise InputError(f"controller '{name}' has no PID gains to set")
        if isinstance(gains, PidGains):
            gains = [gains] * len(joints if joints is not None else ctrl.joints)
        for g in gains:
            problem = g.problem()
            if problem:
                raise InputError(f"gains for '{name}': {problem}", hint="use finite gains >= 0")
        if joints is not None:
            unknown = [j for j in joints if j not in ctrl.joints]
            if unknown:
                raise InputError(f"controller '{name}' does not drive {', '.join(unknown)}",
                                 hint="its joints: " + ", ".join(ctrl.joints))
            for joint, g in zip(joints, gains, strict=True):
                current[ctrl.joints.index(joint)] = g
            gains = current
        ctrl.set_gains(list(gains))
        self._schedule()

    def command(self, name: str, values: dict[str, float] | Sequence[float]) -> None:
        """Publish a command to controller `name` on its topic, as any node would: `values` per
        joint (a dict may name some joints; the others keep their setpoint)."""
        ctrl = self._get(name)
        if ctrl.msg_type is None:
            raise InputError(f"controller '{name}' computes its own commands; it takes none",
                             hint="change its parameters (set_param) or stop it")
        if isinstance(values, dict):
            current = ctrl.setpoint
            unknown = [j for j in values if j not in ctrl.joints]
            if unknown:
                raise InputError(f"controller '{name}' does not drive {', '.join(unknown)}",
                                 hint="its joints: " + ", ".join(ctrl.joints))
            values = [values.get(j, current[i]) for i, j in enumerate(ctrl.joints)]
        values = [float(v) for v in values]
        msg = Float64(values[0]) if ctrl.msg_type is Float64 else Float64MultiArray(values)
        self.bus.publish(self.topic(name), msg)

    def setpoints(self) -> np.ndarray:
        """What every actuated joint is commanded now (hardware order; rad, rad/s or N m as its
        controller takes commands; 0 without a controller)."""
        out = np.zeros(len(self.hw.joints))
        for ctrl in self._running:
            if ctrl.drives_joints:
                out[ctrl.rows] = ctrl.setpoint
        return out


def _runner(spec: ControllerSpec) -> type[PythonRunner]:
    """A Python controller's runner: in a worker process unless its class is mexone's own or was
    handed over in Python (control/worker.py)."""
    return IsolatedRunner if spec.plugin.isolated else PythonRunner
