"""EditSession: the working model in a folder, every edit a step of an undoable history on disk.

The folder holds model.urdf (the current model), meshes/ (imported parts, under names the server
chose) and history/ (one URDF and one JSON of editor state per step, and which step is current).
The URDF is the document: each edit copies the model, changes the copy, writes it as a new step
and reads it back, so what the page shows is always what a save would write, and a reload of
the page (or of the server) finds the same model and the same undo history.
"""

from __future__ import annotations

import copy
import json
import math
import os
import re
import threading
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from mexone.control.autotune import tune
from mexone.control.spec import PidGains
from mexone.description.check import check_model, inertial_problem
from mexone.description.convert import rebase_meshes
from mexone.description.findings import Finding
from mexone.description.kinematics import joint_motion
from mexone.description.loader import load_model
from mexone.description.meshes import load_mesh, resolve_mesh
from mexone.description.model import (
    Box,
    Collision,
    Cylinder,
    Dynamics,
    GazeboLink,
    Inertial,
    Joint,
    Limit,
    Link,
    Mesh,
    Pose,
    RobotModel,
    Sphere,
    Transmission,
    Visual,
)
from mexone.description.urdf import parse_urdf, write_urdf
from mexone.description.xmlio import XmlReader
from mexone.editor.massprops import MassProperties, fit_collisions, mass_properties, solid_of
from mexone.editor.parts import UNITS, quoted, read_part
from mexone.editor.snapping import SNAP_RADIUS, Snap, nearest_snap, snap_points
from mexone.errors import InputError, MexoneError
from mexone.physics.world import default_world
from mexone.ranges import (
    ANGLE,
    COLOUR,
    CONTACT_KD,
    CONTACT_KP,
    DAMPING,
    EFFORT,
    FRICTION,
    JOINT_VALUE,
    LENGTH,
    MASS,
    MOMENT,
    MU,
    POSITION,
    PRODUCT,
    SIZE,
    VELOCITY,
    Range,
    number_text,
)

__all__ = ["EditSession", "EDIT_TYPES", "DEFAULT_DENSITY", "MAX_SNAP_CHOICES", "selection_of"]

EDIT_TYPES = ("revolute", "continuous", "prismatic", "fixed")  # what the Model Editor offered
DEFAULT_DENSITY = 1200.0  # kg/m^3 (3D-printed plastic): an imported part's mass until one is typed
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,63}$")
_ELEMENT = re.compile(r'^(link|joint) "(.+)"$')
MAX_HISTORY = 500  # steps kept on disk; older ones are dropped
MAX_SNAP_CHOICES = 60  # snap candidates the page lists for a child


def selection_of(finding: Finding) -> tuple[str, str] | None:
    """('link'|'joint', name) a finding is about, for the page to select it."""
    match = _ELEMENT.match(finding.element)
    return (match.group(1), match.group(2)) if match else None


def _numbers(values, what: str, valid: Range | None = None, count: int | None = None) -> tuple[float, ...]:
    """`count` numbers from what a page sent, each finite and in `valid` (ranges.py), or an
    InputError naming `what`: the page is not trusted, so nothing it sends reaches the model unread."""
    try:
        items = np.asarray(values, dtype=float).ravel()
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{what} is not a list of numbers", hint="type numbers") from None
    if count is not None and len(items) != count:
        raise InputError(f"{what} needs {count} numbers, not {len(items)}", hint="type numbers")
    for item in items:
        if valid is not None:
            valid.check(item, what)  # its range says what to type
        elif not math.isfinite(item):
            raise InputError(f"{what} {number_text(item)} is not finite", hint="type numbers")
    return tuple(float(v) for v in items)


def _direction(values, what: str) -> tuple[float, ...]:
    """A unit vector along three finite numbers, not all zero (scaled first: the norm of
    (1e308, 1e308, 1e308) overflows, its direction does not)."""
    vector = np.array(_numbers(values, what, count=3))
    largest = float(np.max(np.abs(vector)))
    if largest == 0:
        raise InputError(f"{what} ({', '.join(number_text(v) for v in vector)}) must not be all zero",
                         hint="type the direction, e.g. 0 0 1")
    vector = vector / largest
    return tuple(float(v) for v in vector / np.linalg.norm(vector))


def _shown(value: object) -> str:
    """What a page sent, quoted for a one-line message: escapes shown, at most 64 characters."""
    return repr(value[:64] if isinstance(value, str) else value)[:80]


def _name(text: str, what: str) -> str:
    if not isinstance(text, str) or not _NAME.match(text):
        raise InputError(f"{what} {_shown(text)} is not a valid name",
                         hint="letters, digits and _, starting with a letter, at most 64")
    return text


@dataclass
class _Extras:
    """What the URDF cannot hold: motor gains, where loose parts sit, the step's description."""

    label: str = ""
    motors: dict[str, PidGains] = field(default_factory=dict)
    placements: dict[str, list[float]] = field(default_factory=dict)  # root link -> 4x4 row-major
    collision_shapes: dict[str, str] = field(default_factory=dict)  # link -> last fitted shape
    uris: dict[str, str] = field(default_factory=dict)  # absolute mesh path -> the URI it was
    typed: list[str] = field(default_factory=list)  # motors whose gains were typed, not auto

    def to_json(self) -> str:
        return json.dumps({"label": self.label, "placements": self.placements,
                           "collision_shapes": self.collision_shapes, "uris": self.uris, "typed": self.typed,
                           "motors": {k: vars(v) for k, v in self.motors.items()}}, indent=1)

    @staticmethod
    def from_json(text: str) -> _Extras:
        raw = json.loads(text)
        return _Extras(raw.get("label", ""), {k: PidGains(**v) for k, v in raw.get("motors", {}).items()},
                       raw.get("placements", {}), raw.get("collision_shapes", {}), raw.get("uris", {}),
                       raw.get("typed", []))


class EditSession:
    """The model being edited. Every public method that changes it is one undoable step."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self.history = self.folder / "history"
        self.meshes = self.folder / "meshes"
        self.model: RobotModel
        self.extras: _Extras
        self._findings: list[Finding] | None = None
        self._state_cache: dict | None = None

    # ----- opening ------------------------------------------------------------------------------
    @classmethod
    def open(cls, folder: Path, source: Path | None = None, name: str = "robot") -> EditSession:
        """Resume the folder's history if it has one, else start from `source` (any model file
        mexone reads) or from an empty robot."""
        session = cls(folder)
        session.folder.mkdir(parents=True, exist_ok=True)
        session.meshes.mkdir(exist_ok=True)
        session.history.mkdir(exist_ok=True)
        if (session.history / "state.json").is_file():
            session._load(session._state()["index"])
            return session
        if source is not None:
            model = load_model(source)
            model = rebase_meshes(model, session.folder)
            extras = _Extras("open " + Path(source).name)
            extras.uris = _absolute_uris(model, session.folder)
            extras.motors = _auto_gains(model, [t.joint for t in model.transmissions])
        else:
            model = RobotModel(_name(name, "robot name"), {}, {})
            extras = _Extras("new robot")
        session._write_step(0, model, extras)
        return session

    # ----- history ------------------------------------------------------------------------------
    def _state(self) -> dict:
        if self._state_cache is None:
            self._state_cache = json.loads((self.history / "state.json").read_text())
        return dict(self._state_cache)

    def _save_state(self, state: dict) -> None:
        """Atomically (a crash or a reader never sees half a file), then remembered."""
        _write_atomic(self.history / "state.json", json.dumps(state))
        self._state_cache = dict(state)

    def _step_paths(self, index: int) -> tuple[Path, Path]:
        return self.history / f"{index:04d}.urdf", self.history / f"{index:04d}.json"

    def _write_step(self, index: int, model: RobotModel, extras: _Extras) -> None:
        """The model is read back before anything is written, so one the reader refuses (an
        axis that overflowed to zero) changes no file; then the step's files, the working
        model.urdf (atomically) and last the index: whoever sees the new index sees its model."""
        text = write_urdf(model)
        checked = self._read_back(text)
        urdf, meta = self._step_paths(index)
        _write_atomic(urdf, text)
        _write_atomic(meta, extras.to_json())
        first = 0 if index == 0 else self._state().get("first", 0)
        if index - first >= MAX_HISTORY:
            for old in self._step_paths(first):
                old.unlink(missing_ok=True)
            first += 1
        self._install(checked, extras)
        self._save_state({"index": index, "top": index, "first": first})

    def _read_back(self, text: str) -> tuple[str, RobotModel]:
        """(the URDF `text`, the model the reader reads from it as model.urdf), or the reader's
        error: the check comes before any file is written."""
        working = self.folder / "model.urdf"
        model = parse_urdf(XmlReader(working, data=text.encode()), working)
        model.reader_findings.clear()  # a new robot has no links yet; check says so itself
        return text, model

    def _install(self, checked: tuple[str, RobotModel], extras: _Extras) -> None:
        text, model = checked
        _write_atomic(self.folder / "model.urdf", text)
        self.model, self.extras = model, extras
        self._findings = None

    def _load(self, index: int) -> None:
        urdf, meta = self._step_paths(index)
        extras = _Extras.from_json(meta.read_text())
        self._install(self._read_back(urdf.read_text()), extras)

    @property
    def index(self) -> int:
        return self._state()["index"]

    @property
    def can_undo(self) -> bool:
        state = self._state()
        return state["index"] > state.get("first", 0)

    @property
    def can_redo(self) -> bool:
        state = self._state()
        return state["index"] < state["top"]

    def _move(self, index: int) -> None:
        state = self._state()
        self._load(index)
        state["index"] = index
        self._save_state(state)

    def undo(self) -> str:
        """Back one step; returns what was undone."""
        if not self.can_undo:
            raise InputError("nothing to undo")
        label = self.extras.label
        self._move(self.index - 1)
        return label

    def redo(self) -> str:
        if not self.can_redo:
            raise InputError("nothing to redo")
        self._move(self.index + 1)
        return self.extras.label

    def _edit(self, label: str, change) -> None:
        """One step: `change(model, extras)` edits copies; they become the new current step
        (any redo steps beyond the current one are dropped, as in every editor)."""
        model = copy.deepcopy(self.model)
        model = replace(model)  # a fresh object: no stale cached tree
        extras = copy.deepcopy(self.extras)
        extras.label = label
        change(model, extras)
        model = replace(model)
        # auto gains follow the robot (a joint added below a motor changes what it moves)
        extras.motors.update(_auto_gains(model, [j for j in extras.motors if j not in extras.typed]))
        self._write_step(self.index + 1, model, extras)

    # ----- queries ------------------------------------------------------------------------------
    def findings(self) -> list[Finding]:
        """`mexone check`'s findings for the current model (and its controllers)."""
        if self._findings is None:
            from mexone.control.lint import lint_controllers

            found = [] if not self.model.links else check_model(self.model)
            if self.extras.motors:
                found += lint_controllers(self.model, self.control_config())
            self._findings = found
        return self._findings

    def link(self, name: str) -> Link:
        if not isinstance(name, str) or name not in self.model.links:
            raise InputError(f"no link {_shown(name)}", hint="pick a link of the model")
        return self.model.links[name]

    def joint(self, name: str) -> Joint:
        if not isinstance(name, str) or name not in self.model.joints:
            raise InputError(f"no joint {_shown(name)}", hint="pick a joint of the model")
        return self.model.joints[name]

    def part_mesh(self, link: str):
        """(trimesh in metres in its geometry frame, geometry origin in the link) of the link's
        first mesh visual, or None."""
        for visual in self.link(link).visuals:
            if isinstance(visual.geometry, Mesh):
                path = resolve_mesh(visual.geometry.filename, self.model.base_dir)
                mesh = load_mesh(path).copy()
                mesh.merge_vertices()  # loaded unprocessed: an STL closes only once corners merge
                mesh.apply_scale(np.asarray(visual.geometry.scale))
                return mesh, visual.origin.matrix
        return None

    def world_frames(self, positions: dict[str, float] | None = None) -> dict[str, np.ndarray]:
        """Every link's frame in the editor's world: each root where it was placed, the rest
        through the joints at `positions` (others at 0)."""
        model, positions = self.model, positions or {}
        frames: dict[str, np.ndarray] = {}
        for root in model.roots or list(model.links)[:1]:
            frames[root] = np.asarray(self.extras.placements.get(root, np.eye(4).ravel().tolist()),
                                      dtype=float).reshape(4, 4)
            for name in model.walk(root):
                for joint in model.child_joints.get(name, []):
                    if joint.child not in frames:
                        motion = joint_motion(joint.axis, joint.type, positions.get(joint.name, 0.0))
                        frames[joint.child] = frames[name] @ joint.origin.matrix @ motion
        return frames

    def snaps(self, link: str) -> list[tuple[Snap, np.ndarray, np.ndarray]]:
        """Snap candidates on the link's mesh: (snap, point, axis) with point and axis in the
        editor's world."""
        found = self.part_mesh(link)
        if found is None:
            return []
        mesh, origin = found
        frame = self.world_frames()[link] @ origin
        return [(s, frame[:3, :3] @ s.point + frame[:3, 3], frame[:3, :3] @ s.axis)
                for s in snap_points(mesh)]

    def snap_choices(self, link: str) -> list[str]:
        """What the page's *Snap on child* list offers for `link`: 'index: label', the first
        MAX_SNAP_CHOICES candidates."""
        return [f"{i}: {snap.label}" for i, (snap, _p, _a) in enumerate(self.snaps(link)[:MAX_SNAP_CHOICES])]

    def snap_of(self, link: str, choice: object) -> int:
        """The index of the snap candidate `choice` names, refused unless it is one the page was
        offered for `link` (a websocket client can send any string: '9999: x', '-1: x')."""
        self.link(link)
        choices = self.snap_choices(link)
        if not isinstance(choice, str) or choice not in choices:
            raise InputError(f"snap {_shown(choice)} is not one of the {len(choices)} offered on '{link}'",
                             hint="pick a snap from the list")
        return choices.index(choice)

    def control_config(self):
        """The controllers the motors make: a position controller per motor, with its gains."""
        from mexone.control.autotune import POSITION_TYPE, STATE_RATE, STATE_TYPE, controller_name
        from mexone.control.spec import ControlConfig, ControllerSpec

        config = ControlConfig(namespace=self.namespace.strip("/"))
        config.controllers["joint_state_controller"] = ControllerSpec(
            "joint_state_controller", STATE_TYPE, publish_rate=STATE_RATE)
        for joint, gains in self.extras.motors.items():
            name = controller_name(joint)
            config.controllers[name] = ControllerSpec(name, POSITION_TYPE, (joint,), gains)
        return config

    @property
    def namespace(self) -> str:
        from mexone.lab import robot_namespace

        return robot_namespace(self.model)

    # ----- links --------------------------------------------------------------------------------
    def import_part(self, filename: str, data: bytes, unit: str | None = None) -> str:
        """A new link from an uploaded mesh (`unit`: None means the guess). Its mass starts at
        DEFAULT_DENSITY; its inertia and a mesh collision come from the mesh. Returns its name."""
        part = read_part(filename, data, taken=set(self.model.links) | {"world"})
        unit = unit or part.guess
        if unit not in UNITS:
            raise InputError(f"unknown unit {_shown(unit)}", hint=f"one of: {', '.join(UNITS)}")
        scaled = part.mesh.copy()
        scaled.apply_scale(UNITS[unit])
        SIZE.check(float(np.max(scaled.extents)), f"{quoted(filename)} in {unit}: its largest side",
                   hint="pick the unit the part was drawn in")
        solid, _hull = solid_of(scaled, quoted(filename))
        mass = DEFAULT_DENSITY * solid.volume
        MASS.check(mass, f"{quoted(filename)} in {unit}: its mass at {DEFAULT_DENSITY:g} kg/m^3",
                   hint="pick the unit the part was drawn in")
        props = mass_properties(scaled, mass, np.eye(4))
        _refuse_inertial(part.name, props.inertial)
        path = self.meshes / f"{part.name}.stl"
        n = 2
        while path.exists():  # an undone import left its file; never reuse a name for new bytes
            path, n = self.meshes / f"{part.name}_{n}.stl", n + 1
        ref = Mesh(f"meshes/{path.name}", (UNITS[unit],) * 3)

        def change(model: RobotModel, extras: _Extras) -> None:
            model.links[part.name] = Link(part.name, props.inertial,
                                          [Visual(ref, name=f"{part.name}_visual")],
                                          [Collision(ref, name=f"{part.name}_collision")])
            extras.collision_shapes[part.name] = "mesh"

        part.mesh.export(path)
        try:
            self._edit(f"import {part.name} ({unit})", change)
        except BaseException:
            path.unlink(missing_ok=True)  # a refused import leaves nothing behind
            raise
        return part.name

    def mass_properties(self, link: str, mass: float) -> MassProperties:
        found = self.part_mesh(link)
        if found is None:
            raise InputError(f"link '{link}' has no mesh to compute an inertia from",
                             hint="type its inertia")
        (mass,) = _numbers(mass, "mass", MASS, 1)
        return mass_properties(found[0], mass, found[1])

    def compute_inertia(self, link: str, mass: float) -> MassProperties:
        """COM and inertia of the link's mesh at `mass` kg, uniform density."""
        props = self.mass_properties(link, mass)
        _refuse_inertial(link, props.inertial)

        def change(model: RobotModel, _extras: _Extras) -> None:
            model.links[link].inertial = props.inertial

        self._edit(f"{link}: inertia from mesh at {number_text(props.inertial.mass)} kg", change)
        return props

    def set_inertial(self, link: str, mass: float, com, inertia, rpy=(0.0, 0.0, 0.0)) -> None:
        """Typed in, as the seed did from CAD: mass, COM (link frame), ixx ixy ixz iyy iyz izz."""
        self.link(link)
        (mass,) = _numbers(mass, "mass", MASS, 1)
        ixx, ixy, ixz, iyy, iyz, izz = _numbers(inertia, "inertia", count=6)
        inertial = Inertial(mass, (ixx, ixy, ixz, iyy, iyz, izz),
                            Pose(_numbers(com, "centre of mass", LENGTH, 3),
                                 _numbers(rpy, "inertial rpy", ANGLE, 3)))
        _refuse_inertial(link, inertial)  # check's rule first: it says what is impossible
        _numbers((ixx, iyy, izz), "moment of inertia", MOMENT)
        _numbers((ixy, ixz, iyz), "product of inertia", PRODUCT)

        def change(model: RobotModel, _extras: _Extras) -> None:
            model.links[link].inertial = inertial

        self._edit(f"{link}: inertial typed", change)

    def fit_collision(self, link: str, shape: str) -> None:
        found = self.part_mesh(link)
        if found is None:
            raise InputError(f"link '{link}' has no mesh to fit a collision to")
        mesh, origin = found
        visual = next(v for v in self.link(link).visuals if isinstance(v.geometry, Mesh))
        hull_ref = None
        if shape == "convex hull":
            hull_path = self.meshes / f"{link}_hull.stl"
            mesh.convex_hull.export(hull_path)  # in metres already
            hull_ref = Mesh(f"meshes/{hull_path.name}")
        collisions = fit_collisions(mesh, shape, origin, visual.geometry, hull_ref)
        collisions = [replace(c, name=c.name or f"{link}_collision") for c in collisions]

        def change(model: RobotModel, extras: _Extras) -> None:
            model.links[link].collisions = collisions
            extras.collision_shapes[link] = shape

        self._edit(f"{link}: collision {shape}", change)

    def set_collision(self, link: str, index: int, geometry, origin: Pose) -> None:
        """Edit a fitted shape by hand (its size and place)."""
        cols = self.link(link).collisions
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < len(cols):
            raise InputError(f"link '{link}' has no collision {index!r}")
        match geometry:
            case Box(size):
                geometry = Box(_numbers(size, "collision size", SIZE, 3))
            case Cylinder(radius, length):
                geometry = Cylinder(*_numbers((radius, length), "collision size", SIZE, 2))
            case Sphere(radius):
                geometry = Sphere(*_numbers(radius, "collision size", SIZE, 1))
            case Mesh():
                geometry = cols[index].geometry if isinstance(cols[index].geometry, Mesh) else None
            case _:
                geometry = None
        if geometry is None:
            raise InputError("a collision is a box, cylinder or sphere", hint="fit a shape first")
        origin = Pose(_numbers(getattr(origin, "xyz", None), "collision xyz", LENGTH, 3),
                      _numbers(getattr(origin, "rpy", None), "collision rpy", ANGLE, 3))

        def change(model: RobotModel, _extras: _Extras) -> None:
            model.links[link].collisions[index] = replace(cols[index], geometry=geometry,
                                                          origin=origin)

        self._edit(f"{link}: collision {index} edited", change)

    def set_surface(self, link: str, mu1: float | None = None, mu2: float | None = None,
                    kp: float | None = None, kd: float | None = None) -> None:
        """Gazebo friction and contact values (None: Gazebo's default)."""
        self.link(link)
        values = {"mu1": mu1, "mu2": mu2, "kp": kp, "kd": kd}
        valid = {"mu1": MU, "mu2": MU, "kp": CONTACT_KP, "kd": CONTACT_KD}
        values = {key: None if value is None else _numbers(value, key, valid[key], 1)[0]
                  for key, value in values.items()}

        def change(model: RobotModel, _extras: _Extras) -> None:
            props = model.gazebo_links.get(link, GazeboLink())
            model.gazebo_links[link] = replace(props, **values)

        self._edit(f"{link}: surface", change)

    def set_color(self, link: str, rgba) -> None:
        self.link(link)
        rgba = _numbers(rgba, "colour", COLOUR, 4)

        def change(model: RobotModel, _extras: _Extras) -> None:
            target = model.links[link]
            target.visuals = [replace(v, rgba=rgba, material=v.material or f"{link}_color")
                              for v in target.visuals]

        self._edit(f"{link}: colour", change)

    def place(self, link: str, matrix: np.ndarray) -> None:
        """Where a loose part (a root) sits in the editor's world, before a joint holds it."""
        self.link(link)
        if link not in self.model.roots:
            raise InputError(f"'{link}' hangs on joint '{self.model.parent_joint[link].name}'",
                             hint="move the joint's frame instead")
        matrix = np.array(_numbers(matrix, "placement", count=16)).reshape(4, 4)
        _numbers(matrix[:3, 3], "placement", POSITION)
        rotation = matrix[:3, :3]
        if not (np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-6) and np.linalg.det(rotation) > 0
                and np.allclose(matrix[3], (0, 0, 0, 1))):
            raise InputError("placement is not a rigid motion (a rotation and a translation)",
                             hint="move the part with the gizmo")

        def change(_model: RobotModel, extras: _Extras) -> None:
            extras.placements[link] = matrix.ravel().tolist()

        self._edit(f"{link}: moved", change)

    def fix_to_world(self, link: str, fixed: bool = True) -> None:
        """Weld a root to a 'world' link where it sits (an arm on a table), or free it."""
        model = self.model
        if fixed:
            if model.fixed_to_world:
                raise InputError("the robot is already fixed to the world")
            if link not in model.roots:
                raise InputError(f"'{link}' is not a root link", hint="fix the arm's base")

            def change(m: RobotModel, extras: _Extras) -> None:
                place = np.asarray(extras.placements.pop(link, np.eye(4).ravel().tolist())).reshape(4, 4)
                m.links = {"world": Link("world"), **m.links}
                m.joints[f"{link}_to_world"] = Joint(f"{link}_to_world", "fixed", "world", link,
                                                     Pose.from_matrix(place))
        else:
            world = [j for j in model.joints.values() if j.parent == "world"]
            if not world:
                raise InputError("the robot is not fixed to the world")

            def change(m: RobotModel, extras: _Extras) -> None:
                for j in world:
                    extras.placements[j.child] = j.origin.matrix.ravel().tolist()
                    del m.joints[j.name]
                del m.links["world"]
        self._edit(f"{link}: {'fixed to' if fixed else 'freed from'} the world", change)

    # ----- joints -------------------------------------------------------------------------------
    def add_joint(self, name: str, parent: str, child: str, type: str, point, axis) -> None:
        """Join `child` to `parent` where they sit now, the joint at `point` turning about `axis`
        (both in the editor's world: a snap's, or typed). The child's frame moves onto the joint
        (as URDF requires) and its parts stay where they are."""
        _name(name, "joint name")
        if name in self.model.joints:
            raise InputError(f"there is already a joint '{name}'", hint="pick another name")
        self.link(parent)
        self.link(child)
        if type not in EDIT_TYPES:
            raise InputError(f"joint type {_shown(type)} is not one of {', '.join(EDIT_TYPES)}")
        if child not in self.model.roots or child == "world":
            raise InputError(f"'{child}' already hangs on a joint", hint="a link has one parent")
        if parent in self.model.walk(child):
            raise InputError(f"'{parent}' hangs below '{child}': that joint would close a loop",
                             hint="swap parent and child")
        point = np.array(_numbers(point, "joint point", POSITION, 3))
        axis = np.array(_direction(axis, "joint axis"))
        frames = self.world_frames()
        child_world, parent_world = frames[child], frames[parent]
        joint_world = child_world.copy()
        joint_world[:3, 3] = point  # the child's frame keeps its orientation, moves to the joint
        shift = np.linalg.inv(joint_world) @ child_world
        local_axis = child_world[:3, :3].T @ axis
        origin = Pose.from_matrix(np.linalg.inv(parent_world) @ joint_world)
        limit = Limit(-math.pi / 2, math.pi / 2, 10.0, 3.0) if type == "revolute" else \
            Limit(-0.1, 0.1, 100.0, 0.5) if type == "prismatic" else \
            Limit(0.0, 0.0, 10.0, 3.0) if type == "continuous" else None

        def change(model: RobotModel, extras: _Extras) -> None:
            _reexpress(model, child, shift)
            model.joints[name] = Joint(name, type, parent, child, origin,
                                       tuple(float(v) for v in local_axis), limit)
            extras.placements.pop(child, None)

        self._edit(f"joint {name}: {parent} -> {child}", change)

    def set_joint(self, name: str, type: str | None = None, axis=None, limit: Limit | None = None,
                  dynamics: Dynamics | None = None) -> None:
        joint = self.joint(name)
        if type is not None and type not in EDIT_TYPES:
            raise InputError(f"joint type {_shown(type)} is not one of {', '.join(EDIT_TYPES)}")
        if axis is not None:
            axis = _direction(axis, "axis")
        if limit is not None:
            lower, upper = _numbers((limit.lower, limit.upper), "limit", JOINT_VALUE, 2)
            if lower > upper:
                raise InputError(f"lower limit {number_text(lower)} > upper limit {number_text(upper)}")
            limit = Limit(lower, upper, *_numbers(limit.effort, "effort limit", EFFORT, 1),
                          *_numbers(limit.velocity, "velocity limit", VELOCITY, 1))
        if dynamics is not None:
            dynamics = Dynamics(*_numbers(dynamics.damping, "damping", DAMPING, 1),
                                *_numbers(dynamics.friction, "friction", FRICTION, 1),
                                *_numbers(dynamics.armature, "armature", MOMENT, 1))

        def change(model: RobotModel, extras: _Extras) -> None:
            target = model.joints[name]
            target.type = type or target.type
            target.axis = axis or target.axis
            target.limit = limit if limit is not None else target.limit
            target.dynamics = dynamics if dynamics is not None else target.dynamics
            if dynamics is not None and name in model.gazebo_joints:
                model.gazebo_joints[name] = dynamics  # Gazebo's <gazebo> value wins: both say it
            if target.type == "fixed":
                model.transmissions = [t for t in model.transmissions if t.joint != name]
                extras.motors.pop(name, None)
            elif target.limit is None:
                target.limit = Limit(0.0, 0.0, 10.0, 3.0)

        self._edit(f"joint {name}: {'type ' + type if type and type != joint.type else 'edited'}", change)

    def move_joint_frame(self, name: str, origin: Pose, keep_parts: bool = True) -> None:
        """Put the joint's frame at `origin` (in the parent's frame), from a gizmo or typed.
        keep_parts: the child's parts stay where they are (the frame moves over them, as in the
        Model Editor); otherwise the child moves with its frame."""
        joint = self.joint(name)
        new = Pose(_numbers(getattr(origin, "xyz", None), "joint position", LENGTH, 3),
                   _numbers(getattr(origin, "rpy", None), "joint rotation", ANGLE, 3))
        shift = np.linalg.inv(new.matrix) @ joint.origin.matrix

        def change(model: RobotModel, _extras: _Extras) -> None:
            target = model.joints[name]
            target.origin = new
            if keep_parts:
                _reexpress(model, target.child, shift)
                target.axis = tuple(float(v) for v in shift[:3, :3] @ np.asarray(target.axis))

        self._edit(f"joint {name}: frame moved", change)

    def snap_joint(self, name: str, snap_index: int) -> Snap:
        """Move the joint's frame onto a snap candidate of its child's mesh (parts stay), its
        axis along the candidate's: one edit, one undo. The frame keeps the child's orientation,
        so a URDF reads `axis 0 1 0` for a hole along y, not a rotated frame."""
        joint = self.joint(name)
        snaps = self.snaps(joint.child)
        if isinstance(snap_index, bool) or not isinstance(snap_index, int | np.integer) \
                or not 0 <= snap_index < len(snaps):
            raise InputError(f"snap {_shown(snap_index)} is not one of the {len(snaps)} candidates on "
                             f"'{joint.child}'", hint="pick a snap from the list")
        snap, point, axis = snaps[snap_index]
        frames = self.world_frames()
        parent, child = frames[joint.parent], frames[joint.child]
        joint_world = child.copy()
        joint_world[:3, 3] = point
        new = Pose.from_matrix(np.linalg.inv(parent) @ joint_world)
        shift = np.linalg.inv(new.matrix) @ joint.origin.matrix
        local_axis = child[:3, :3].T @ np.array(_direction(axis, "snap axis"))

        def change(model: RobotModel, _extras: _Extras) -> None:
            target = model.joints[name]
            target.origin = new
            _reexpress(model, target.child, shift)
            target.axis = tuple(float(v) for v in local_axis)

        self._edit(f"joint {name}: frame snapped to {snap.label}", change)
        return snap

    def snap_joint_near(self, name: str, at, radius: float = SNAP_RADIUS) -> Snap | None:
        """The dropped gizmo's magnet: snap the joint's frame to the candidate of its child's
        mesh nearest `at` (the editor's world) within `radius`; None (nothing changed) when
        every candidate is further."""
        joint = self.joint(name)
        at = np.array(_numbers(at, "gizmo position", POSITION, 3))
        index = nearest_snap(self.snaps(joint.child), at, radius)
        return None if index is None else self.snap_joint(name, index)

    def remove_joint(self, name: str) -> None:
        joint = self.joint(name)
        frames = self.world_frames()

        def change(model: RobotModel, extras: _Extras) -> None:
            del model.joints[name]
            model.transmissions = [t for t in model.transmissions if t.joint != name]
            extras.motors.pop(name, None)
            extras.placements[joint.child] = frames[joint.child].ravel().tolist()

        self._edit(f"joint {name} removed", change)

    def remove_link(self, name: str) -> None:
        self.link(name)
        if self.model.child_joints.get(name) or name in self.model.parent_joint:
            raise InputError(f"link '{name}' is joined to others", hint="remove its joints first")

        def change(model: RobotModel, extras: _Extras) -> None:
            del model.links[name]
            model.gazebo_links.pop(name, None)
            extras.placements.pop(name, None)

        self._edit(f"link {name} removed", change)

    # ----- motors -------------------------------------------------------------------------------
    def set_motor(self, joint: str, on: bool = True, gains: PidGains | None = None) -> PidGains | None:
        """A transmission and a position controller on the joint, or neither. Gains given are
        kept; otherwise they are the auto gains of `mexone controllers`, recomputed after every
        edit. Returns the gains."""
        target = self.joint(joint)
        if on and not target.moving:
            raise InputError(f"joint '{joint}' is {target.type}: nothing for a motor to move")
        if gains is not None:
            gains = PidGains(*_numbers((gains.p, gains.i, gains.d, gains.i_clamp_min, gains.i_clamp_max),
                                       "gains", count=5), antiwindup=bool(gains.antiwindup))
        if gains is not None and (problem := gains.problem()) is not None:
            raise InputError(f"joint '{joint}': {problem}")
        typed = gains is not None
        if on and gains is None:
            gains = _auto_gains(self.model, [joint]).get(joint)
            if gains is None:
                raise InputError(f"joint '{joint}' moves nothing with mass: no gains to derive",
                                 hint="give the child link a mass first")

        def change(model: RobotModel, extras: _Extras) -> None:
            model.transmissions = [t for t in model.transmissions if t.joint != joint]
            extras.motors.pop(joint, None)
            if joint in extras.typed:
                extras.typed.remove(joint)
            if on:
                model.transmissions.append(Transmission(f"{joint}_tran", joint, actuator=f"{joint}_motor"))
                extras.motors[joint] = gains
                if typed:
                    extras.typed.append(joint)
                if model.ros_namespace is None:
                    model.ros_namespace = "/" + model.name
        self._edit(f"motor {joint}: {'on' if on else 'off'}", change)
        return gains

    def auto_gains(self) -> dict[str, PidGains]:
        """Fresh auto gains for every motor (after masses or joints changed)."""
        return _auto_gains(self.model, list(self.extras.motors))

    def rename(self, name: str) -> None:
        _name(name, "robot name")

        def change(model: RobotModel, _extras: _Extras) -> None:
            model.name = name

        self._edit(f"robot named {name}", change)


def _write_atomic(path: Path, text: str) -> None:
    """`text` in `path` whole or not at all (a crash or a reader never sees half a file)."""
    temporary = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}")
    try:
        temporary.write_text(text)
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)


def _refuse_inertial(link: str, inertial: Inertial) -> None:
    """`mexone check`'s inertial rule (description/check.py), as a refusal."""
    if (problem := inertial_problem(inertial)) is not None:
        raise InputError(f"link '{link}': {problem[1]}", hint="type the inertia of a real body, or "
                         "compute it from the mesh")


def _reexpress(model: RobotModel, link: str, shift: np.ndarray) -> None:
    """The link's frame moved by inv(shift): everything it carries gets `shift` so it stays put."""
    target = model.links[link]

    def moved(pose: Pose) -> Pose:
        return Pose.from_matrix(shift @ pose.matrix)

    target.visuals = [replace(v, origin=moved(v.origin)) for v in target.visuals]
    target.collisions = [replace(c, origin=moved(c.origin)) for c in target.collisions]
    if target.inertial is not None:
        target.inertial = replace(target.inertial, origin=moved(target.inertial.origin))
    for joint in model.joints.values():
        if joint.parent == link:
            joint.origin = moved(joint.origin)
    for i, sensor in enumerate(model.sensors):
        if getattr(sensor, "link", None) == link and hasattr(sensor, "pose"):
            model.sensors[i] = replace(sensor, pose=moved(sensor.pose))


def _auto_gains(model: RobotModel, joints: list[str]) -> dict[str, PidGains]:
    """The any-robot auto gains (control/autotune.py) for these joints, at the default step."""
    if not joints:
        return {}
    try:
        tunings = tune(model, default_world().step)
    except MexoneError:
        return {}
    return {t.joint: t.gains for t in tunings if t.joint in joints}


def _absolute_uris(model: RobotModel, folder: Path) -> dict[str, str]:
    """package:// and model:// meshes that only resolve from the model's own place (a student's
    workspace) become absolute paths, so the working folder finds them too; returns which, so
    saving can write the URIs back."""
    source_dir = model.base_dir
    uris: dict[str, str] = {}

    def fix(geometry):
        if not isinstance(geometry, Mesh) or not geometry.filename.startswith(("package://", "model://")):
            return geometry
        try:
            if resolve_mesh(geometry.filename, folder).exists():
                return geometry
        except MexoneError:
            pass
        try:
            path = str(resolve_mesh(geometry.filename, source_dir).resolve())
        except MexoneError:
            return geometry  # check reports it as a missing mesh
        uris[path] = geometry.filename
        return replace(geometry, filename=path)

    for link in model.links.values():
        link.visuals = [replace(v, geometry=fix(v.geometry)) for v in link.visuals]
        link.collisions = [replace(c, geometry=fix(c.geometry)) for c in link.collisions]
    return uris

