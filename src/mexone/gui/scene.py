"""RobotScene: the robot in viser's 3D scene, plus the seed's View-menu overlays.

Every link is a scene node ``/robot/<link>`` posed in the world each frame; its visual meshes,
collision shapes, centre-of-mass marker, inertia box and joint axis hang below it, so toggling
an overlay is one ``visible`` flag and a frame update is one pose per link.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np
import viser

from mexone.description.materials import display_rgba
from mexone.description.meshes import load_mesh, resolve_mesh
from mexone.description.model import Box, Cylinder, Geometry, Mesh, RobotModel, Sphere
from mexone.gui.display import display_budgets, display_mesh
from mexone.physics.simulation import Simulation

__all__ = ["RobotScene", "OVERLAYS", "inertia_box", "trimesh_of"]

OVERLAYS = ("Center of Mass", "Inertia", "Joints", "Collisions", "Contacts")
_COLLISION_RGB = (224, 140, 60)
_COM_RGB = (40, 40, 230)
_INERTIA_RGB = (150, 60, 200)
_JOINT_RGB = (250, 220, 0)
_CONTACT_RGB = (230, 30, 30)
_MAX_CONTACTS = 64
ENVIRONMENT_LIGHT, AMBIENT_LIGHT = 0.35, 0.35  # (viser's default environment is 1.0)
# a link is sent to the page when its position (m) or a quaternion component moved more than this
# since it was last sent: 20 um, 0.002 degree -- far below a pixel at any view of a robot
SENT_MOVE = 2e-5
SHADOW_TRIANGLES = 30_000  # a robot drawn with more triangles casts no shadow (see build)


# triangles the page draws for a primitive (three.js's box, 32-segment cylinder, icosahedron of
# detail 2): they count towards the shadow budget as a mesh's do
_PRIMITIVE_TRIANGLES = {Box: 12, Cylinder: 128, Sphere: 180}


def trimesh_of(geometry: Geometry, robot: RobotModel):
    """A trimesh of the geometry (the model editor's; the lab's page draws without trimesh)."""
    import trimesh

    match geometry:
        case Box(size):
            return trimesh.creation.box(extents=size)
        case Cylinder(radius, length):
            return trimesh.creation.cylinder(radius=radius, height=length, sections=32)
        case Sphere(radius):
            return trimesh.creation.icosphere(subdivisions=2, radius=radius)
        case Mesh(filename, scale):
            mesh = load_mesh(resolve_mesh(filename, robot.base_dir)).copy()
            mesh.apply_scale(scale)
            return mesh
    raise TypeError(geometry)


def inertia_box(mass: float, tensor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(box sizes, principal axes): the uniform box with the same mass and principal moments,
    which is what Gazebo's View > Inertia draws."""
    moments, axes = np.linalg.eigh(tensor)
    a, b, c = moments
    sizes = np.sqrt(np.maximum(6.0 / mass * np.array([b + c - a, a + c - b, a + b - c]), 0.0))
    if np.linalg.det(axes) < 0:
        axes[:, 2] *= -1
    return sizes, axes


def _wxyz(rotation: np.ndarray) -> np.ndarray:
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(rotation).ravel())
    return quat


@dataclass
class RobotScene:
    server: viser.ViserServer
    sim: Simulation
    links: dict[str, viser.SceneNodeHandle] = field(default_factory=dict)
    visuals: list = field(default_factory=list)
    triangles: int = 0  # drawn in the robot's visuals, after simplification
    overlays: dict[str, list] = field(default_factory=lambda: {k: [] for k in OVERLAYS})
    showing: set[str] = field(default_factory=set)  # the overlays shown now
    _sent: np.ndarray = field(default_factory=lambda: np.zeros((0, 7)))  # poses last sent
    _ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))  # their bodies

    def _terrain(self) -> None:
        """The world's static boxes (slopes, steps: physics.world.Block), as MuJoCo places them."""
        model = self.sim.model
        for i in range(model.ngeom):
            name = model.geom(i).name
            if not name.startswith("world/") or model.geom_type[i] != mujoco.mjtGeom.mjGEOM_BOX:
                continue
            self.server.scene.add_box(f"/terrain/{i}", dimensions=tuple(2 * model.geom_size[i]),
                                      color=(150, 144, 134), position=tuple(model.geom_pos[i]),
                                      wxyz=tuple(model.geom_quat[i]))

    def build(self) -> None:
        scene, robot = self.server.scene, self.sim.robot
        scene.set_up_direction("+z")
        scene.add_grid("/ground", width=20, height=20, cell_size=0.25, section_size=1.0,
                       plane_color=(225, 228, 232), plane_opacity=1.0, position=(0, 0, -0.0005))
        self._terrain()
        # the world's sun casts the one shadow (viser's default lights would add a second pass)
        scene.configure_default_lights(cast_shadow=False)
        # dimmer than viser's defaults, which wash a white robot's dark servos out to mid grey
        scene.configure_environment_map(environment_intensity=ENVIRONMENT_LIGHT)
        scene.add_light_ambient("/ambient", intensity=AMBIENT_LIGHT)
        # sent before the meshes and hidden after them, so every page shows it while they arrive
        loading = self.server.gui.add_markdown("**Loading the robot…**")
        budgets = display_budgets(robot)
        self.triangles = 0
        for name in self.sim.compiled.bodies:
            node = scene.add_frame(f"/robot/{name}", show_axes=False)
            self.links[name] = node
            link = robot.links[name]
            for i, vis in enumerate(link.visuals):
                rgba = display_rgba(robot, name, vis)
                handle, triangles = self._add_shape(
                    f"/robot/{name}/visual_{i}", vis.geometry, budgets,
                    color=tuple(int(255 * c) for c in rgba[:3]),
                    position=vis.origin.xyz, wxyz=_wxyz(vis.origin.matrix[:3, :3]))
                self.visuals.append(handle)
                self.triangles += triangles
            for i, col in enumerate(link.collisions):
                handle, _ = self._add_shape(
                    f"/robot/{name}/collision_{i}", col.geometry, budgets,
                    color=_COLLISION_RGB, opacity=0.55, position=col.origin.xyz,
                    wxyz=_wxyz(col.origin.matrix[:3, :3]), visible=False)
                self.overlays["Collisions"].append(handle)
            if link.inertial and link.inertial.mass > 0:
                self._add_inertial(name, link.inertial)
            joint = robot.parent_joint.get(name)
            if joint is not None and joint.moving:
                axis = np.asarray(joint.axis, dtype=float)
                axis /= np.linalg.norm(axis)
                self.overlays["Joints"].append(scene.add_arrows(
                    f"/robot/{name}/joint_axis", np.array([[[0, 0, 0], 0.12 * axis]]),
                    _JOINT_RGB, shaft_radius=0.004, head_radius=0.01, head_length=0.025,
                    visible=False))
        self.overlays["Contacts"].append(scene.add_line_segments(
            "/contacts", np.zeros((1, 2, 3)), _CONTACT_RGB, thickness=0.006, visible=False))
        # a shadow pass draws every triangle again: a browser without a GPU draws a big robot's
        # first frame in seconds with it, so only a light robot casts a shadow
        scene.add_light_directional("/sun", color=(255, 250, 240), intensity=2.0,
                                    cast_shadow=self.triangles <= SHADOW_TRIANGLES,
                                    wxyz=_wxyz(_look(np.array(self.sim.compiled.world.sun_direction))))
        loading.visible = False
        self.update()

    def _add_shape(self, name: str, geometry: Geometry, budgets: dict[str, int | None],
                   **style) -> tuple[viser.SceneNodeHandle, int]:
        """(the scene node, triangles drawn): primitives as viser's, meshes as their arrays
        (float32 vertices, uint32 faces: what goes on the wire, and no trimesh imported)."""
        scene = self.server.scene
        match geometry:
            case Box(size):
                handle = scene.add_box(name, dimensions=tuple(size), **style)
            case Cylinder(radius, length):
                handle = scene.add_cylinder(name, radius=radius, height=length, radial_segments=32,
                                            **style)
            case Sphere(radius):
                handle = scene.add_icosphere(name, radius=radius, subdivisions=2, **style)
            case Mesh(filename, scale):
                path = resolve_mesh(filename, self.sim.robot.base_dir)
                mesh = display_mesh(path, budgets.get(filename)).scaled(scale)
                handle = scene.add_mesh_simple(name, mesh.vertices.astype(np.float32),
                                               mesh.faces.astype(np.uint32), **style)
                return handle, len(mesh.faces)
            case _:
                raise TypeError(geometry)
        return handle, _PRIMITIVE_TRIANGLES[type(geometry)]

    def _add_inertial(self, name: str, inertial) -> None:
        scene = self.server.scene
        com = np.asarray(inertial.origin.xyz)
        radius = 0.015 * max(inertial.mass, 0.05) ** (1 / 3)
        self.overlays["Center of Mass"].append(scene.add_icosphere(
            f"/robot/{name}/com", radius=radius, color=_COM_RGB, position=com, visible=False))
        rot = inertial.origin.matrix[:3, :3]
        sizes, axes = inertia_box(inertial.mass, rot @ inertial.tensor @ rot.T)
        self.overlays["Inertia"].append(scene.add_box(
            f"/robot/{name}/inertia", dimensions=tuple(np.maximum(sizes, 1e-4)), color=_INERTIA_RGB,
            opacity=0.35, position=com, wxyz=_wxyz(axes), visible=False))

    # ----- per frame ------------------------------------------------------------------------
    def update(self, everything: bool = False) -> None:
        """Send the links that moved since they were last sent (SENT_MOVE): a standing robot
        costs the page almost no messages, where each link's pose every frame was most of a
        lab's CPU with its page open (benchmarks/RESULTS.md, "what one lab costs").
        `everything`: every link's pose (a recording's first frame, where its loop restarts)."""
        data, bodies = self.sim.data, self.sim.compiled.bodies
        if everything or len(self._sent) != len(bodies):
            self._sent = np.full((len(bodies), 7), np.nan)  # nothing sent yet
            self._ids = np.fromiter(bodies.values(), dtype=int, count=len(bodies))
        names, ids = list(bodies), self._ids
        now = np.concatenate((data.xpos[ids], data.xquat[ids]), axis=1)
        # NaN (never sent) compares False: every link goes out the first time
        moved = np.flatnonzero(~(np.abs(now - self._sent).max(axis=1) <= SENT_MOVE))
        contacts = self.overlays["Contacts"][0]
        if moved.size == 0 and not contacts.visible:
            return  # nothing to send: not even an empty batch (each wakes viser's event loop)
        with self.server.atomic():
            for i in moved:
                node = self.links[names[i]]
                node.position = now[i, :3]
                node.wxyz = now[i, 3:]
            self._sent[moved] = now[moved]
            if contacts.visible:
                contacts.points = self._contact_segments()

    def _contact_segments(self) -> np.ndarray:
        model, data = self.sim.model, self.sim.data
        force = np.zeros(6)
        segments = []
        for i in range(min(data.ncon, _MAX_CONTACTS)):
            contact = data.contact[i]
            mujoco.mj_contactForce(model, data, i, force)
            frame = contact.frame.reshape(3, 3)  # rows: normal, tangent, tangent
            world = frame.T @ force[:3]
            tip = contact.pos + 0.01 * world  # 1 cm per newton
            segments.append([contact.pos, tip])
        return np.array(segments, dtype=np.float32) if segments else np.zeros((1, 2, 3), np.float32)

    # ----- toggles --------------------------------------------------------------------------
    def show(self, overlay: str, visible: bool) -> None:
        (self.showing.add if visible else self.showing.discard)(overlay)
        for handle in self.overlays[overlay]:
            handle.visible = visible
        if overlay == "Contacts" and visible:
            self.update()

    def set_transparent(self, on: bool) -> None:
        for handle in self.visuals:
            handle.opacity = 0.35 if on else None

    def set_wireframe(self, on: bool) -> None:
        for handle in self.visuals:
            handle.wireframe = on

    def set_robot_visible(self, on: bool) -> None:
        for handle in self.visuals:
            handle.visible = on


def _look(direction: np.ndarray) -> np.ndarray:
    """A rotation whose -z axis points along `direction` (three.js lights shine along -z)."""
    z = -direction / np.linalg.norm(direction)
    x = np.cross([0.0, 0.0, 1.0], z)
    if np.linalg.norm(x) < 1e-6:
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])
