"""ROS 2 message packages PyPI has no wheel for, built on this machine from their official
definitions with the rosidl tools that are on PyPI (the `ros2-build` extra):
today tf2_msgs (TFMessage, for /tf), control_msgs (JointControllerState, the
controllers' state topics) and controller_manager_msgs (ros2_control's controller manager
services, mexone.ros2.controller_manager).

`share/<package>/` holds the official .msg files with a package.xml and a CMakeLists.txt;
`build()` runs CMake's `rosidl_generate_interfaces` against the wheels' prefix (the venv) and
installs the result there, as a colcon build of that package would: C and C++ type support
libraries into `<prefix>/lib` (which the wheels' loader already searches), the Python package
into site-packages. It needs CMake and a C/C++ compiler, and takes 20 s a package
(controller_manager_msgs, 17 interfaces: 1-2 min).

    python -m mexone.ros2.interfaces        # build what is missing, into this Python's prefix
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path

from mexone.errors import MexoneError, install_extra

__all__ = ["SHARE", "PACKAGES", "BUILD_INSTALL", "build", "missing"]

SHARE = Path(__file__).resolve().parent / "share"
PACKAGES = ("tf2_msgs", "control_msgs", "controller_manager_msgs")
BUILD_INSTALL = f"{install_extra('ros2-build')} (and apt-get install cmake g++)"
_PYTHON_TOOLS = ("ament_package", "catkin_pkg", "rosidl_adapter", "rosidl_generator_py")


def missing() -> list[str]:
    """The packages of PACKAGES this Python cannot import yet."""
    return [p for p in PACKAGES if importlib.util.find_spec(p) is None]


def _check_tools(prefix: Path) -> None:
    for tool in ("cmake", "make", "cc", "c++"):
        if shutil.which(tool) is None:
            raise MexoneError(f"building ROS 2 messages needs '{tool}', which is not on PATH",
                              hint=f"install the build tools: {BUILD_INSTALL}")
    for module in _PYTHON_TOOLS:
        if importlib.util.find_spec(module) is None:
            raise MexoneError(f"building ROS 2 messages needs the Python module {module}",
                              hint=BUILD_INSTALL)
    if not (prefix / "share" / "rosidl_default_generators").is_dir():
        raise MexoneError(f"no rosidl_default_generators under {prefix}/share",
                          hint=BUILD_INSTALL)


def build(prefix: Path | None = None, packages: tuple[str, ...] = PACKAGES, log=print) -> None:
    """Build `packages` from share/ and install them into `prefix` (default: this Python's)."""
    prefix = Path(prefix or sys.prefix).resolve()
    _check_tools(prefix)
    env = dict(os.environ)
    env["AMENT_PREFIX_PATH"] = os.pathsep.join(
        [str(prefix), *[p for p in env.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]])
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    python_include = sysconfig.get_paths()["include"]
    for package in packages:
        source = SHARE / package
        with tempfile.TemporaryDirectory(prefix=f"mexone-{package}-") as tmp:
            steps = (
                ["cmake", "-S", str(source), "-B", tmp, f"-DCMAKE_PREFIX_PATH={prefix}",
                 f"-DCMAKE_INSTALL_PREFIX={prefix}", f"-DPython3_EXECUTABLE={sys.executable}",
                 f"-DPython3_INCLUDE_DIR={python_include}", "-DBUILD_TESTING=OFF",
                 "-DCMAKE_BUILD_TYPE=Release"],
                ["cmake", "--build", tmp, "--parallel", str(min(4, os.cpu_count() or 1))],
                ["cmake", "--install", tmp],
            )
            for step in steps:
                log(f"mexone: {package}: {' '.join(step[:2])} ...")
                done = subprocess.run(step, env=env, capture_output=True, text=True)
                if done.returncode != 0:
                    tail = [line for line in (done.stderr or done.stdout).splitlines()
                            if line.strip()][-1:] or ["(no output)"]
                    raise MexoneError(f"building {package} failed at '{' '.join(step[:2])}': "
                                      f"{tail[0].strip()}", hint=BUILD_INSTALL)
        log(f"mexone: {package} installed into {prefix}")


def main() -> int:
    """Build the packages this Python cannot import yet (all of them with --all)."""
    todo = PACKAGES if "--all" in sys.argv[1:] else tuple(missing())
    if not todo:
        print(f"mexone: {', '.join(PACKAGES)} already importable (--all rebuilds them)")
        return 0
    try:
        build(packages=todo)
    except MexoneError as exc:
        print(f"mexone: {exc.one_line()}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
