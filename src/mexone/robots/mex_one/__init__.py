"""The built-in Mex-One humanoid: package data (URDF, meshes, controllers, world) and its paths."""

from __future__ import annotations

from importlib.resources import as_file, files
from pathlib import Path

__all__ = ["package_dir", "urdf_path", "controllers_path", "world_path", "walking_path", "END_EFFECTORS"]

# Named frames whole-body motion commands (mexone.motion): link and offset (m) in its frame.
# Hands: the far end of the forearm (its 0.15 m cylinder centred 0.095 m down); feet: the
# centre of the sole (the 0.03 m sole box centred at (0.02, 0, -0.045)); the camera: the
# Kinect's body frame (x forward), whose optical axis the head points with look_at.
END_EFFECTORS: dict[str, tuple[str, tuple[float, float, float]]] = {
    "l_hand": ("l_forearm", (0.0, 0.0, -0.17)),
    "r_hand": ("r_forearm", (0.0, 0.0, -0.17)),
    "l_foot": ("l_foot", (0.02, 0.0, -0.06)),
    "r_foot": ("r_foot", (0.02, 0.0, -0.06)),
    "head": ("head", (0.0, 0.0, 0.0)),
    "camera": ("kinect_link", (0.0, 0.0, 0.0)),
}


def package_dir() -> Path:
    """Folder holding the robot's files (a ROS package named mex_rb, see package.xml)."""
    with as_file(files(__name__)) as path:
        return Path(path)


def urdf_path() -> Path:
    return package_dir() / "urdf" / "mex_rb.urdf"


def controllers_path() -> Path:
    return package_dir() / "config" / "controllers.yaml"


def world_path(name: str = "empty") -> Path:
    """A shipped world: empty (the ground), slope (5 degrees up and down), step (2 cm)."""
    return package_dir() / "worlds" / f"{name}.world"


def walking_path() -> Path:
    """The walking stack's controllers (config/walking.yaml: four chained parts, torque-level)."""
    return package_dir() / "config" / "walking.yaml"
