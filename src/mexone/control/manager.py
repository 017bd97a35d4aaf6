"""ControllerManager: load, start, stop, switch and list controllers; run their update loop.

As in ros_control: controllers are configured from the parameter file, claim joints through the
hardware interface (one running controller per joint), listen on ``/<ns>/<name>/command``, and
``joint_state_controller`` publishes ``/<ns>/joint_states``. The update runs every control
period of sim time, and only when a running controller needs it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from mexone.bus.msgs import Header, JointState, Time
from mexone.bus.topics import Bus, Subscription
from mexone.control.config import ControlConfig, ControllerSpec
from mexone.control.controllers import Controller, make_controller
from mexone.control.hardware import SimHardware
from mexone.control.servo import ServoBank
from mexone.errors import InputError
from mexone.physics.simulation import Simulation

__all__ = ["ControllerManager", "ControllerInfo", "JointStatePublisher"]

log = logging.getLogger("mexone.control")


@dataclass(frozen=True)
class ControllerInfo:
    name: str
    type: str
    state: str  # "running" or "stopped"
    joints: tuple[str, ...]


class JointStatePublisher:
    """joint_state_controller: every actuated joint, alphabetical, stamped with sim time,
    published when last + 1/rate <= t."""

    def __init__(self, spec: ControllerSpec, hw: SimHardware, bus: Bus, topic: str):
        self.spec, self.hw, self.bus, self.topic = spec, hw, bus, topic
        self.name = spec.name
        order = sorted(hw.joints)
        self.names = order
        self.rows = np.array([hw.index[j] for j in order], dtype=int)
        self.period = 1.0 / (spec.publish_rate or 50.0)
        self.timer = None
        self.seq = 0
        self.running = False
        bus.advertise(topic, JointState)

    def publish(self, sim: Simulation) -> None:
        self.seq += 1
        msg = JointState(Header(self.seq, Time.from_sec(sim.time), ""), list(self.names),
                         self.hw.position(self.rows).tolist(), self.hw.velocity(self.rows).tolist(),
                         self.hw.effort(self.rows).tolist())
        self.bus.publish(self.topic, msg)


class ControllerManager:
    def __init__(self, sim: Simulation, bus: Bus, config: ControlConfig,
                 namespace: str | None = None, control_period: float | None = None):
        self.sim, self.bus, self.config = sim, bus, config
        ns = namespace or config.namespace or (sim.robot.ros_namespace or "").strip("/") \
            or sim.robot.name
        self.namespace = "/" + ns.strip("/")
        self.hw = SimHardware(sim)
        self.bank = ServoBank(self.hw)
        self.control_period = control_period or sim.timestep
        if self.control_period < sim.timestep * (1 - 1e-9):
            raise InputError(f"control period {self.control_period} s is shorter than the physics "
                             f"step {sim.timestep} s")
        self.controllers: dict[str, Controller] = {}
        self.publishers: dict[str, JointStatePublisher] = {}
        self._subs: dict[str, Subscription] = {}
        self._scheduled = None
        self._warn_about_gazebo_differences()

    # ----- loading --------------------------------------------------------------------------
    def topic(self, name: str) -> str:
        return f"{self.namespace}/{name}/command"

    def load(self, name: str) -> None:
        spec = self.config.controllers.get(name)
        if spec is None:
            raise InputError(f"no controller named '{name}' in the configuration",
                             hint="controllers: " + ", ".join(self.config.controllers))
        if name in self.controllers or name in self.publishers:
            return
        if spec.kind == "state":
            self.publishers[name] = JointStatePublisher(spec, self.hw, self.bus,
                                                        f"{self.namespace}/joint_states")
            return
        missing = [j for j in spec.joints if j not in self.sim.robot.joints]
        if missing:
            raise InputError(f"controller '{name}' names joint '{missing[0]}', which the robot "
                             "does not have", file=spec.source, line=spec.line,
                             hint="joints: " + ", ".join(self.hw.joints))
        try:
            self.controllers[name] = make_controller(spec, self.hw, self.bank, self.config.pid_gains)
        except InputError as exc:
            raise exc.located(spec.source or "<controllers>", spec.line) from None

    def load_all(self) -> list[str]:
        for name in self.config.controllers:
            self.load(name)
        return list(self.config.controllers)

    # ----- running --------------------------------------------------------------------------
    def start(self, *names: str) -> None:
        self.switch(start=names)

    def stop(self, *names: str) -> None:
        self.switch(stop=names)

    def switch(self, start=(), stop=()) -> None:
        """Stop then start, refusing two running controllers on one joint (ros_control's rule)."""
        for name in list(start) + list(stop):
            if name not in self.controllers and name not in self.publishers:
                self.load(name)
        claimed = {j: c.name for c in self.controllers.values()
                   if c.running and c.name not in stop for j in c.joints}
        for name in start:
            ctrl = self.controllers.get(name)
            if ctrl is None or ctrl.running:
                continue
            for joint in ctrl.joints:
                if claimed.get(joint, name) != name:
                    raise InputError(f"cannot start '{name}': joint '{joint}' is driven by "
                                     f"'{claimed[joint]}'", hint="stop that controller first")
                claimed[joint] = name
        for name in stop:
            self._stop(name)
        for name in start:
            self._start(name)
        self.reschedule()

    def _start(self, name: str) -> None:
        if name in self.publishers:
            pub = self.publishers[name]
            if not pub.running:
                pub.running = True
                pub.timer = self.sim.add_periodic(pub.period, pub.publish)
            return
        ctrl = self.controllers[name]
        if ctrl.running:
            return
        ctrl.start(self.sim.time)
        self._subs[name] = self.bus.subscribe(self.topic(name), ctrl.msg_type, ctrl.command)

    def _stop(self, name: str) -> None:
        if name in self.publishers:
            pub = self.publishers[name]
            if pub.running:
                pub.running = False
                self.sim.remove_periodic(pub.timer)
            return
        ctrl = self.controllers.get(name)
        if ctrl is None or not ctrl.running:
            return
        ctrl.stop()
        self._subs.pop(name).unregister()

    def restart(self) -> None:
        """Stop and start every running controller (after a reset: they hold the new pose)."""
        running = [c.name for c in self.list() if c.state == "running"]
        self.switch(stop=running)
        self.switch(start=running)

    def start_all(self) -> None:
        self.load_all()
        self.switch(start=list(self.config.controllers))

    def list(self) -> list[ControllerInfo]:
        out = [ControllerInfo(p.name, p.spec.type, "running" if p.running else "stopped", ())
               for p in self.publishers.values()]
        out += [ControllerInfo(c.name, c.spec.type, "running" if c.running else "stopped",
                               tuple(c.joints)) for c in self.controllers.values()]
        return out

    def reschedule(self) -> None:
        """(Re)install the per-period update for what the running controllers need now."""
        active = [c for c in self.controllers.values() if c.running and c.needs_update]
        self.sim.controllers_active = any(c.running for c in self.controllers.values())
        if self._scheduled is not None:
            kind, handle = self._scheduled
            if kind == "hook":
                self.sim.remove_hook(handle)
            else:
                self.sim.remove_periodic(handle)
            self._scheduled = None
        bank = self.bank
        if not active and not bank.integrating.any():
            return
        dt = self.control_period

        def update(sim: Simulation) -> None:
            for ctrl in active:
                ctrl.update(sim.time, dt)
            bank.integrate(dt)

        if abs(dt - self.sim.timestep) < 1e-12:
            self.sim.add_hook(update)
            self._scheduled = ("hook", update)
        else:
            self._scheduled = ("periodic", self.sim.add_periodic(dt, update))
        update(self.sim)

    def by_joint(self) -> dict[str, Controller]:
        return {j: c for c in self.controllers.values() if c.running for j in c.joints}

    # ----- what Gazebo 7 would have done differently -------------------------------------------
    def _warn_about_gazebo_differences(self) -> None:
        for spec in self.config.controllers.values():
            if spec.type.startswith("position_controllers/") and spec.pid and not spec.ideal_servo:
                log.warning("%s: Gazebo 7 ignored this pid: block and teleported the joint "
                            "(SetPosition); mexone applies the PID as a torque, so the joint has "
                            "real dynamics (ideal_servo: true restores Gazebo's behaviour)",
                            spec.name)
            gains = [spec.pid] if spec.pid else []
            gains += list((spec.gains or {}).values())
            if any(g.i and not (g.i_clamp_min or g.i_clamp_max) for g in gains):
                log.warning("%s: i is set but i_clamp_min/i_clamp_max are 0, so there is no "
                            "integral action (ROS clamps the integral term to 0); set the clamps",
                            spec.name)
