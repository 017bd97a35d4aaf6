"""Contact sensor (gazebo_ros_bumper): gazebo_msgs/ContactsState naming what touches the link; its
state interfaces are whether it touches anything and the total force on it.

One ContactState per pair of colliding collision elements, named as Gazebo names them
(`model::link::collision`; the ground is `ground_plane::link::collision`), with every contact
point, its normal, depth and the force on the sensor's link, in the world frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from mexone.bus.msgs import ContactsState, ContactState, Header, Vector3, Wrench
from mexone.description.model import RobotModel
from mexone.description.sensors import SensorSpec
from mexone.physics.compile import GROUP_VISUAL
from mexone.physics.simulation import Simulation
from mexone.sensors.base import Sensor, register_sensor
from mexone.sensors.build import sensor_link

__all__ = ["ContactSensor", "ContactSensorState", "collision_names"]

GROUND_NAME = "ground_plane::link::collision"
# MuJoCo's contact sensor: whether a geom touches anything and the net force it applies, summed
# in C in the sensor pass every other sensor shares
_FOUND_AND_FORCE = (1 << int(mujoco.mjtConDataField.mjCONDATA_FOUND)) \
    | (1 << int(mujoco.mjtConDataField.mjCONDATA_FORCE))
_NETFORCE = 3  # mjtConReduce's netforce: the sum over matching contacts, world frame


def watched_collisions(robot: RobotModel, link: str, wanted: tuple[str, ...]) -> list[int]:
    """Indices of the link's collision elements a contact sensor watches: those it names (by
    Gazebo's element name), or all of them when it names none or none of those it names."""
    names = [col.name or (f"{link}_collision" if i == 0 else f"{link}_collision_{i}")
             for i, col in enumerate(robot.links[link].collisions)]
    picked = [i for i, n in enumerate(names) if n in set(wanted)] if wanted else []
    return picked or list(range(len(names)))


def collision_names(sim: Simulation) -> dict[int, tuple[str, str]]:
    """MuJoCo collision geom -> (link, Gazebo's scoped name of the collision element)."""
    model, robot = sim.model, sim.robot
    out: dict[int, tuple[str, str]] = {}
    for link in sim.compiled.bodies:
        for i, col in enumerate(robot.links[link].collisions):
            geom = model.geom(f"{link}/collision/{i}").id
            element = col.name or (f"{link}_collision" if i == 0 else f"{link}_collision_{i}")
            out[geom] = (link, f"{robot.name}::{link}::{element}")
    for geom in range(model.ngeom):
        if geom not in out and model.geom_group[geom] != GROUP_VISUAL:  # the world's bodies
            name = model.geom(geom).name
            out[geom] = ("", GROUND_NAME if name == "ground_plane" else f"{name}::link::collision")
    return out


@dataclass(frozen=True)
class ContactSensorState:
    """The contact sensor's state interfaces."""

    force: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """N, world frame: the total force the contacts apply to the sensor's link"""
    count: np.ndarray = field(default_factory=lambda: np.zeros(1))
    """how many contact points touch its collision elements"""

    @property
    def in_contact(self) -> bool:
        """Whether any of its collision elements touches something."""
        return bool(self.count[0] > 0)


@register_sensor("contact")
class ContactSensor(Sensor):
    """Gazebo's contact sensor (libgazebo_ros_bumper.so) on a link's collisions: state
    `in_contact`, `force`, `count`; broadcasts gazebo_msgs/ContactsState."""

    state_type = ContactSensorState
    message_type = ContactsState
    broadcaster = "gazebo_ros_bumper"
    plot = {"force": "N"}
    linear = True

    @classmethod
    def build(cls, spec: mujoco.MjSpec, body: mujoco.MjsBody, sensor: SensorSpec,
              robot: RobotModel) -> None:
        """A MuJoCo contact sensor per watched collision geom (found, net force): the state
        interfaces come out of the shared sensor pass, with no Python per contact."""
        link = sensor_link(robot, sensor)  # checked: build_sensors found its body
        for i in watched_collisions(robot, link, sensor.collisions):
            geom = f"{link}/collision/{i}"
            if spec.geom(geom) is None:
                continue
            mj = spec.add_sensor(name=f"{sensor.name}/{i}", type=mujoco.mjtSensor.mjSENS_CONTACT,
                                 objtype=mujoco.mjtObj.mjOBJ_GEOM, objname=geom)
            params = np.zeros(len(mj.intprm), dtype=int)
            params[:3] = (_FOUND_AND_FORCE, _NETFORCE, 1)
            mj.intprm = params

    def setup(self) -> None:
        model = self.sim.model
        adrs = []
        for i in watched_collisions(self.sim.robot, self.link, self.spec.collisions):
            try:
                adrs.append(int(model.sensor_adr[model.sensor(f"{self.spec.name}/{i}").id]))
            except KeyError:
                continue
        # sensordata per geom: found, then the net force it applies (3): the force on the link
        # is minus their sum, and the count their sum
        rows = np.array([a + k for a in adrs for k in range(4)], dtype=int)
        matrix = np.zeros((4, len(rows)))
        for j in range(len(adrs)):
            matrix[0:3, 4 * j + 1:4 * j + 4] = -np.eye(3)
            matrix[3, 4 * j] = 1.0
        if len(rows):
            self.measure.linear(rows, matrix, self.bind(force=slice(0, 3), count=slice(3, 4)))
        else:
            self.linear = False  # type: ignore[misc]  # this one: nothing to watch, never in contact
            state = self._state
            assert state is not None  # contact sensors have state interfaces
            for array in (state.force, state.count):
                array.flags.writeable = False
        self.names = collision_names(self.sim)
        mine = {g for g, (link, scoped) in self.names.items() if link == self.link}
        if self.spec.collisions:  # only the collision elements it names, when it names them
            wanted = set(self.spec.collisions)
            mine = {g for g in mine if self.names[g][1].rsplit("::", 1)[1] in wanted} or mine
        self.geoms = mine
        self._mine_list = [g in mine for g in range(self.sim.model.ngeom)]  # geom id -> ours

    def contacts(self) -> list[ContactState]:
        """Our contacts at this instant, grouped by pair of collision elements (the message's
        states), from the instant's contact lists every contact sensor shares: a handful of
        points per sole, handled in plain Python (this runs between steps with the interpreter
        cold: every call and temporary counts, so the loop is written out flat)."""
        geoms, frames, positions, dists, local = self.measure.contacts()
        mine = self._mine_list
        pairs: dict[tuple[int, int], list[Any]] = {}  # (own, other) -> [first index, points...]
        i = 0
        for g1, g2 in geoms:
            # MuJoCo's force acts on geom2, along the normal (from geom1 to geom2)
            if mine[g1]:
                pair, sign = (g1, g2), -1.0
            elif mine[g2]:
                pair, sign = (g2, g1), 1.0
            else:
                i += 1
                continue
            points = pairs.get(pair)
            if points is None:
                points = pairs[pair] = [i]
            points.append((i, sign))
            i += 1
        if not pairs:
            return []
        names, ncon = self.names, len(geoms)
        vector, wrench = Vector3, Wrench
        out = []
        for (own, other), (first, *points) in pairs.items():
            wrenches, positions_out, normals, depths = [], [], [], []
            tx = ty = tz = 0.0
            for i, sign in points:
                fn, t1, t2 = local[i]
                n0, n1, n2, a0, a1, a2, b0, b1, b2 = frames[i]  # normal, two tangents (world)
                fx = sign * (fn * n0 + t1 * a0 + t2 * b0)
                fy = sign * (fn * n1 + t1 * a1 + t2 * b1)
                fz = sign * (fn * n2 + t1 * a2 + t2 * b2)
                tx += fx
                ty += fy
                tz += fz
                wrenches.append(wrench(vector(fx, fy, fz), vector()))
                positions_out.append(vector(*positions[i]))
                normals.append(vector(sign * n0, sign * n1, sign * n2))
                depth = dists[i]
                depths.append(-depth if depth < 0 else 0.0)
            out.append(ContactState(
                f"Debug: i:({first}/{ncon})", names[own][1],
                names[other][1] if other in names else self.sim.model.geom(other).name,
                wrenches, wrench(vector(tx, ty, tz), vector()), positions_out, normals, depths))
        return out

    def message(self, state: ContactSensorState) -> ContactsState:
        return ContactsState(self.header("world"), self.contacts())

    def publish(self, sim: Simulation) -> None:
        """The broadcaster's tick: the message is built from the contacts alone (the state
        interfaces need not be read for it)."""
        self.seq = seq = self.seq + 1
        self.bus.deliver(self._topic, ContactsState(Header(seq, self.measure.stamp(), "world"),
                                                    self.contacts()))

    def view(self) -> str:
        state = self.state()
        return f"{'🟢' if state.in_contact else '⚪'} `{self.link}` {float(state.force[2]):5.1f} N"
