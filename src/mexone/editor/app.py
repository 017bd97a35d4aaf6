"""EditorApp: `mexone edit`'s web page (viser), Gazebo 7's Model Editor in a browser.

Every button calls one EditSession method under a lock (viser runs callbacks in a thread pool),
then the page redraws from the session: the scene, the widgets and the live checks always show
what is on disk. The page is not trusted: every value it sends is checked by the session
(names, finite numbers, ranges), uploads arrive as bytes and are stored under names the server
chooses, and saves go into the folder the server was started with, under a base name the page
may only pick from letters, digits and _. The websocket Origin guard and the loopback default
are the GUI's (gui/security.py).

Simulate hands the page to `mexone sim`'s GuiApp for the current model and its controllers
(same server, the editor's panels and scene reset); Back to editing stops it and rebuilds them.

The joint gizmo is magnetic: a drag's end arrives on viser's event loop and is handed to a thread
that runs it as one edit (the lock, the session's checks): near a snap candidate of the joint's
child the frame goes there, else the gizmo stays where it was let go.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import viser

from mexone import signals
from mexone.control.spec import PidGains
from mexone.description.materials import display_rgba
from mexone.description.model import Box, Cylinder, Dynamics, Limit, Pose, Sphere
from mexone.editor.massprops import SHAPES
from mexone.editor.parts import UNITS, Part, read_parts, safe_name
from mexone.editor.save import save_controllers, save_package, save_sdf, save_urdf
from mexone.editor.session import EDIT_TYPES, MAX_SNAP_CHOICES, EditSession, selection_of
from mexone.editor.snapping import SNAP_RADIUS
from mexone.errors import MexoneError
from mexone.gui.scene import _wxyz, trimesh_of
from mexone.gui.security import guard, lab_access, warn_if_exposed
from mexone.ranges import MASS

__all__ = ["EditorApp"]

log = logging.getLogger("mexone.editor")
_SELECTED_RGB = (250, 170, 40)
_COLLISION_RGB = (224, 140, 60)
_MAX_FINDING_BUTTONS = 12
_NONE = "(none)"
GUESS = "guess from size"
# the page's mass input keeps the minimum its browser test ran with (a widget bound is only a
# convenience: a websocket client sends any number, and the session checks it by ranges.MASS)
_MASS_WIDGET_MIN = 1e-6


class EditorApp:
    def __init__(self, session: EditSession, out_dir: Path, host: str = "127.0.0.1", port: int = 8080):
        self.session = session
        self.out_dir = Path(out_dir)
        self.host = host
        self.lock = threading.RLock()
        self.server = viser.ViserServer(host=host, port=port, label="mexone edit", verbose=False)
        self.access = lab_access()  # a secret inside a JupyterHub (gui/security.py)
        guard(self.server, self.access)
        warn_if_exposed(host, self.server.get_port())
        self.pending: list[Part] = []
        self.selected_link: str | None = None
        self.selected_joint: str | None = None
        self.click_sets = "select"
        self.sim_app = None
        self.sim_thread: threading.Thread | None = None
        self.swinging = threading.Event()
        self.stopping = threading.Event()
        self._nodes: dict[str, viser.SceneNodeHandle] = {}
        self._finding_buttons: list = []
        self.messages: list[str] = []
        self._snaps: list = []
        self._build_gui()
        self.server.initial_camera.position = (0.45, -0.55, 0.35)  # a 30 cm part fills the view
        self.server.initial_camera.look_at = (0.1, 0.0, 0.08)
        self.refresh()

    # ----- running ----------------------------------------------------------------------------
    def serve_forever(self) -> None:
        """Animate the swing preview until stopped (the page itself runs in viser's threads)."""
        start = time.perf_counter()
        while not self.stopping.is_set() and not signals.requested():
            if self.swinging.is_set() and self.selected_joint:
                with self.lock:
                    self._swing(time.perf_counter() - start)
            time.sleep(1 / 30)

    def stop(self) -> None:
        self.stopping.set()
        self._stop_sim()
        self.server.stop()

    def act(self, what: str, action, redraw: bool = True) -> bool:
        """Run one edit under the lock; a refused one is said on the page, never raised.
        redraw=False: the action refreshes the page itself if it changed anything."""
        with self.lock:
            try:
                action()
            except MexoneError as exc:
                self.say(f"refused: {exc.one_line()}", error=True)
                return False
            except (ValueError, TypeError) as exc:  # a widget value of the wrong shape
                self.say(f"refused ({what}): {exc}", error=True)
                return False
            if redraw and self.sim_app is None:  # while simulating, the page is the simulator's
                self.refresh()
            return True

    def say(self, text: str, error: bool = False) -> None:
        self.messages = [text, *self.messages][:4]
        self._status_msg.content = "\n\n".join(("**" + m + "**") if i == 0 and error else m
                                               for i, m in enumerate(self.messages))
        if error:
            log.warning(text)

    # ----- widgets ----------------------------------------------------------------------------
    def _button(self, label: str, action, **kwargs):
        """A button whose click runs `action` as one edit (see act)."""
        button = self.server.gui.add_button(label, **kwargs)
        button.on_click(lambda _: self.act(label, action))
        return button

    def _build_gui(self) -> None:
        gui = self.server.gui
        button = self._button
        gui.configure_theme(control_width="large")
        with gui.add_folder("Model"):
            self._status = gui.add_markdown("")
            undo = gui.add_button("Undo", icon=None)
            redo = gui.add_button("Redo")
            undo.on_click(lambda _: self.act("undo", lambda: self.say("undid " + self.session.undo())))
            redo.on_click(lambda _: self.act("redo", lambda: self.say("redid " + self.session.redo())))
            self._name = gui.add_text("Robot name", self.session.model.name)
            gui.add_button("Rename").on_click(lambda _: self.act("rename", lambda: self.session.rename(
                self._name.value)))
            self._click = gui.add_dropdown("Click in 3D sets", ("select", "parent", "child"))
            self._click.on_update(lambda _: setattr(self, "click_sets", self._click.value))
            self._show_collisions = gui.add_checkbox("Show collisions", False)
            self._show_collisions.on_update(lambda _: self.act("view", self._draw))
            self._status_msg = gui.add_markdown("")
        with gui.add_folder("Import"):
            self._upload = gui.add_upload_button("Upload part (STL, OBJ, DAE; .zip of a folder)",
                                                 mime_type="*/*")
            self._upload.on_upload(lambda _: self.act("upload", self._received))
            self._pending = gui.add_markdown("No part waiting.")
            self._unit = gui.add_dropdown("Unit", (GUESS, *UNITS))
            gui.add_button("Accept import").on_click(lambda _: self.act("import", self._accept))
            gui.add_button("Discard").on_click(lambda _: self.act("discard", self._discard))
        with gui.add_folder("Link"):
            self._link = gui.add_dropdown("Link", (_NONE,))
            self._link.on_update(lambda _: self._select_link(self._link.value))
            self._mass = gui.add_number("Mass (kg)", 1.0, min=_MASS_WIDGET_MIN, max=MASS.high, step=0.001)
            gui.add_button("Compute COM + inertia from mesh").on_click(lambda _: self.act(
                "inertia", lambda: self.session.compute_inertia(self._need_link(), self._mass.value)))
            self._com = gui.add_vector3("COM (m)", (0.0, 0.0, 0.0), step=0.0001)
            self._moments = gui.add_vector3("Ixx Iyy Izz", (0.0, 0.0, 0.0), step=1e-6)
            self._products = gui.add_vector3("Ixy Ixz Iyz", (0.0, 0.0, 0.0), step=1e-6)
            button("Apply typed inertial", self._typed_inertial)
            self._principal = gui.add_markdown("")
            self._shape = gui.add_dropdown("Collision", SHAPES, initial_value="cylinder")
            gui.add_button("Fit collision").on_click(lambda _: self.act(
                "collision", lambda: self.session.fit_collision(self._need_link(), self._shape.value)))
            self._col_size = gui.add_vector3("Collision size", (0.0, 0.0, 0.0), step=0.001,
                                             hint="box: x y z; cylinder: radius length; sphere: radius")
            self._col_xyz = gui.add_vector3("Collision xyz", (0.0, 0.0, 0.0), step=0.001)
            button("Apply collision size", self._edit_collision)
            self._mu = gui.add_vector3("mu1 mu2 kp", (1.0, 1.0, 1e6), step=0.01)
            self._kd = gui.add_number("kd", 1.0, min=0.0, step=0.1)
            button("Apply surface", lambda: self.session.set_surface(self._need_link(), *self._mu.value,
                                                                     self._kd.value))
            self._rgb = gui.add_rgb("Colour", (180, 180, 190))
            button("Apply colour", lambda: self.session.set_color(
                self._need_link(), (*(c / 255 for c in self._rgb.value), 1.0)))
            gui.add_button("Fix to world / free").on_click(lambda _: self.act("fix", self._toggle_world))
            gui.add_button("Remove link").on_click(lambda _: self.act(
                "remove", lambda: self.session.remove_link(self._need_link())))
        with gui.add_folder("Joints"):
            self._parent = gui.add_dropdown("Parent", (_NONE,))
            self._child = gui.add_dropdown("Child", (_NONE,))
            self._child.on_update(lambda _: self._update_snaps())
            self._jtype = gui.add_dropdown("Type", EDIT_TYPES)
            self._jname = gui.add_text("New joint name", "joint_1")
            self._snap = gui.add_dropdown("Snap on child", (_NONE,))
            gui.add_button("Add joint").on_click(lambda _: self.act("joint", self._add_joint))
            self._joint = gui.add_dropdown("Joint", (_NONE,))
            self._joint.on_update(lambda _: self._select_joint(self._joint.value))
            self._axis = gui.add_vector3("Axis", (0.0, 0.0, 1.0), step=0.01)
            self._limits = gui.add_vector3("lower upper effort", (-1.57, 1.57, 10.0), step=0.01)
            self._dyn = gui.add_vector3("velocity damping friction", (3.0, 0.0, 0.0), step=0.01)
            gui.add_button("Apply joint").on_click(lambda _: self.act("joint", self._apply_joint))
            self._origin = gui.add_vector3("Frame xyz (parent)", (0.0, 0.0, 0.0), step=0.001)
            self._origin_rpy = gui.add_vector3("Frame rpy", (0.0, 0.0, 0.0), step=0.01)
            button("Place frame (typed)", self._typed_frame)
            button("Place frame at gizmo", self._gizmo_frame,
                   hint=f"let go within {SNAP_RADIUS * 1000:g} mm of a snap of the child and the frame "
                        "snaps there by itself; dropped elsewhere, this puts the frame at the gizmo")
            button("Snap frame to selected snap", self._snap_frame)
            self._swing_box = gui.add_checkbox("Swing preview", False)
            self._swing_box.on_update(lambda _: self._set_swing(self._swing_box.value))
            gui.add_button("Remove joint").on_click(lambda _: self.act(
                "remove", lambda: self.session.remove_joint(self._need_joint())))
        with gui.add_folder("Motors"):
            self._motor = gui.add_checkbox("Motor on selected joint", False)
            self._pid = gui.add_vector3("p i d", (0.0, 0.0, 0.0), step=0.001)
            gui.add_button("Apply motor").on_click(lambda _: self.act("motor", self._apply_motor))
            gui.add_button("Auto gains").on_click(lambda _: self.act("motor", lambda: self.session.set_motor(
                self._need_joint(), True)))
        with gui.add_folder("Checks"):
            self._checks = gui.add_markdown("")
            self._checks_folder = gui.add_folder("Findings (click to select)")
        with gui.add_folder("Save"):
            self._base = gui.add_text("Base name", self.session.model.name)
            self._overwrite = gui.add_checkbox("Overwrite existing files", False)
            for label, kind in (("Save URDF", "urdf"), ("Save SDF", "sdf"),
                                ("Save controllers YAML", "yaml"), ("Save ROS package", "package")):
                gui.add_button(label).on_click(lambda _, kind=kind: self.act("save", lambda: self.save(kind)))
            gui.add_markdown(f"Files go to `{self.out_dir}` (chosen when the editor started).")
        with gui.add_folder("Simulate"):
            button("Simulate", self.simulate, hint="play, pause, push and plot the robot in this "
                                                    "page; Back to editing returns")
        self._gizmo = self.server.scene.add_transform_controls("/gizmo", scale=0.12, visible=False)
        self._gizmo.on_update(self._gizmo_moved)

    # ----- refreshing -------------------------------------------------------------------------
    def refresh(self) -> None:
        model = self.session.model
        links = [n for n in model.links if n != "world"]
        joints = list(model.joints)
        if self.selected_link not in model.links:
            self.selected_link = links[0] if links else None
        if self.selected_joint not in model.joints:
            self.selected_joint = joints[-1] if joints else None
        selected = self.selected_link, self.selected_joint
        self._link.options = links or [_NONE]  # (new options may select their first: undo that)
        self._parent.options = [*model.links] or [_NONE]
        self._child.options = [n for n in model.roots if n != "world"] or [_NONE]
        self._joint.options = joints or [_NONE]
        self.selected_link, self.selected_joint = selected
        self._link.value = self.selected_link or _NONE
        self._joint.value = self.selected_joint or _NONE
        step = self.session.index
        self._status.content = (f"**{model.name}**: {len(links)} links, {len(joints)} joints, "
                                f"{len(model.actuated_joints)} motors, {model.mass:.3f} kg  \n"
                                f"history step {step}" + (f" (undo: {self.session.extras.label})"
                                                          if self.session.can_undo else ""))
        self._fill_link()
        self._fill_joint()
        self._update_snaps()
        self._fill_checks()
        self._draw()

    def _fill_link(self) -> None:
        link = self.session.model.links.get(self.selected_link or "")
        if link is not None and link.collisions:
            col = link.collisions[0]
            self._col_xyz.value = col.origin.xyz
            match col.geometry:
                case Box(size):
                    self._col_size.value = size
                case Cylinder(radius, length):
                    self._col_size.value = (radius, length, 0.0)
                case Sphere(radius):
                    self._col_size.value = (radius, 0.0, 0.0)
        if link is None or link.inertial is None:
            self._principal.content = ""
            return
        inertial = link.inertial
        ixx, ixy, ixz, iyy, iyz, izz = inertial.inertia
        self._mass.value = inertial.mass
        self._com.value = inertial.origin.xyz
        self._moments.value = (ixx, iyy, izz)
        self._products.value = (ixy, ixz, iyz)
        moments, axes = np.linalg.eigh(inertial.tensor)
        rot = inertial.origin.matrix[:3, :3] @ axes
        self._principal.content = "Principal moments (kg m²) and axes (link frame):  \n" + "  \n".join(
            f"{m:.3g}: ({a[0]:.2f}, {a[1]:.2f}, {a[2]:.2f})" for m, a in zip(moments, rot.T, strict=True))

    def _fill_joint(self) -> None:
        joint = self.session.model.joints.get(self.selected_joint or "")
        if joint is None:
            self._gizmo.visible = False
            return
        self._axis.value = joint.axis
        limit = joint.limit or Limit()
        dyn = joint.dynamics
        self._limits.value = (limit.lower, limit.upper, limit.effort)
        self._dyn.value = (limit.velocity, dyn.damping, dyn.friction)
        self._origin.value = joint.origin.xyz
        self._origin_rpy.value = joint.origin.rpy
        gains = self.session.extras.motors.get(joint.name)
        self._motor.value = gains is not None
        if gains is not None:
            self._pid.value = (gains.p, gains.i, gains.d)
        frame = self.session.world_frames()[joint.child]
        self._gizmo.position = frame[:3, 3]
        self._gizmo.wxyz = _wxyz(frame[:3, :3])
        self._gizmo.visible = True

    def _update_snaps(self) -> None:
        child = self._child.value
        if child not in self.session.model.links:
            self._snaps = []
            self._snap.options = [_NONE]
            return
        self._snaps = self.session.snaps(child)[:MAX_SNAP_CHOICES]
        self._snap.options = self.session.snap_choices(child) or [_NONE]

    def _fill_checks(self) -> None:
        findings = self.session.findings()
        counts = {s: sum(f.severity == s for f in findings) for s in ("error", "warning", "info")}
        self._checks.content = (f"{counts['error']} error(s), {counts['warning']} warning(s), "
                                f"{counts['info']} note(s)" if findings else "no problems found")
        for button in self._finding_buttons:
            button.remove()
        self._finding_buttons = []
        with self._checks_folder:
            for finding in findings[:_MAX_FINDING_BUTTONS]:
                target = selection_of(finding)
                button = self.server.gui.add_button(
                    f"{finding.severity}: {finding.element}: {finding.code}",
                    color="red" if finding.severity == "error" else "yellow" if finding.severity == "warning"
                    else "gray", hint=finding.message)
                button.on_click(lambda _, t=target: self._goto(t))
                self._finding_buttons.append(button)

    def _goto(self, target) -> None:
        if target is None:
            return
        kind, name = target
        with self.lock:
            if kind == "link":
                self._select_link(name)
            else:
                self._select_joint(name)

    # ----- the scene --------------------------------------------------------------------------
    def _draw(self) -> None:
        scene = self.server.scene
        for node in self._nodes.values():
            node.remove()
        self._nodes = {}
        model = self.session.model
        frames = self.session.world_frames()
        show_collisions = self._show_collisions.value
        for name, link in model.links.items():
            if name == "world" or name not in frames:
                continue
            frame = frames[name]
            node = scene.add_frame(f"/model/{name}", show_axes=False, position=frame[:3, 3],
                                   wxyz=_wxyz(frame[:3, :3]))
            self._nodes[name] = node
            selected = name == self.selected_link
            for i, vis in enumerate(link.visuals):
                try:
                    mesh = trimesh_of(vis.geometry, model)
                except MexoneError:
                    continue  # the checks panel says the mesh is missing
                rgba = display_rgba(model, name, vis)
                color = _SELECTED_RGB if selected else tuple(int(255 * c) for c in rgba[:3])
                handle = scene.add_mesh_simple(f"/model/{name}/visual_{i}", mesh.vertices, mesh.faces,
                                               color=color, position=vis.origin.xyz,
                                               wxyz=_wxyz(vis.origin.matrix[:3, :3]))
                handle.on_click(lambda _, n=name: self._clicked(n))
            if show_collisions:
                for i, col in enumerate(link.collisions):
                    try:
                        mesh = trimesh_of(col.geometry, model)
                    except MexoneError:
                        continue
                    scene.add_mesh_simple(f"/model/{name}/collision_{i}", mesh.vertices, mesh.faces,
                                          color=_COLLISION_RGB, opacity=0.45, position=col.origin.xyz,
                                          wxyz=_wxyz(col.origin.matrix[:3, :3]))
        for joint in model.joints.values():
            if joint.child in frames and joint.type != "fixed":
                frame = frames[joint.child]
                axis = frame[:3, :3] @ np.asarray(joint.axis)
                points = np.array([[frame[:3, 3] - 0.06 * axis, frame[:3, 3] + 0.06 * axis]])
                self._nodes[f"axis_{joint.name}"] = scene.add_line_segments(
                    f"/axes/{joint.name}", points, (250, 220, 0), thickness=0.004)

    def _clicked(self, link: str) -> None:
        with self.lock:
            if self.click_sets == "parent":
                self._parent.value = link
            elif self.click_sets == "child" and link in self.session.model.roots:
                self._child.value = link
                self._update_snaps()
            self._select_link(link)

    # A selection fills the widgets under the edit lock: an edit clicked meanwhile (Place frame
    # (typed)) waits for it and reads what the page shows.
    def _select_link(self, name: str) -> None:
        with self.lock:
            if name in self.session.model.links and name != self.selected_link:
                self.selected_link = name
                self._link.value = name
                self._fill_link()
                self._draw()

    def _select_joint(self, name: str) -> None:
        with self.lock:
            if name in self.session.model.joints:
                self.selected_joint = name
                self._joint.value = name
                self._fill_joint()

    def _set_swing(self, on: bool) -> None:
        if on:
            self.swinging.set()
        else:
            self.swinging.clear()
            with self.lock:
                self._draw()

    def _swing(self, t: float) -> None:
        """Move the drawn parts (not the model) through the joint's range, 2 s per swing."""
        joint = self.session.model.joints.get(self.selected_joint or "")
        if joint is None or not joint.moving:
            return
        lo, hi = (joint.limit.lower, joint.limit.upper) if joint.limit and joint.type != "continuous" \
            else (-math.pi, math.pi)
        q = lo + (hi - lo) * (0.5 + 0.5 * math.sin(math.pi * t))
        frames = self.session.world_frames({joint.name: q})
        for name in self.session.model.walk(joint.child):
            if name in self._nodes and name in frames:
                self._nodes[name].position = frames[name][:3, 3]
                self._nodes[name].wxyz = _wxyz(frames[name][:3, :3])

    # ----- actions ----------------------------------------------------------------------------
    def _need_link(self) -> str:
        if self.selected_link is None:
            raise MexoneError("select a link first")
        return self.selected_link

    def _need_joint(self) -> str:
        if self.selected_joint is None:
            raise MexoneError("select a joint first")
        return self.selected_joint

    def _received(self) -> None:
        upload = self._upload.value
        taken = set(self.session.model.links) | {p.name for p in self.pending}
        parts = read_parts(upload.name, upload.content, taken)
        self.pending += parts
        self._unit.value = self.pending[0].guess
        self._show_pending()

    def _show_pending(self) -> None:
        if not self.pending:
            self._pending.content = "No part waiting."
            return
        part = self.pending[0]
        size = " x ".join(f"{v:.4g}" for v in part.mesh.extents)
        scaled = part.extent * UNITS[part.guess]
        self._pending.content = (f"**{part.name}**: {len(part.mesh.faces)} triangles, {size} "
                                 f"(file units). Guess: **{part.guess}** (largest side "
                                 f"{scaled:.3g} m)" + (f"; {len(self.pending) - 1} more waiting"
                                                       if len(self.pending) > 1 else ""))

    def _accept(self) -> None:
        if not self.pending:
            raise MexoneError("no part waiting: upload one first")
        part = self.pending[0]
        unit = None if self._unit.value == GUESS else self._unit.value
        import io

        buffer = io.BytesIO()
        part.mesh.export(buffer, file_type="stl")
        name = self.session.import_part(f"{part.name}.stl", buffer.getvalue(), unit or part.guess)
        self.pending.pop(0)
        self.selected_link = name
        if self.pending:
            self._unit.value = self.pending[0].guess
        self._show_pending()
        self.say(f"imported {name} in {unit or part.guess}")

    def _discard(self) -> None:
        if self.pending:
            self.pending.pop(0)
        if self.pending:
            self._unit.value = self.pending[0].guess
        self._show_pending()

    def _typed_inertial(self) -> None:
        ixx, iyy, izz = self._moments.value
        ixy, ixz, iyz = self._products.value
        self.session.set_inertial(self._need_link(), self._mass.value, self._com.value,
                                  (ixx, ixy, ixz, iyy, iyz, izz))

    def _edit_collision(self) -> None:
        """The first collision shape's size and place, typed (a fitted shape, adjusted)."""
        link = self._need_link()
        cols = self.session.link(link).collisions
        if not cols:
            raise MexoneError(f"link '{link}' has no collision shape: fit one first")
        a, b, c = self._col_size.value
        match cols[0].geometry:
            case Box():
                geometry = Box((a, b, c))
            case Cylinder():
                geometry = Cylinder(a, b)
            case Sphere():
                geometry = Sphere(a)
            case _:
                raise MexoneError("a mesh collision has no size to type: fit a shape first")
        self.session.set_collision(link, 0, geometry, replace(cols[0].origin, xyz=tuple(self._col_xyz.value)))

    def _toggle_world(self) -> None:
        link = self._need_link()
        self.session.fix_to_world(link, not self.session.model.fixed_to_world)

    def _add_joint(self) -> None:
        parent, child = self._parent.value, self._child.value
        if not self._snaps or self._snap.value == _NONE:
            raise MexoneError("pick a child with a mesh and a snap point")
        index = self.session.snap_of(child, self._snap.value)
        _snap, point, axis = self.session.snaps(child)[index]
        name = self._jname.value
        self.session.add_joint(name, parent, child, self._jtype.value, point, axis)
        self.selected_joint = name
        self._jname.value = safe_name(f"joint_{len(self.session.model.joints) + 1}",
                                      set(self.session.model.joints))

    def _apply_joint(self) -> None:
        lower, upper, effort = self._limits.value
        velocity, damping, friction = self._dyn.value
        self.session.set_joint(self._need_joint(), axis=self._axis.value,
                               limit=Limit(lower, upper, effort, velocity),
                               dynamics=Dynamics(damping, friction))

    def _typed_frame(self) -> None:
        self.session.move_joint_frame(self._need_joint(), Pose(tuple(self._origin.value),
                                                               tuple(self._origin_rpy.value)))

    def _gizmo_frame(self) -> None:
        joint = self.session.joint(self._need_joint())
        import mujoco

        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, np.asarray(self._gizmo.wxyz, dtype=float))
        world = np.eye(4)
        world[:3, :3] = rot.reshape(3, 3)
        world[:3, 3] = self._gizmo.position
        parent = self.session.world_frames()[joint.parent]
        self.session.move_joint_frame(joint.name, Pose.from_matrix(np.linalg.inv(parent) @ world))

    async def _gizmo_moved(self, event) -> None:
        """A drag's end (async: viser keeps a drag's phases in order only for async callbacks):
        the pose it was let go at goes to a thread of its own, as every edit does, so the page's
        messages keep flowing while the session writes its step."""
        if event.phase != "end" or event.client is None:
            return
        at = np.array(event.target.position, dtype=float)
        threading.Thread(target=self.act, args=("gizmo", lambda: self._dropped(at), False),
                         daemon=True, name="editor-gizmo").start()

    def _dropped(self, at: np.ndarray) -> None:
        """The magnet: let go within SNAP_RADIUS of a snap candidate of the selected joint's
        child, the joint's frame goes there at once (one undoable step; the gizmo follows);
        further away the gizmo stays where it was dropped for "Place frame at gizmo"."""
        if self.sim_app is not None or self.selected_joint is None:
            return
        joint = self.selected_joint
        snap = self.session.snap_joint_near(joint, at)
        x, y, z = (1000 * v for v in at)
        if snap is None:
            self.say(f"gizmo at ({x:.1f}, {y:.1f}, {z:.1f}) mm: no snap within "
                     f"{SNAP_RADIUS * 1000:g} mm; Place frame at gizmo puts {joint}'s frame there")
            return
        self.refresh()
        off = np.linalg.norm(self.session.world_frames()[self.session.joint(joint).child][:3, 3] - at)
        self.say(f"{joint} snapped to {snap.label} (let go {off * 1000:.1f} mm from it)")

    def _snap_frame(self) -> None:
        joint = self.session.joint(self._need_joint())
        if self._snap.value == _NONE:
            raise MexoneError("pick a snap point")
        if self._child.value != joint.child:  # the list shows the Child dropdown's candidates
            self._child.options = [*self._child.options, joint.child]
            self._child.value = joint.child
            self._update_snaps()
            raise MexoneError(f"the snap list now shows '{joint.child}': pick a point and snap again")
        snap = self.session.snap_joint(joint.name, self.session.snap_of(joint.child, self._snap.value))
        self.say(f"{joint.name} snapped to {snap.label}")

    def _apply_motor(self) -> None:
        joint = self._need_joint()
        p, i, d = self._pid.value
        if self._motor.value:
            clamp = 1.0 if i else 0.0  # an I term needs a clamp to act at all (ROS's rule)
            self.session.set_motor(joint, True, PidGains(p, i, d, -clamp, clamp))
        else:
            self.session.set_motor(joint, False)

    def save(self, kind: str) -> Path:
        base = self._base.value
        if safe_name(base) != base:
            raise MexoneError(f"base name {repr(base)[:80]} must be lower-case letters, digits and _")
        force = self._overwrite.value
        target = {"urdf": f"{base}.urdf", "sdf": f"{base}.sdf", "yaml": f"{base}_controllers.yaml",
                  "package": base}[kind]
        path = self.out_dir / target
        writer = {"urdf": save_urdf, "sdf": save_sdf, "yaml": save_controllers, "package": save_package}[kind]
        writer(self.session, path, force)
        self._overwrite.value = False  # one confirmation, one overwrite
        self.say(f"saved {path}")
        return path

    def simulate(self) -> None:
        """`mexone sim`'s page for the current model and its controllers, in this page: the
        editor's panels and scene give way to the simulator's until Back to editing."""
        from mexone.gui.app import GuiApp
        from mexone.lab import Lab
        from mexone.physics.compile import CompileOptions

        self._stop_sim()
        self.swinging.clear()
        folder = self.session.folder / "simulate"
        folder.mkdir(exist_ok=True)
        urdf = save_urdf(self.session, folder / "model.urdf", force=True)
        controllers = self.session.control_config() if self.session.extras.motors else False
        lab = Lab.create(urdf, controllers)  # before the page changes: a model sim refuses stays here
        self.server.gui.reset()
        self.server.scene.reset()
        self._nodes, self._finding_buttons = {}, []
        back = self.server.gui.add_button("Back to editing", color="green", order=-1.0)
        back.on_click(lambda _: self.act("back", self._stop_sim))
        self.sim_app = GuiApp(lambda _options: lab, CompileOptions(), server=self.server)
        self.sim_thread = threading.Thread(target=self.sim_app.serve_forever, daemon=True,
                                           name="editor-sim")
        self.sim_thread.start()

    def _stop_sim(self) -> None:
        """Back to editing: the simulator stops and the editor's page returns as it was."""
        if self.sim_app is None:
            return
        self.sim_app.stop()
        if self.sim_thread is not None:
            self.sim_thread.join(timeout=5)
        self.sim_app = self.sim_thread = None
        if not self.stopping.is_set():
            self.server.gui.reset()
            self.server.scene.reset()
            self._nodes, self._finding_buttons = {}, []
            self._build_gui()
            self.say("back to editing")
