"""mexone: a humanoid-robot simulation lab in Python (Mex-One, MuJoCo, ros_control, ROS names).

Importing mexone changes nothing in the environment: offscreen rendering picks its OpenGL
platform where it starts (mexone.record.video).
"""

__version__ = "0.1.0"  #: mexone's version (the wheel's)

__all__ = ["Controller", "Param", "StateFeedback", "LinearController", "API", "__version__"]

#: The public API, by who imports it: a student (a lab, controllers, experiments, notebooks), a
#: teacher (exercises, sweeps) and a plug-in author (a controller, sensor type, GUI panel or
#: exercise in a package of their own, found through entry points). A public module's `__all__`
#: is its public API, each name documented; every other module of mexone, and every name not in
#: such an `__all__`, is internal and may change without notice (tests/test_public_api.py).
API: dict[str, tuple[str, ...]] = {
    "student": ("mexone", "mexone.lab", "mexone.physics", "mexone.control", "mexone.dynamics",
                "mexone.design", "mexone.sensors", "mexone.motion", "mexone.rospy",
                "mexone.msgs", "mexone.record.bag", "mexone.record.reader", "mexone.notebook",
                "mexone.errors"),
    "teacher": ("mexone.exercises", "mexone.sweep"),
    "plug-in author": ("mexone.control", "mexone.sensors", "mexone.gui.panels",
                       "mexone.exercises"),
}


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
