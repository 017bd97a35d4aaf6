"""mexone: a humanoid-robot simulation lab in Python (Mex-One, MuJoCo, ros_control, ROS names)."""

import os as _os

# MuJoCo picks its OpenGL platform when it is imported. A lab machine often has no display, and
# mexone's GUI runs in the browser, so offscreen EGL is the right default (renders use it).
if not _os.environ.get("MUJOCO_GL") and not _os.environ.get("DISPLAY"):
    _os.environ["MUJOCO_GL"] = "egl"
    _os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

__version__ = "0.1.0"
