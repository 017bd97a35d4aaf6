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
        self._mine_list = [g in mine for g in range(self.sim.model.ngeom)]  # geom id -> ours
        self._force6 = np.zeros(6)
        self.outputs = [Output(topic_name(self.namespace, self.spec.topic or self.spec.name),
                               ContactsState)]

    def contacts(self) -> list[ContactState]:
        """Our contacts, grouped by pair of collision elements. MuJoCo's contact arrays are
        read once each and the few contacts of one sole handled in plain Python: at a handful
        of points per sole, per-point numpy calls cost more than the arithmetic."""
        model, data = self.sim.model, self.sim.data
        ncon = data.ncon
        if ncon == 0:
            return []
        mine = self._mine_list
        picked = [(i, g1, g2) for i, (g1, g2) in enumerate(data.contact.geom[:ncon].tolist())
                  if mine[g1] or mine[g2]]
        if not picked:
            return []
        index = [i for i, _, _ in picked]
        frames = data.contact.frame[index].tolist()  # rows: normal, two tangents (world)
        positions = data.contact.pos[index].tolist()
        dists = data.contact.dist[index].tolist()
        local = self._force6
        states: dict[tuple[int, int], ContactState] = {}
        totals: dict[tuple[int, int], list[float]] = {}
        for k, (i, g1, g2) in enumerate(picked):
            # MuJoCo's force acts on geom2, along the normal (from geom1 to geom2)
            own, other, sign = (g1, g2, -1.0) if mine[g1] else (g2, g1, 1.0)
            mujoco.mj_contactForce(model, data, i, local)
            fn, t1, t2 = local[0] * sign, local[1] * sign, local[2] * sign
            f = frames[k]
            force = [fn * f[0] + t1 * f[3] + t2 * f[6], fn * f[1] + t1 * f[4] + t2 * f[7],
                     fn * f[2] + t1 * f[5] + t2 * f[8]]
            pair = (own, other)
            state = states.get(pair)
            if state is None:
                state = states[pair] = ContactState(
                    info=f"Debug: i:({i}/{ncon})", collision1_name=self.names[own][1],
                    collision2_name=self.names[other][1] if other in self.names
                    else model.geom(other).name)
                totals[pair] = [0.0, 0.0, 0.0]
            total = totals[pair]
            total[0], total[1], total[2] = total[0] + force[0], total[1] + force[1], total[2] + force[2]
            state.wrenches.append(Wrench(Vector3(*force), Vector3()))
            state.contact_positions.append(Vector3(*positions[k]))
            state.contact_normals.append(Vector3(sign * f[0], sign * f[1], sign * f[2]))
            state.depths.append(max(-dists[k], 0.0))
        for pair, state in states.items():
            state.total_wrench.force = Vector3(*totals[pair])
        return list(states.values())

    def publish(self, sim) -> None:
        msg = ContactsState(self.header("world"), self.contacts())
        self.bus.publish(self.outputs[0].topic, msg)
