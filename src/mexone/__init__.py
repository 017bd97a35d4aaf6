"""mexone: a humanoid-robot simulation lab in Python (Mex-One, MuJoCo, ros_control, ROS names).

Importing mexone changes nothing in the environment: offscreen rendering picks its OpenGL
platform where it starts (mexone.record.video).
"""

__version__ = "0.1.0"

__all__ = ["Controller", "Param", "__version__"]


def __getattr__(name: str):
    """`mexone.Controller` (mexone.control.PythonController) and `mexone.Param`, imported when
    first used, so `import mexone` stays light."""
    if name in ("Controller", "Param"):
        from mexone.control import student

        return student.PythonController if name == "Controller" else student.Param
    raise AttributeError(f"module 'mexone' has no attribute {name!r}")
