"""Lab: one simulation with its topics and controllers, assembled the way every front end
(`mexone sim`, `mexone run`, the GUI, the ROS bridge) needs it."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from mexone.bus.msgs import Clock, Time
from mexone.bus.topics import Bus
from mexone.control.config import ControlConfig, load_control_config
from mexone.control.manager import ControllerManager
from mexone.description.loader import load_model
from mexone.description.model import RobotModel
from mexone.physics.compile import CompileOptions, Spawn
from mexone.physics.simulation import Simulation
from mexone.physics.world import World, default_world
from mexone.robots import mex_one

__all__ = ["Lab", "CLOCK_RATE"]

CLOCK_RATE = 1000.0  # Hz of /clock, as gazebo_ros publishes it (only while someone listens)


@dataclass
class Lab:
    sim: Simulation
    bus: Bus
    controllers: ControllerManager | None

    @classmethod
    def create(cls, model: RobotModel | Path | str | None = None,
               controllers: ControlConfig | Path | str | bool | None = None,
               world: World | None = None, spawn: Spawn = Spawn(),
               options: CompileOptions = CompileOptions(), target_rtf: float | None = None,
               control_period: float | None = None) -> Lab:
        """model None: the built-in Mex-One. controllers None: the built-in robot's YAML (or none
        for other robots); False: no controllers; a path or ControlConfig: that one."""
        builtin = model is None
        robot = model if isinstance(model, RobotModel) else load_model(model or mex_one.urdf_path())
        sim = Simulation(robot, world or default_world(), spawn, options, target_rtf)
        bus = Bus()
        if controllers is None:
            controllers = mex_one.controllers_path() if builtin else False
        manager = None
        if controllers is not False:
            config = controllers if isinstance(controllers, ControlConfig) \
                else load_control_config(controllers)
            manager = ControllerManager(sim, bus, config, control_period=control_period)
            manager.start_all()
        lab = cls(sim, bus, manager)
        bus.on_subscribers("/clock", lab._clock_listeners)
        return lab

    @property
    def namespace(self) -> str:
        if self.controllers:
            return self.controllers.namespace
        return "/" + ((self.sim.robot.ros_namespace or "").strip("/") or self.sim.robot.name)

    def _clock_listeners(self, count: int) -> None:
        """Publish /clock only while someone listens: a 1 kHz publisher costs a Python call
        per physics step."""
        timer = self.__dict__.get("_clock_timer")
        if count and timer is None:
            self._clock_timer = self.sim.add_periodic(1.0 / CLOCK_RATE, self._publish_clock)
        elif not count and timer is not None:
            self.sim.remove_periodic(timer)
            self._clock_timer = None

    def _publish_clock(self, sim: Simulation) -> None:
        self.bus.publish("/clock", Clock(Time.from_sec(sim.time)))
