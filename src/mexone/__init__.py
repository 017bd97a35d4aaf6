"""mexone: a humanoid-robot simulation lab in Python (Mex-One, MuJoCo, ros_control, ROS names).

Importing mexone changes nothing in the environment: offscreen rendering picks its OpenGL
platform where it starts (mexone.record.video).
"""

__version__ = "0.1.0"

__all__ = ["Controller", "Param", "StateFeedback", "LinearController", "__version__"]


def __getattr__(name: str):
    """`mexone.Controller` (mexone.control.PythonController), `mexone.Param` and the design
    controllers `mexone.StateFeedback`, `mexone.LinearController` (mexone.design.deploy),
    imported when first used, so `import mexone` stays light."""
    if name in ("Controller", "Param"):
        from mexone.control import student

        return student.PythonController if name == "Controller" else student.Param
    if name in ("StateFeedback", "LinearController"):  # a YAML's `type: mexone/StateFeedback`
        import importlib

        return getattr(importlib.import_module("mexone.design.deploy"), name)
    raise AttributeError(f"module 'mexone' has no attribute {name!r}")
