"""The robot's dynamics from the simulated MuJoCo model: mass matrix, bias and gravity forces,
inverse dynamics, Jacobians, centre of mass, centroidal momentum (see `queries` for the frames
and the floating base's coordinates)."""

from mexone.dynamics.queries import Dynamics

__all__ = ["Dynamics"]
