"""The built-in Mex-One humanoid: package data (URDF, meshes, controllers, world) and its paths."""

from __future__ import annotations

from importlib.resources import as_file, files
from pathlib import Path

__all__ = ["package_dir", "urdf_path", "controllers_path", "world_path", "NAMESPACE"]

NAMESPACE = "mex_rb"


def package_dir() -> Path:
    """Folder holding the robot's files (a ROS package named mex_rb, see package.xml)."""
    with as_file(files(__name__)) as path:
        return Path(path)


def urdf_path() -> Path:
    return package_dir() / "urdf" / "mex_rb.urdf"


def controllers_path() -> Path:
    return package_dir() / "config" / "controllers.yaml"


def world_path() -> Path:
    return package_dir() / "worlds" / "empty.world"
