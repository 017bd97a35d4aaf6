"""World: what an SDF .world file says about the environment (Gazebo's defaults where silent).

Reads the parts a robot lab needs: gravity, the physics step and solver iterations, a ground
plane with its friction, and the sun. ``<include>`` of Gazebo's stock ``ground_plane`` and
``sun`` models (the seed's Listing 3.14) are understood without Gazebo's model database.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mexone.description.sdf import sdf_version
from mexone.description.xmlio import XmlReader
from mexone.errors import UnsupportedError
from mexone.ranges import GRAVITY, RTF, TIMESTEP, number_text

if TYPE_CHECKING:
    import numpy as np
    from lxml import etree

__all__ = ["World", "Ground", "Block", "read_world", "default_world"]


@dataclass(frozen=True)
class Ground:
    mu1: float = 100.0  # Gazebo's stock ground_plane
    mu2: float = 50.0
    z: float = 0.0


@dataclass(frozen=True)
class Block:
    """A static box in the world (terrain: a slope, a step), from a `<static>` SDF model whose
    link collides as one `<box>`: its size (m), pose (model pose composed with the link's:
    x y z, roll pitch yaw) and friction."""

    name: str
    size: tuple[float, ...]  # x y z
    xyz: tuple[float, ...] = (0.0, 0.0, 0.0)
    rpy: tuple[float, ...] = (0.0, 0.0, 0.0)
    mu: float = 1.0


@dataclass(frozen=True)
class World:
    name: str = "default"
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    step: float = 0.001  # s, Gazebo's max_step_size
    iterations: int = 50  # ODE quick-step iterations; the MuJoCo solver cap
    real_time_factor: float = 1.0
    ground: Ground | None = Ground()
    sun_direction: tuple[float, float, float] = (-0.5, 0.1, -0.9)
    source: Path | None = None
    blocks: tuple[Block, ...] = ()


def default_world() -> World:
    """The built-in empty world (ground plane, sun, gravity, 1 ms step)."""
    return World()  # Gazebo's empty.world; the shipped worlds/empty.world says the same (tested)


def read_world(path: Path | str) -> World:
    """A Gazebo `.world` file (SDF): physics step, gravity, ground friction, the sun, static
    boxes; every mistake one line at its line."""
    path = Path(path)
    xml = XmlReader(path)
    root = xml.root
    world = root.find("world") if root.tag == "sdf" else None
    if world is None:
        raise xml.fail(root, "holds no <world>", "a world file is <sdf><world>...</world></sdf>")
    sdf_version(xml, root)
    values: dict[str, Any] = {"name": world.get("name", "default"), "source": path, "ground": None}
    if (g := world.find("gravity")) is not None:
        values["gravity"] = xml.numbers(g, g.text or "", 3, "value")
        if not all(GRAVITY.contains(v) for v in values["gravity"]):
            raise xml.fail(g, f"({', '.join(number_text(v) for v in values['gravity'])}) m/s^2: each "
                              f"component must be {GRAVITY.describe()}", "Earth's is 0 0 -9.8")
    physics = world.find("physics")
    if physics is not None:
        values["step"] = xml.text_number(physics, "max_step_size", 0.001)
        if not TIMESTEP.contains(values["step"]):  # ranges.TIMESTEP says why
            step_el = physics.find("max_step_size")
            raise xml.fail(step_el, f"{number_text(values['step'])} s must be {TIMESTEP.describe()}",
                           "Gazebo's default is 0.001")
        values["real_time_factor"] = xml.text_number(physics, "real_time_factor", 1.0)
        if not RTF.contains(values["real_time_factor"]):
            raise xml.fail(physics.find("real_time_factor"), f"{number_text(values['real_time_factor'])} "
                           f"must be {RTF.describe()} (0: as fast as possible)")
        iters = physics.find("ode/solver/iters")
        if iters is not None:
            count = xml.number(iters, iters.text or "", "value")
            if count < 1 or count != int(count) or count > 10_000:
                raise xml.fail(iters, f"{count:g} is not a whole number of iterations from 1 to 10000",
                               "Gazebo's default is 50")
            values["iterations"] = int(count)
    for include in world.iterfind("include"):
        uri = (include.findtext("uri") or "").strip()
        if uri == "model://ground_plane":
            values["ground"] = Ground()
        elif uri != "model://sun":
            raise UnsupportedError(f"<include> of '{uri}' needs Gazebo's model database",
                                   file=path, line=include.sourceline,
                                   hint="write the model into the world file; only ground_plane "
                                        "and sun are built in")
    blocks = []
    for model in world.iterfind("model"):
        plane = model.find("link/collision/geometry/plane")
        box = model.find("link/collision/geometry/box/size")
        if plane is None and box is not None and (model.findtext("static") or "").strip() in ("1", "true"):
            blocks.append(_block(xml, model, box))
            continue
        if plane is None:
            raise UnsupportedError(f"world model '{model.get('name')}' is neither a ground plane nor "
                                   "a static box", file=path, line=model.sourceline,
                                   hint="spawn robots with 'mexone sim MODEL'; worlds hold the ground "
                                        "and static boxes (terrain)")
        friction = model.find("link/collision/surface/friction/ode")
        mu1 = xml.text_number(friction, "mu", 1.0) if friction is not None else 1.0
        mu2 = xml.text_number(friction, "mu2", mu1) if friction is not None else mu1
        values["ground"] = Ground(mu1, mu2)
    if (sun := world.find("light/direction")) is not None:
        values["sun_direction"] = xml.numbers(sun, sun.text or "", 3, "value")
    values["blocks"] = tuple(blocks)
    return World(**values)


def _pose(xml: XmlReader, el: etree._Element | None) -> tuple[tuple[float, ...], tuple[float, ...]]:
    pose = el.find("pose") if el is not None else None
    if pose is None:
        return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    values = xml.numbers(pose, pose.text or "", 6, "pose")
    return values[:3], values[3:]


def _block(xml: XmlReader, model: etree._Element, size_el: etree._Element) -> Block:
    """A static model's box: its model and link poses composed (as SDF frames: model, then link)."""
    import numpy as np

    from mexone.description.transforms import rpy_to_matrix

    size = xml.numbers(size_el, size_el.text or "", 3, "size")
    if not all(0 < v <= 1000 for v in size):
        raise xml.fail(size_el, f"box size {' '.join(number_text(v) for v in size)} m: each must be "
                                "> 0 and <= 1000", "a box is three positive lengths, x y z")
    (mx, mr), (lx, lr) = _pose(xml, model), _pose(xml, model.find("link"))
    outer, inner = rpy_to_matrix(mr), rpy_to_matrix(lr)
    rotation = outer @ inner
    xyz = tuple(float(v) for v in np.asarray(mx) + outer @ np.asarray(lx))
    rpy = _matrix_to_rpy(rotation)
    friction = model.find("link/collision/surface/friction/ode")
    mu = xml.text_number(friction, "mu", 1.0) if friction is not None else 1.0
    return Block(model.get("name", "block"), size, xyz, rpy, mu)


def _matrix_to_rpy(r: np.ndarray) -> tuple[float, float, float]:
    import math

    pitch = math.asin(max(-1.0, min(1.0, -r[2, 0])))
    return math.atan2(r[2, 1], r[2, 2]), pitch, math.atan2(r[1, 0], r[0, 0])
