"""What every simulated sensor shares: its topics, its header, and lazily measured MuJoCo data.

A sensor publishes at its update rate in sim time, from the simulation thread, and only while
someone listens to one of its topics (as gazebo_ros plugins do): nobody listening, no timer, no
cost. MuJoCo's sensors are evaluated on demand (`Measure`), once per instant however many
sensors ask.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco

from mexone.bus.msgs import Header, Time
from mexone.bus.topics import Bus, resolve_name
from mexone.description.sensors import SensorSpec
from mexone.physics.simulation import Simulation

__all__ = ["Output", "Measure", "Sensor", "topic_name"]


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
    """MuJoCo's sensor values at the current instant, computed on the first request (the
    simulation steps with MuJoCo's sensor pass turned off)."""

    def __init__(self, sim: Simulation):
        self.sim = sim
        self._at = -1
        sim.model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_SENSOR

    def data(self):
        sim = self.sim
        if self._at != sim.time_ns:
            model, data = sim.model, sim.data
            flags = model.opt.disableflags
            model.opt.disableflags = flags & ~int(mujoco.mjtDisableBit.mjDSBL_SENSOR)
            try:  # the state the last step computed (positions, velocities, accelerations)
                mujoco.mj_sensorPos(model, data)
                mujoco.mj_sensorVel(model, data)
                mujoco.mj_sensorAcc(model, data)
            finally:
                model.opt.disableflags = flags
            self._at = sim.time_ns
        return sim.data.sensordata


@dataclass
class Sensor:
    spec: SensorSpec
    sim: Simulation
    bus: Bus
    namespace: str
    measure: Measure
    link: str
    outputs: list[Output] = field(default_factory=list)
    seq: int = 0

    def __post_init__(self) -> None:
        """Each sensor type finds its MuJoCo data and names its outputs here."""

    @property
    def frame(self) -> str:
        return self.spec.frame or self.link

    @property
    def rate(self) -> float:
        """Hz; 0 (Gazebo: as fast as possible) is every physics step."""
        return self.spec.update_rate or 1.0 / self.sim.timestep

    def header(self, frame: str | None = None) -> Header:
        self.seq += 1
        return Header(self.seq, Time.from_nsec(self.sim.time_ns), frame or self.frame)

    def wanted(self, output: Output) -> bool:
        topic = self.bus.topics.get(output.topic)
        if output.heavy:  # recorders alone do not make a camera render
            return topic is not None and bool(topic.subscriptions)
        return self.bus.wanted(output.topic)

    def publish(self, sim: Simulation) -> None:
        raise NotImplementedError
