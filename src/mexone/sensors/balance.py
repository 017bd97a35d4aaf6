"""The humanoid's balance quantities: whole-body centre of mass, the support polygon of the feet in
contact, and the centre of pressure (ZMP) measured by the foot force-torque sensors.

Published on `/<ns>/com`, `/<ns>/zmp` (geometry_msgs/PointStamped) and `/<ns>/support_polygon`
(geometry_msgs/PolygonStamped), all in the world frame. The robot is statically stable when the
projection of its COM lies inside the support polygon.

ZMP from the sensors: each foot sensor measures the wrench its parent applies to the foot at the
ankle; the ground's wrench on the foot is the opposite, less the foot's own weight (the foot
assumed at rest: its acceleration is small next to g while it carries the robot). Its centre of
pressure is where that wrench has no horizontal moment on the ground plane; the feet's centres
of pressure, weighted by their normal forces, give the ZMP.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from mexone.bus.msgs import Header, Point, Point32, PointStamped, Polygon, PolygonStamped, Time
from mexone.bus.topics import Bus
from mexone.physics.simulation import Simulation
from mexone.sensors.force_torque import ForceTorqueSensor

__all__ = ["Balance", "convex_hull", "inside", "centre_of_pressure", "BalanceState"]

MIN_LOAD = 1.0  # N: a foot carrying less than this is not on the ground
RATE = 50.0  # Hz, as joint_states


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b for two 3-vectors (np.cross costs ten times as much on this size)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def convex_hull(points: np.ndarray) -> np.ndarray:
    """2-D convex hull, counter-clockwise (Andrew's monotone chain)."""
    pts = sorted({(p[0], p[1]) for p in np.asarray(points, dtype=float).tolist()})
    if len(pts) < 3:
        return np.array(pts).reshape(-1, 2)

    def half(seq: Iterable[tuple[float, float]]) -> list[tuple[float, float]]:
        out: list[tuple[float, float]] = []
        for p in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (p[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(reversed(pts))
    return np.array(lower[:-1] + upper[:-1])


def inside(point: np.ndarray, hull: np.ndarray) -> bool:
    """Whether a 2-D point lies in a counter-clockwise convex polygon (edges included)."""
    if len(hull) < 3:
        return False
    edges = np.roll(hull, -1, axis=0) - hull
    rel = np.asarray(point[:2]) - hull
    return bool(np.all(edges[:, 0] * rel[:, 1] - edges[:, 1] * rel[:, 0] >= -1e-9))


def centre_of_pressure(force: np.ndarray, torque: np.ndarray, at: np.ndarray,
                       ground_z: float) -> np.ndarray | None:
    """Where on the plane z = ground_z the wrench (force, torque about `at`) has no horizontal
    moment; None if it does not push on the ground."""
    if force[2] < MIN_LOAD:
        return None
    rz = ground_z - at[2]
    rx = (rz * force[0] - torque[1]) / force[2]
    ry = (torque[0] + rz * force[1]) / force[2]
    return np.array([at[0] + rx, at[1] + ry, ground_z])


class BalanceState:
    """One instant's COM, support polygon and ZMP (numbers; the GUI draws them)."""

    def __init__(self, com: np.ndarray, polygon: np.ndarray, zmp: np.ndarray | None) -> None:
        self.com, self.polygon, self.zmp = com, polygon, zmp

    @property
    def statically_stable(self) -> bool:
        """Whether the COM's ground projection is inside the support polygon."""
        return inside(self.com, self.polygon)


class Balance:
    """A humanoid's balance quantities from its two foot force-torque sensors: the COM's ground
    projection, the support polygon and the measured ZMP (`state()`), and their topics
    (/<ns>/com, /<ns>/zmp, /<ns>/support_polygon), published while someone listens."""

    def __init__(self, sim: Simulation, bus: Bus, namespace: str, feet: list[ForceTorqueSensor]) -> None:
        self.sim, self.bus, self.feet = sim, bus, feet
        self.topics = {"com": f"{namespace}/com", "zmp": f"{namespace}/zmp",
                       "support_polygon": f"{namespace}/support_polygon"}
        self.types = {"com": PointStamped, "zmp": PointStamped, "support_polygon": PolygonStamped}
        for key, topic in self.topics.items():  # listed, so bridges and GUIs can offer them
            bus.advertise(topic, self.types[key])
        model = sim.model
        ground = [g for g in range(model.ngeom) if model.geom(g).name == "ground_plane"]
        self.ground = ground[0] if ground else None
        self.ground_z = float(model.geom_pos[self.ground][2]) if ground else 0.0
        robot_bodies = set(sim.compiled.bodies.values())
        self.robot_geoms = {g for g in range(model.ngeom) if model.geom_bodyid[g] in robot_bodies}
        self._robot_geom = [g in self.robot_geoms for g in range(model.ngeom)]  # id -> robot's
        # each foot's weight acts at its subtree's centre of mass
        self.foot_bodies = [model.site_bodyid[f.site] for f in feet]
        self.seq = 0

    def state(self) -> BalanceState:
        """The balance quantities now (COM, support polygon, ZMP)."""
        sim = self.sim
        data = sim.data
        com = data.subtree_com[sim.compiled.root_body].copy()
        polygon = np.zeros((0, 2))
        if self.ground is not None and data.ncon:
            ground, robot = self.ground, self._robot_geom
            on_ground = [i for i, (g1, g2) in enumerate(data.contact.geom[:data.ncon].tolist())
                         if (g1 == ground and robot[g2]) or (g2 == ground and robot[g1])]
            if on_ground:
                polygon = convex_hull(data.contact.pos[on_ground])
        return BalanceState(com, polygon, self.zmp())

    def zmp(self) -> np.ndarray | None:
        """The measured ZMP, from the foot sensors; None when no foot carries load."""
        model, data = self.sim.model, self.sim.data
        gravity = model.opt.gravity
        total, weighted = 0.0, np.zeros(3)
        for sensor, body in zip(self.feet, self.foot_bodies, strict=True):
            force, torque, at = sensor.parent_on_child_world()
            mass = model.body_subtreemass[body]
            com = data.subtree_com[body]
            ground_force = -force - mass * gravity  # the foot at rest: the ground holds the rest
            ground_torque = -torque - _cross(com - at, mass * gravity)
            cop = centre_of_pressure(ground_force, ground_torque, at, self.ground_z)
            if cop is not None:
                total += ground_force[2]
                weighted += cop * ground_force[2]
        return weighted / total if total > 0 else None

    def publish(self, sim: Simulation) -> None:
        """The broadcaster's tick: /com, /zmp and /support_polygon for their listeners."""
        wanted = {k for k, t in self.topics.items() if self.bus.wanted(t)}
        if not wanted:
            return
        self.seq += 1
        header = Header(self.seq, Time.from_nsec(sim.time_ns), "world")
        state = self.state()
        if "com" in wanted:
            self.bus.publish(self.topics["com"], PointStamped(header, Point(*state.com.tolist())))
        if "zmp" in wanted and state.zmp is not None:
            self.bus.publish(self.topics["zmp"], PointStamped(header, Point(*state.zmp.tolist())))
        if "support_polygon" in wanted:
            polygon = Polygon([Point32(float(x), float(y), self.ground_z) for x, y in state.polygon])
            self.bus.publish(self.topics["support_polygon"], PolygonStamped(header, polygon))
