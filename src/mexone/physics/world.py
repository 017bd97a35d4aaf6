"""World: what an SDF .world file says about the environment (Gazebo's defaults where silent).

Reads the parts a robot lab needs: gravity, the physics step and solver iterations, a ground
plane with its friction, and the sun. ``<include>`` of Gazebo's stock ``ground_plane`` and
``sun`` models (the seed's Listing 3.14) are understood without Gazebo's model database.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mexone.description.sdf import sdf_version
from mexone.description.xmlio import XmlReader
from mexone.errors import UnsupportedError
from mexone.ranges import GRAVITY, RTF, TIMESTEP, number_text

__all__ = ["World", "Ground", "read_world", "default_world"]


@dataclass(frozen=True)
class Ground:
    mu1: float = 100.0  # Gazebo's stock ground_plane
    mu2: float = 50.0
    z: float = 0.0


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


def default_world() -> World:
    """The built-in empty world (ground plane, sun, gravity, 1 ms step)."""
    return World()  # Gazebo's empty.world; the shipped worlds/empty.world says the same (tested)


def read_world(path: Path | str) -> World:
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
    for model in world.iterfind("model"):
        plane = model.find("link/collision/geometry/plane")
        if plane is None:
            raise UnsupportedError(f"world model '{model.get('name')}' is not a ground plane",
                                   file=path, line=model.sourceline,
                                   hint="spawn robots with 'mexone sim MODEL'; worlds hold the ground")
        friction = model.find("link/collision/surface/friction/ode")
        mu1 = xml.text_number(friction, "mu", 1.0) if friction is not None else 1.0
        mu2 = xml.text_number(friction, "mu2", mu1) if friction is not None else mu1
        values["ground"] = Ground(mu1, mu2)
    if (sun := world.find("light/direction")) is not None:
        values["sun_direction"] = xml.numbers(sun, sun.text or "", 3, "value")
    return World(**values)
