"""Contact sensor (gazebo_ros_bumper): gazebo_msgs/ContactsState naming what touches the link.

One ContactState per pair of colliding collision elements, named as Gazebo names them
(`model::link::collision`; the ground is `ground_plane::link::collision`), with every contact
point, its normal, depth and the force on the sensor's link, in the world frame.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mexone.bus.msgs import ContactsState, ContactState, Vector3, Wrench
from mexone.physics.compile import GROUP_VISUAL
from mexone.sensors.base import Output, Sensor, topic_name

__all__ = ["ContactSensor", "collision_names"]

GROUND_NAME = "ground_plane::link::collision"


def collision_names(sim) -> dict[int, tuple[str, str]]:
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


class ContactSensor(Sensor):
    def __post_init__(self) -> None:
        self.names = collision_names(self.sim)
        mine = {g for g, (link, scoped) in self.names.items() if link == self.link}
        if self.spec.collisions:  # only the collision elements it names, when it names them
            wanted = set(self.spec.collisions)
            mine = {g for g in mine if self.names[g][1].rsplit("::", 1)[1] in wanted} or mine
        self.geoms = mine
        self._mine = np.zeros(self.sim.model.ngeom, dtype=bool)  # geom id -> one of ours
        self._mine[sorted(mine)] = True
        self.outputs = [Output(topic_name(self.namespace, self.spec.topic or self.spec.name),
                               ContactsState)]

    def contacts(self) -> list[ContactState]:
        """Our contacts, grouped by pair of collision elements. Vectorised over MuJoCo's contact
        arrays: at 50 Hz on two soles this ran once per message in Python per contact point."""
        model, data = self.sim.model, self.sim.data
        ncon = data.ncon
        if ncon == 0:
            return []
        pairs = data.contact.geom[:ncon]
        ours = self._mine[pairs]  # (ncon, 2)
        index = np.flatnonzero(ours.any(axis=1))
        if index.size == 0:
            return []
        first = ours[index, 0]  # ours is geom1: MuJoCo's force acts on geom2, along the normal
        own = np.where(first, pairs[index, 0], pairs[index, 1])
        other = np.where(first, pairs[index, 1], pairs[index, 0])
        sign = np.where(first, -1.0, 1.0)
        local = np.empty((index.size, 6))
        for row, i in enumerate(index.tolist()):
            mujoco.mj_contactForce(model, data, i, local[row])
        frames = data.contact.frame[index].reshape(-1, 3, 3)  # rows: normal, tangents (world)
        forces = sign[:, None] * np.einsum("kji,kj->ki", frames, local[:, :3])
        normals = sign[:, None] * frames[:, 0]
        positions = data.contact.pos[index]
        depths = np.maximum(-data.contact.dist[index], 0.0)
        states: dict[tuple[int, int], ContactState] = {}
        totals: dict[tuple[int, int], np.ndarray] = {}
        for k, pair in enumerate(zip(own.tolist(), other.tolist(), strict=True)):
            state = states.get(pair)
            if state is None:
                state = states[pair] = ContactState(
                    info=f"Debug: i:({int(index[k])}/{ncon})", collision1_name=self.names[pair[0]][1],
                    collision2_name=self.names.get(pair[1], ("", model.geom(pair[1]).name))[1])
                totals[pair] = np.zeros(3)
            totals[pair] += forces[k]
            state.wrenches.append(Wrench(Vector3(*forces[k].tolist()), Vector3()))
            state.contact_positions.append(Vector3(*positions[k].tolist()))
            state.contact_normals.append(Vector3(*normals[k].tolist()))
            state.depths.append(float(depths[k]))
        for pair, state in states.items():
            state.total_wrench.force = Vector3(*totals[pair].tolist())
        return list(states.values())

    def publish(self, sim) -> None:
        msg = ContactsState(self.header("world"), self.contacts())
        self.bus.publish(self.outputs[0].topic, msg)
