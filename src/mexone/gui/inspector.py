"""Click a link: Gazebo's property panel (inspect) or its force tool (push).

A click on the page sends a ray; the simulation thread casts it into MuJoCo (`mj_ray`, the
robot's geoms only), so the link and the point hit are the physics' own. Inspecting shows the
link as its URDF declares it (mass, centre of mass, principal inertia) and as it is now (pose,
velocity, contacts, the joint above it). Pushing applies an impulse at that point for a short
time in sim time (`Simulation.apply_wrench`), drawn as an arrow while it acts.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import viser

from mexone.lab import Lab

__all__ = ["Inspector", "CLICK_MODES", "PUSH_DIRECTIONS", "hit", "link_report"]

CLICK_MODES = ("inspect", "push")
PUSH_DIRECTIONS = ("away from the camera", "+x", "-x", "+y", "-y", "+z", "-z")
ARROW_METRES_PER_NS = 0.02  # a 40 N s push draws 0.8 m
_AXES = {"+x": (1, 0, 0), "-x": (-1, 0, 0), "+y": (0, 1, 0), "-y": (0, -1, 0), "+z": (0, 0, 1),
         "-z": (0, 0, -1)}


def hit(lab: Lab, origin, direction) -> tuple[str, np.ndarray] | None:
    """(link, world point) where the ray first meets the robot, or None (simulation thread)."""
    sim = lab.sim
    origin = np.asarray(origin, dtype=float)
    direction = np.asarray(direction, dtype=float)
    if origin.shape != (3,) or direction.shape != (3,) or not np.isfinite(np.r_[origin, direction]).all() \
            or np.linalg.norm(direction) == 0:
        raise ValueError("a click must send a finite ray")
    direction = direction / np.linalg.norm(direction)
    geom = np.array([-1], dtype=np.int32)
    distance = mujoco.mj_ray(sim.model, sim.data, origin, direction, None, 0, -1, geom)
    if geom[0] < 0 or distance < 0:
        return None
    body = int(sim.model.geom_bodyid[geom[0]])
    names = {b: n for n, b in reversed(list(sim.compiled.bodies.items()))}
    while body not in names and body > 0:
        body = int(sim.model.body_parentid[body])
    if body not in names:
        return None
    return names[body], origin + distance * direction


def _fmt(v) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in np.asarray(v).ravel()) + ")"


def link_report(lab: Lab, link: str) -> str:
    """The link as its URDF says and as it is now, in markdown (simulation thread)."""
    sim = lab.sim
    robot = sim.robot
    body = sim.compiled.bodies[link]
    lines = [f"**link** `{link}`"]
    inertial = robot.links[link].inertial
    if inertial is not None and inertial.mass > 0:
        rot = inertial.origin.matrix[:3, :3]
        moments, axes = np.linalg.eigh(rot @ inertial.tensor @ rot.T)
        lines += [f"mass {inertial.mass:.6g} kg (URDF)",
                  f"centre of mass {_fmt(inertial.origin.xyz)} m in the link frame",
                  f"principal moments {_fmt(moments)} kg m², axes (columns) {_fmt(axes.T)}"]
    else:
        lines.append("no mass of its own (URDF)")
    rpy = np.zeros(3)
    quat = sim.data.xquat[body]
    w, x, y, z = quat
    rpy[:] = (math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y)),
              math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x)))),
              math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
    velocity = np.zeros(6)
    mujoco.mj_objectVelocity(sim.model, sim.data, mujoco.mjtObj.mjOBJ_BODY, body, velocity, 0)
    lines += [f"pose: xyz {_fmt(sim.data.xpos[body])} m, rpy {_fmt(rpy)} rad (world)",
              f"velocity: linear {_fmt(velocity[3:])} m/s, angular {_fmt(velocity[:3])} rad/s"]
    touching = set()
    names = {b: n for n, b in sim.compiled.bodies.items()}
    for i in range(sim.data.ncon):
        c = sim.data.contact[i]
        b1, b2 = (int(sim.model.geom_bodyid[g]) for g in (c.geom1, c.geom2))
        if body in (b1, b2):
            other = b2 if b1 == body else b1
            touching.add(names.get(other, sim.model.body(other).name or "ground"))
    lines.append(f"contacts: {', '.join(sorted(touching)) if touching else 'none'}")
    joint = robot.parent_joint.get(link)
    if joint is not None:
        text = f"joint above: `{joint.name}` ({joint.type}, parent `{joint.parent}`)"
        if joint.name in sim.joint_names:
            i = sim.joint_names.index(joint.name)
            text += (f": position {sim.joint_positions()[i]:.4g}, velocity "
                     f"{sim.joint_velocities()[i]:.4g}, effort {sim.joint_efforts()[i]:.4g}")
        if joint.limit is not None:
            text += (f"; limits [{joint.limit.lower:g}, {joint.limit.upper:g}], effort "
                     f"{joint.limit.effort:g}, velocity {joint.limit.velocity:g}")
        lines.append(text)
    return "<br>".join(lines)


class Inspector:
    """The Tools panel: what a click does, the last report, the push settings."""

    def __init__(self, server: viser.ViserServer, lab: Lab, do, number):
        self.server, self.lab, self.do = server, lab, do
        self.impulse, self.duration = 20.0, 0.1
        self.selected: str | None = None
        self.arrow_until = -1.0
        gui = server.gui
        with gui.add_folder("Tools"):
            self.mode = gui.add_dropdown("Click does", CLICK_MODES, initial_value="inspect",
                                         hint="click a link in the 3D view")
            self.direction = gui.add_dropdown("Push direction", PUSH_DIRECTIONS,
                                              initial_value=PUSH_DIRECTIONS[0])
            number("Push impulse (N s)", self.impulse, 0.0, 1000.0,
                   lambda v: setattr(self, "impulse", v))
            number("Push duration (s)", self.duration, 0.001, 5.0,
                   lambda v: setattr(self, "duration", v), hint="force = impulse / duration")
            self.report = gui.add_markdown("*click a link to inspect it*")
        self.arrow = server.scene.add_arrows("/tools/push", np.zeros((1, 2, 3), np.float32),
                                             (230, 30, 200), shaft_radius=0.01, head_radius=0.025,
                                             head_length=0.06, visible=False)
        server.scene.on_click()(lambda e: self.do(
            lambda: self.click(e.ray_origin, e.ray_direction)))

    def click(self, origin, direction) -> str | None:
        """What a click at this ray does (simulation thread); returns the link hit."""
        found = hit(self.lab, origin, direction)
        if found is None:
            return None
        link, point = found
        if self.mode.value == "push":
            d = np.asarray(direction, dtype=float)
            self.push(link, point, _push_direction(self.direction.value, d))
        else:
            self.selected = link
            self.report.content = link_report(self.lab, link)
        return link

    def push(self, link: str, point, direction) -> None:
        """An impulse of `self.impulse` N s along `direction` at `point`, over self.duration."""
        direction = np.asarray(direction, dtype=float)
        direction /= np.linalg.norm(direction)
        sim = self.lab.sim
        sim.apply_wrench(link, direction * self.impulse / self.duration, point=point,
                         duration=self.duration)
        tail = np.asarray(point) - direction * max(self.impulse * ARROW_METRES_PER_NS, 0.05)
        self.arrow.points = np.array([[tail, point]], dtype=np.float32)
        self.arrow.visible = True
        self.arrow_until = sim.time + self.duration
        self.report.content = (f"pushed `{link}` with {self.impulse:g} N s "
                               f"({self.impulse / self.duration:g} N for {self.duration:g} s) "
                               f"along {_fmt(direction)} at {_fmt(point)}")

    def update(self) -> None:
        """Once a frame: the arrow shows while the push acts (sim time); the report refreshes."""
        if self.arrow.visible and not (0 <= self.lab.sim.time < self.arrow_until):
            self.arrow.visible = False
        if self.selected and self.mode.value == "inspect":
            self.report.content = link_report(self.lab, self.selected)


def _push_direction(choice: str, ray: np.ndarray) -> np.ndarray:
    if choice in _AXES:
        return np.array(_AXES[choice], dtype=float)
    flat = np.array([ray[0], ray[1], 0.0])  # away from the camera, level with the ground
    return flat if np.linalg.norm(flat) > 1e-6 else np.array([1.0, 0.0, 0.0])
