"""find_package(name, near): the folder of a ROS package, for ``$(find pkg)`` and ``package://``.

ROS finds packages by crawling ROS_PACKAGE_PATH for ``package.xml`` files; a student's model
usually sits inside its own catkin package, and mexone ships its robots as packages. So, in
this order: ROS_PACKAGE_PATH (crawled like rospack: a folder with a package.xml is a package
and is not searched further, CATKIN_IGNORE stops a crawl), then the folders above the model
file (the one whose package.xml names the package, one named like it, or a sibling package
in the same workspace), then mexone's own robots.
"""

from __future__ import annotations

import os
import re
from functools import lru_cache
from importlib.resources import as_file, files
from pathlib import Path

from mexone.errors import ModelError

__all__ = ["find_package", "require_package", "package_name"]

_PKG_NAME = re.compile(rb"<name>\s*([^<\s]+)\s*</name>")
_CRAWL_LIMIT = 20_000  # folders per ROS_PACKAGE_PATH entry: ROS_PACKAGE_PATH=/ must not hang us
_CRAWL_DEPTH = 8


def package_name(folder: Path) -> str | None:
    """The <name> in folder/package.xml, or None if it is not a package."""
    manifest = folder / "package.xml"
    try:
        if not manifest.is_file() or manifest.stat().st_size > 1_000_000:
            return None
        found = _PKG_NAME.search(manifest.read_bytes())
    except OSError:
        return None
    return found.group(1).decode() if found else None


@lru_cache(maxsize=16)
def _crawl(root: str) -> dict[str, Path]:
    """name -> folder for every package under root, breadth first (the shallower one wins)."""
    found: dict[str, Path] = {}
    queue, visited = [(Path(root), 0)], 0
    while queue and visited < _CRAWL_LIMIT:
        folder, depth = queue.pop(0)
        visited += 1
        if (name := package_name(folder)) is not None:
            found.setdefault(name, folder)
            continue
        if depth >= _CRAWL_DEPTH or (folder / "CATKIN_IGNORE").exists():
            continue
        try:
            subdirs = sorted(e.path for e in os.scandir(folder)
                             if e.is_dir(follow_symlinks=False) and not e.name.startswith("."))
        except OSError:
            continue
        queue.extend((Path(p), depth + 1) for p in subdirs)
    return found


def _own_robots() -> list[Path]:
    with as_file(files("mexone.robots")) as robots:
        return sorted(p for p in Path(robots).iterdir() if (p / "package.xml").is_file())


def find_package(name: str, near: Path | None = None) -> Path | None:
    """The package's folder, or None. near: the folder of the file that names it."""
    for entry in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep):
        if entry and (folder := _crawl(os.path.abspath(entry)).get(name)) is not None:
            return folder
    if near is not None:
        near = near.resolve()
        for folder in (near, *near.parents):
            if package_name(folder) == name or folder.name == name:
                return folder
            if (folder / name).is_dir():
                return folder / name
    for folder in _own_robots():
        if package_name(folder) == name or folder.name == name:
            return folder
    return None


def require_package(name: str, near: Path | None, what: str) -> Path:
    """find_package, or a ModelError saying where we looked."""
    folder = find_package(name, near)
    if folder is None:
        ros_path = os.environ.get("ROS_PACKAGE_PATH")
        searched = f"ROS_PACKAGE_PATH ({ros_path})" if ros_path else "ROS_PACKAGE_PATH (not set)"
        above = ", the folders above the file" if near is not None else ""
        raise ModelError(f"{what}: cannot find package '{name}' in {searched}{above} or mexone's "
                         "robots", hint="add the folder that holds the package to ROS_PACKAGE_PATH")
    return folder
