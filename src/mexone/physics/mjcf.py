"""MJCF export from the same compile path the simulator uses, so the XML is the simulated robot."""

from __future__ import annotations

from mexone.description.model import RobotModel
from mexone.physics.compile import CompileOptions, Spawn, compile_model
from mexone.physics.world import World

__all__ = ["write_mjcf"]


def write_mjcf(robot: RobotModel, world: World | None = None, spawn: Spawn = Spawn(),
               options: CompileOptions = CompileOptions()) -> str:
    """MuJoCo XML of robot + world. Meshes are referenced by absolute path; the actuators are
    effort motors (gain 1), one per transmission, limited to the URDF effort."""
    return compile_model(robot, world, spawn, options).spec.to_xml()
