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
        self._geom_ids = np.array(sorted(mine), dtype=np.int32)
        self.outputs = [Output(topic_name(self.namespace, self.spec.topic or self.spec.name),
                               ContactsState)]

    def contacts(self) -> list[ContactState]:
        model, data = self.sim.model, self.sim.data
        states: dict[tuple[int, int], ContactState] = {}
        force6 = np.zeros(6)
        ncon = data.ncon
        if ncon == 0:
            return []
        pairs = data.contact.geom[:ncon]  # one vector test, then Python only for our contacts
        for i in np.flatnonzero(np.isin(pairs, self._geom_ids).any(axis=1)).tolist():
            contact = data.contact[i]
            g1, g2 = int(pairs[i, 0]), int(pairs[i, 1])
            if g1 in self.geoms:
                own, other, sign = g1, g2, -1.0  # MuJoCo's force acts on geom2, along the normal
            elif g2 in self.geoms:
                own, other, sign = g2, g1, 1.0
            else:
                continue
            mujoco.mj_contactForce(model, data, i, force6)
            frame = contact.frame.reshape(3, 3)
            force = sign * (frame.T @ force6[:3])
            normal = sign * frame[0]
            state = states.get((own, other))
            if state is None:
                state = states[(own, other)] = ContactState(
                    info=f"Debug: i:({i}/{data.ncon})", collision1_name=self.names[own][1],
                    collision2_name=self.names.get(other, ("", model.geom(other).name))[1])
            point = contact.pos
            state.wrenches.append(Wrench(Vector3(*force.tolist()), Vector3()))
            state.contact_positions.append(Vector3(*point.tolist()))
            state.contact_normals.append(Vector3(*normal.tolist()))
            state.depths.append(float(max(-contact.dist, 0.0)))
            total = state.total_wrench.force
            total.x, total.y, total.z = total.x + force[0], total.y + force[1], total.z + force[2]
        return list(states.values())

    def publish(self, sim) -> None:
        msg = ContactsState(self.header("world"), self.contacts())
        self.bus.publish(self.outputs[0].topic, msg)
