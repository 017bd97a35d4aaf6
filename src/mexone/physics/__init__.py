"""Physics layer: compile a RobotModel and a world into MuJoCo and simulate it as Gazebo would."""

from mexone.physics.compile import GAZEBO_MAPPING, Compiled, CompileOptions, Spawn, compile_model
from mexone.physics.divergence import DivergenceError
from mexone.physics.simulation import RtfMeter, Simulation
from mexone.physics.world import Ground, World, default_world, read_world

__all__ = [
    "GAZEBO_MAPPING",
    "CompileOptions",
    "Compiled",
    "Spawn",
    "compile_model",
    "Simulation",
    "RtfMeter",
    "DivergenceError",
    "Ground",
    "World",
    "default_world",
    "read_world",
]
