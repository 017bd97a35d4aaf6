"""SensorSuite: a robot's sensors in a running simulation: their state interfaces for controllers
(`states`) and their broadcasters publishing on the bus.

`states[name]` is the sensor's state object at this instant, read on the first request of the
instant (the hardware's read phase: controllers and broadcasters at the same instant share one
reading). Each sensor's broadcaster runs on a timer at the sensor's update rate in sim time
(simulation thread), and only while someone listens to one of its topics: the timer is added when
the first subscriber comes and removed when the last one leaves, so declared sensors nobody reads
cost nothing per step.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from mexone.bus.topics import Bus
from mexone.physics.compile import lowest_point
from mexone.physics.simulation import Periodic, Simulation
from mexone.sensors.balance import RATE as BALANCE_RATE
from mexone.sensors.balance import Balance
from mexone.sensors.base import SENSOR_CLASSES, Measure, Sensor, SensorStates, sensor_namespace, sensor_type
from mexone.sensors.build import sensor_link
from mexone.sensors.force_torque import ForceTorqueSensor

__all__ = ["SensorSuite", "SENSOR_CLASSES"]

_ANKLE_HEIGHT = 0.25  # m: an FT sensor on a leaf link this close above the soles is a foot's


def _broadcast(sim: Simulation, sensors: list[Sensor]) -> None:
    for sensor in sensors:
        sensor.publish(sim)


class SensorSuite:
    """Every declared sensor of a robot and the balance quantities: `states` (what controllers
    read as state.sensors), the broadcasters (each publishing only while someone listens) and
    the plot signals."""

    def __init__(self, sim: Simulation, bus: Bus, namespace: str, override: str | None = None) -> None:
        self.sim, self.bus = sim, bus
        self.measure = Measure(sim)
        self.sensors: dict[str, Sensor] = {}
        for spec in sim.robot.sensors:
            if not spec.always_on:
                continue
            link = sensor_link(sim.robot, spec)
            self.sensors[spec.name] = sensor_type(spec.type)(
                spec, sim, bus, sensor_namespace(spec, namespace, override), self.measure, link)
        self.states = SensorStates(self.sensors)
        """name -> the sensor's state object at this instant (controllers' `state.sensors`)"""
        self.balance = Balance(sim, bus, namespace, self._feet())
        sim.on_model_change(self.close)  # a spawned model: renderers were built on the old one
        sim.on_reset(self._invalidate)
        self._timers: dict[str, Periodic] = {}  # "balance" -> its timer
        # the broadcasters: one timer per update period, publishing every listened-to sensor of
        # that period at once (one Python burst per tick, not one per sensor)
        self._groups: dict[int, tuple[Periodic, list[Sensor]]] = {}
        for name, sensor in self.sensors.items():
            for output in sensor.outputs:
                bus.advertise(output.topic, output.type)
                bus.on_subscribers(output.topic, partial(self._listener_count, name))
        for topic in self.balance.topics.values():
            bus.on_subscribers(topic, lambda _n: self._listeners_changed("balance"))

    def _invalidate(self) -> None:
        for sensor in self.sensors.values():
            sensor.invalidate()

    def _feet(self) -> list[ForceTorqueSensor]:
        """Force-torque sensors on leaf links near the soles: what the ZMP is measured with."""
        robot = self.sim.robot
        lowest = lowest_point(robot)
        frames = robot.link_frames
        feet = []
        for sensor in self.sensors.values():
            if isinstance(sensor, ForceTorqueSensor) and not robot.child_joints.get(sensor.link) \
                    and frames[sensor.link][2, 3] - lowest < _ANKLE_HEIGHT:
                feet.append(sensor)
        return feet

    @property
    def topics(self) -> dict[str, type]:
        """Every topic the sensors can publish, with its message type."""
        out = {o.topic: o.type for s in self.sensors.values() for o in s.outputs}
        out |= {t: self.balance.types[k] for k, t in self.balance.topics.items()}
        return out

    @property
    def light_topics(self) -> list[str]:
        """What a recorder asks for: everything but images and clouds."""
        heavy = {o.topic for s in self.sensors.values() for o in s.outputs if o.heavy}
        return [t for t in self.topics if t not in heavy]

    def broadcasting(self) -> list[str]:
        """The sensors (and "balance") whose broadcaster runs now: someone listens."""
        return [s.spec.name for _, group in self._groups.values() for s in group] \
            + list(self._timers)

    def _wanted(self, key: str) -> bool:
        if key == "balance":
            return any(self.bus.wanted(t) for t in self.balance.topics.values())
        sensor = self.sensors[key]
        return any(sensor.wanted(o) for o in sensor.outputs)

    def _listener_count(self, name: str, _count: int) -> None:
        self._listeners_changed(name)

    def _listeners_changed(self, key: str) -> None:
        wanted = self._wanted(key)
        if key == "balance":
            timer = self._timers.get(key)
            if wanted and timer is None:
                self._timers[key] = self.sim.add_periodic(1.0 / BALANCE_RATE, self.balance.publish)
            elif not wanted and timer is not None:
                self.sim.remove_periodic(self._timers.pop(key))
            return
        sensor = self.sensors[key]
        period = max(1, round(1e9 / sensor.rate))
        timer, group = self._groups.get(period, (None, []))
        if wanted and sensor not in group:
            group.append(sensor)
            if timer is None:
                timer = self.sim.add_periodic(period / 1e9, partial(_broadcast, sensors=group))
                self._groups[period] = (timer, group)
        elif not wanted and sensor in group:
            group.remove(sensor)
            if not group and timer is not None:
                self.sim.remove_periodic(timer)
                del self._groups[period]

    def close(self) -> None:
        """Release what the sensors hold (the cameras' renderers)."""
        for sensor in self.sensors.values():
            close = getattr(sensor, "close", None)
            if close is not None:
                close()

    def readings(self) -> dict[str, np.ndarray]:
        """Every sensor's plot signals now as plain arrays (see `Sensor.signals`), for GUIs and
        tests."""
        return {name: sensor.values() for name, sensor in self.sensors.items()
                if sensor.state_type is not None and sensor.plot}
