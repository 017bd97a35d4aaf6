"""Click a link: Gazebo's property panel (inspect) or its force tool (push).

A click on the page sends a ray; the simulation thread casts it into MuJoCo (`mj_ray`, the
robot's geoms only), so the link and the point hit are the physics' own. Inspecting shows the
link as its URDF declares it (mass, centre of mass, principal inertia) and as it is now (pose,
velocity, contacts, the joint above it). While View > Joints shows the axis arrows, a ray that
passes within JOINT_PICK of an arrow inspects that joint instead (the arrows sit inside the
links, so they win over the link around them). Pushing applies an impulse at that point for a
short time in sim time (`Simulation.apply_wrench`), drawn as an arrow while it acts.

Direction by dragging: with "drag the handle" a click only aims. A gizmo appears at the tail
of a preview arrow whose head is the clicked point; dragging the gizmo sets the direction (tail
to head) and, with "magnitude from length", the impulse (ARROW_METRES_PER_NS); *Push* fires it.
viser's transform gizmo is the one drag widget a page offers that yields a 3D vector.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import viser

from mexone.gui.move import MoveTool
from mexone.gui.panels import Panel, register_panel
from mexone.lab import Lab
from mexone.ranges import IMPULSE, PUSH_DURATION

__all__ = ["Inspector", "CLICK_MODES", "PUSH_DIRECTIONS", "DRAG", "hit", "joint_hit",
           "link_report", "joint_report"]

CLICK_MODES = ("inspect", "push")
DRAG = "drag the handle"
PUSH_DIRECTIONS = ("away from the camera", DRAG, "+x", "-x", "+y", "-y", "+z", "-z")
ARROW_METRES_PER_NS = 0.02  # a 40 N s push draws 0.8 m
MAX_IMPULSE = IMPULSE.high  # N s: a push drawn longer is capped here
JOINT_ARROW = 0.12  # m: the length View > Joints draws an axis (scene.py)
JOINT_PICK = 0.02  # m: a click this close to an axis arrow picks the joint
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


def joint_hit(lab: Lab, origin, direction, pick: float = JOINT_PICK) -> str | None:
    """The moving joint whose axis arrow (as View > Joints draws it) the ray passes nearest,
    within `pick` metres, or None (simulation thread)."""
    sim = lab.sim
    origin = np.asarray(origin, dtype=float)
    d = np.asarray(direction, dtype=float)
    d = d / np.linalg.norm(d)
    best, best_gap = None, pick
    for joint in sim.robot.joints.values():
        if not joint.moving or joint.child not in sim.compiled.bodies:
            continue
        body = sim.compiled.bodies[joint.child]
        axis = np.asarray(joint.axis, dtype=float)
        start = sim.data.xpos[body]
        end = start + sim.data.xmat[body].reshape(3, 3) @ (JOINT_ARROW * axis / np.linalg.norm(axis))
        gap = _ray_segment_gap(origin, d, start, end)
        if gap < best_gap:
            best, best_gap = joint.name, gap
    return best


def _ray_segment_gap(o: np.ndarray, d: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Shortest distance between the ray o + t d (t >= 0, |d| = 1) and the segment a-b."""
    u = b - a
    samples = np.linspace(0.0, 1.0, 25)[:, None] * u + a  # the arrow is short: sample it
    t = np.maximum((samples - o) @ d, 0.0)
    return float(np.min(np.linalg.norm(o + t[:, None] * d - samples, axis=1)))


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
        lines.append(f"joint above: `{joint.name}` ({joint.type}, parent `{joint.parent}`)"
                     + _joint_state(lab, joint.name))
    return "<br>".join(lines)


def _joint_state(lab: Lab, name: str) -> str:
    sim, joint = lab.sim, lab.sim.robot.joints[name]
    text = ""
    if name in sim.joint_names:
        i = sim.joint_names.index(name)
        text += (f": position {sim.joint_positions()[i]:.4g}, velocity "
                 f"{sim.joint_velocities()[i]:.4g}, effort {sim.joint_efforts()[i]:.4g}")
    if joint.limit is not None:
        text += (f"; limits [{joint.limit.lower:g}, {joint.limit.upper:g}], effort "
                 f"{joint.limit.effort:g}, velocity {joint.limit.velocity:g}")
    return text


def joint_report(lab: Lab, name: str) -> str:
    """A joint as its URDF says and as it is now, in markdown (simulation thread)."""
    sim = lab.sim
    joint = sim.robot.joints[name]
    body = sim.compiled.bodies[joint.child]
    axis = np.asarray(joint.axis, dtype=float)
    world = sim.data.xmat[body].reshape(3, 3) @ (axis / np.linalg.norm(axis))
    unit = "m" if joint.type == "prismatic" else "rad"
    lines = [f"**joint** `{name}` ({joint.type}, {unit})",
             f"parent `{joint.parent}` → child `{joint.child}`",
             f"axis {_fmt(axis)} in the child frame, {_fmt(world)} in the world, at "
             f"{_fmt(sim.data.xpos[body])} m",
             "now" + (_joint_state(lab, name) or ": not simulated (fixed or mimic)")]
    if joint.limit is None:
        lines.append("no limits (continuous)")
    if joint.dynamics.damping or joint.dynamics.friction:
        lines.append(f"damping {joint.dynamics.damping:g}, friction {joint.dynamics.friction:g}")
    return "<br>".join(lines)


@register_panel
class Inspector(Panel):
    """The Tools panel: what a click does, the last report, the push settings, and the Move
    tool (gui/move.py). A click on the 3D view reaches whichever robot is loaded now."""

    name = "tools"
    order = 6
    period = 1

    def __init__(self, host):
        super().__init__(host)
        self._on_click = self.server.scene.on_click()(lambda e: self.do(
            lambda: self.click(e.ray_origin, e.ray_direction)))

    def joints_shown(self) -> bool:
        """View > Joints shows the axis arrows: they can be clicked."""
        return "Joints" in self.host.scene.showing

    def build(self) -> None:
        server, fields = self.server, self.host.fields
        self.fields = fields
        self.impulse, self.duration = 20.0, 0.1
        self.selected: tuple[str, str] | None = None  # ("link" | "joint", name)
        self.arrow_until = -1.0
        self.aim: tuple[str, np.ndarray, np.ndarray] | None = None  # link, local point, head
        self.dragged: np.ndarray | None = None  # the gizmo's position, tail of the push
        gui = server.gui
        with gui.add_folder("Tools") as self.folder:
            self.mode = gui.add_dropdown("Click does", CLICK_MODES, initial_value="inspect",
                                         hint="click a link (or, with View > Joints, a joint's "
                                              "axis arrow) in the 3D view")
            self.direction = gui.add_dropdown("Push direction", PUSH_DIRECTIONS,
                                              initial_value=PUSH_DIRECTIONS[0],
                                              hint=f"{DRAG}: a click aims, the gizmo sets the "
                                                   "direction, Push fires")
            self.impulse_field = fields.add("Push impulse (N s)", self.impulse, IMPULSE,
                                            lambda v: setattr(self, "impulse", v))
            fields.add("Push duration (s)", self.duration, PUSH_DURATION,
                       lambda v: setattr(self, "duration", v), hint="force = impulse / duration")
            self.from_length = gui.add_checkbox("Magnitude from length", False,
                                                hint=f"{DRAG}: the arrow's length sets the "
                                                     f"impulse ({ARROW_METRES_PER_NS * 100:g} cm "
                                                     "per N s)")
            self.fire = gui.add_button("Push", icon=viser.Icon.ARROW_BIG_RIGHT, disabled=True,
                                       hint=f"fire the aimed push ({DRAG})")
            self.fire.on_click(lambda _: self.do(self.push_aimed))
            self.report = gui.add_markdown("*click a link to inspect it*")
            self.move = MoveTool(server, self.lab, self.do)
        self.arrow = server.scene.add_arrows("/tools/push", np.zeros((1, 2, 3), np.float32),
                                             (230, 30, 200), shaft_radius=0.01, head_radius=0.025,
                                             head_length=0.06, visible=False)
        self.preview = server.scene.add_arrows("/tools/aim", np.zeros((1, 2, 3), np.float32),
                                               (250, 150, 30), shaft_radius=0.006,
                                               head_radius=0.018, head_length=0.05, visible=False)
        self.handle = server.scene.add_transform_controls("/tools/aim_handle", scale=0.25,
                                                          disable_rotations=True, depth_test=False,
                                                          visible=False)
        self.handle.on_update(self._dragging)

    def stop(self) -> None:
        self.server.scene.remove_click_callback(self._on_click)

    def click(self, origin, direction) -> str | None:
        """What a click at this ray does (simulation thread); returns the link (or joint) hit."""
        if self.mode.value == "inspect" and self.joints_shown():
            joint = joint_hit(self.lab, origin, direction)
            if joint is not None:
                self.selected = ("joint", joint)
                self.report.content = joint_report(self.lab, joint)
                return joint
        found = hit(self.lab, origin, direction)
        if found is None:
            return None
        link, point = found
        if self.mode.value == "push" and self.direction.value == DRAG:
            self.aim_at(link, point, np.asarray(direction, dtype=float))
        elif self.mode.value == "push":
            d = np.asarray(direction, dtype=float)
            self.push(link, point, _push_direction(self.direction.value, d))
        else:
            self.selected = ("link", link)
            self.report.content = link_report(self.lab, link)
        return link

    # ----- push by dragging ---------------------------------------------------------------------
    def aim_at(self, link: str, point, ray) -> None:
        """A click with "drag the handle": the gizmo at the tail of a preview arrow (simulation
        thread); it starts away from the camera, as long as the typed impulse says."""
        sim = self.lab.sim
        body = sim.compiled.bodies[link]
        point = np.asarray(point, dtype=float)
        rot = sim.data.xmat[body].reshape(3, 3)
        local = rot.T @ (point - sim.data.xpos[body])
        self.aim = (link, local, point)
        tail = point - _push_direction("away", np.asarray(ray)) * self._length()
        self.handle.position = tuple(tail)
        self.handle.visible = True
        self._aimed(tail)

    def _length(self) -> float:
        return max(self.impulse * ARROW_METRES_PER_NS, 0.05)

    async def _dragging(self, event) -> None:
        """async: drag updates stay in order (see move.py); it only queues."""
        if event.client is None:
            return
        position = np.asarray(event.target.position, dtype=float)
        self.do(lambda: self._aimed(position))

    def _aimed(self, tail) -> None:
        """The gizmo moved (simulation thread): redraw the preview, maybe take its length."""
        if self.aim is None:
            return
        tail = np.asarray(tail, dtype=float)
        if tail.shape != (3,) or not np.isfinite(tail).all():
            raise ValueError("Push: the handle's position must be three finite numbers")
        head = self.aim[2]
        length = float(np.linalg.norm(head - tail))
        if length < 1e-3:
            raise ValueError("Push: drag the handle away from the point to give a direction")
        self.dragged = tail
        if self.from_length.value:
            impulse = min(length / ARROW_METRES_PER_NS, MAX_IMPULSE)
            self.impulse = round(impulse, 2)
            self.fields.set_held(self.impulse_field, [self.impulse])
        self.preview.points = np.array([[tail, head]], dtype=np.float32)
        self.preview.visible = True
        self.fire.disabled = False
        self.report.content = (f"aiming at `{self.aim[0]}`: {self.impulse:g} N s along "
                               f"{_fmt((head - tail) / length)}; press *Push*")

    def push_aimed(self) -> None:
        """Fire the aimed push at the aimed point where the link is now (simulation thread)."""
        if self.aim is None or self.dragged is None:
            raise ValueError(f"Push: nothing aimed (Push direction '{DRAG}', then click a link)")
        link, local, head = self.aim
        sim = self.lab.sim
        body = sim.compiled.bodies[link]
        point = sim.data.xpos[body] + sim.data.xmat[body].reshape(3, 3) @ local
        self.push(link, point, head - self.dragged)
        self.clear_aim()

    def clear_aim(self) -> None:
        self.aim, self.dragged = None, None
        self.preview.visible = self.handle.visible = False
        self.fire.disabled = True

    def push(self, link: str, point, direction) -> None:
        """An impulse of `self.impulse` N s along `direction` at `point`, over self.duration."""
        direction = np.asarray(direction, dtype=float)
        direction /= np.linalg.norm(direction)
        sim = self.lab.sim
        sim.apply_wrench(link, direction * self.impulse / self.duration, point=point,
                         duration=self.duration)
        tail = np.asarray(point) - direction * self._length()
        self.arrow.points = np.array([[tail, point]], dtype=np.float32)
        self.arrow.visible = True
        self.arrow_until = sim.time + self.duration
        self.report.content = (f"pushed `{link}` with {self.impulse:g} N s "
                               f"({self.impulse / self.duration:g} N for {self.duration:g} s) "
                               f"along {_fmt(direction)} at {_fmt(point)}")

    def update(self) -> None:
        """Once a frame: the arrow shows while the push acts (sim time); the report refreshes;
        the Move tool holds or follows the robot."""
        if self.arrow.visible and not (0 <= self.lab.sim.time < self.arrow_until):
            self.arrow.visible = False
        if self.selected and self.mode.value == "inspect":
            kind, name = self.selected
            self.report.content = (link_report if kind == "link" else joint_report)(self.lab, name)
        self.move.update()


def _push_direction(choice: str, ray: np.ndarray) -> np.ndarray:
    if choice in _AXES:
        return np.array(_AXES[choice], dtype=float)
    flat = np.array([ray[0], ray[1], 0.0])  # away from the camera, level with the ground
    return flat if np.linalg.norm(flat) > 1e-6 else np.array([1.0, 0.0, 0.0])
