"""The one home of every user-set quantity's valid range.

A value typed on the command line, on the page, in the model editor, sent by a ROS service or
read from a model file is checked against the same `Range` here, so "PID p = 1e300" is refused
the same way everywhere, and the docs' table of valid ranges is generated from `RANGES`
(`python -m mexone.ranges` prints it as Markdown).

Bounds say where a value stops being a robot and becomes a typo or a wrong unit; they are
deliberately wide (a 100 t link is allowed) so no real robot is refused.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from mexone.errors import InputError

__all__ = ["Range", "RANGES", "range_of", "number_text", "markdown_table", "docs_page",
           "MASS", "MOMENT", "PRODUCT", "COLOUR", "LENGTH", "SIZE", "POSITION", "JOINT_VALUE", "ANGLE",
           "VELOCITY",
           "EFFORT", "DAMPING", "FRICTION", "MU", "CONTACT_KP", "CONTACT_KD", "GAIN_P", "GAIN_I",
           "GAIN_D", "GAINS", "I_CLAMP", "TIMESTEP", "GRAVITY", "DURATION", "RTF", "IMPULSE",
           "PUSH_DURATION", "PLOT_WINDOW", "STEP_SIZE", "STEPS", "PORT", "MESH_SCALE", "TIMEOUT",
           "FORCE", "SPEED", "SPIN", "CONTROL_PERIOD", "UPDATE_RATE", "UPDATE_TIME", "OVERRUNS",
           "HANG_TIMEOUT", "SAMPLE_PERIOD", "DESIGN_VALUES", "COMPARE_DURATION", "SWITCH_NAMES"]


def number_text(value: float) -> str:
    """A number as a person writes it: no numpy repr, no 300 digits (`1e+300`, `0.52`)."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        return repr(value)
    if math.isnan(number):
        return "NaN"
    if math.isinf(number):
        return "inf" if number > 0 else "-inf"
    return f"{number:.6g}"


@dataclass(frozen=True)
class Range:
    """A quantity's name, unit and closed (or low-open) interval of valid values."""

    name: str
    unit: str
    low: float
    high: float
    low_open: bool = False  # low itself is not allowed (a mass of 0 is no mass)
    integer: bool = False
    why: str = ""  # what the bounds protect against, for the docs

    def describe(self) -> str:
        """'a finite number > 0 and <= 1e+05 (kg)'."""
        kind = "a whole number" if self.integer else "a finite number"
        low = f"{'>' if self.low_open else '>='} {number_text(self.low)}"
        unit = f" {self.unit}" if self.unit else ""
        return f"{kind} {low} and <= {number_text(self.high)}{unit}"

    def contains(self, value: float) -> bool:
        try:
            number = float(value)
        except (TypeError, ValueError):
            return False
        if not math.isfinite(number) or number > self.high:
            return False
        if number < self.low or (self.low_open and number == self.low):
            return False
        return not (self.integer and number != int(number))

    def check(self, value: float, what: str | None = None, **where: Any) -> float:
        """`value` as a float, or an InputError naming `what` (default: the quantity) and the range.
        `where` (file=, line=, hint=) locates it, as every MexoneError."""
        if isinstance(value, bool) or not self.contains(value):
            label = what or self.name
            raise InputError(f"{label} {number_text(value)} must be {self.describe()}", **where)
        return int(value) if self.integer else float(value)

    def check_all(self, values: Iterable[float], what: str | None = None, **where: Any) -> list[float]:
        return [self.check(v, what, **where) for v in values]


MASS = Range("mass", "kg", 1e-9, 1e5, why="a 100 t link is a typo or grams; under a microgram a "
              "unit error (MuJoCo ignores masses under 1e-15)")
MOMENT = Range("moment of inertia", "kg m^2", 0.0, 1e6, why="100 t at 3 m")
PRODUCT = Range("product of inertia", "kg m^2", -1e6, 1e6, why="Ixy, Ixz, Iyz: as large as a moment")
COLOUR = Range("colour component", "", 0.0, 1.0, why="red, green, blue, alpha")
LENGTH = Range("length", "m", -1e3, 1e3, why="offsets within a robot: a kilometre is a unit error")
SIZE = Range("size", "m", 0.0, 1e3, low_open=True, why="a geometry's size, radius or length")
POSITION = Range("position", "m", -1e4, 1e4, why="a place in the world (spawn, move, goal)")
JOINT_VALUE = Range("joint value", "rad or m", -1e4, 1e4, why="a joint position before its limits")
ANGLE = Range("angle", "rad", -6.3, 6.3, why="within +-2 pi (1.5708 is 90 degrees)")
VELOCITY = Range("velocity", "rad/s or m/s", 0.0, 1e4, why="a joint's velocity limit")
EFFORT = Range("effort", "N m or N", 0.0, 1e6, why="a joint's effort limit")
DAMPING = Range("damping", "N m s/rad", 0.0, 1e5, why="a joint's viscous damping")
FRICTION = Range("joint friction", "N m", 0.0, 1e5, why="a joint's dry friction")
MU = Range("friction coefficient", "", 0.0, 1e3, why="Gazebo's mu1, mu2")
CONTACT_KP = Range("contact kp", "N/m", 0.0, 1e12, low_open=True, why="Gazebo's contact stiffness")
CONTACT_KD = Range("contact kd", "N s/m", 0.0, 1e9, why="Gazebo's contact damping")
GAIN_P = Range("p gain", "", 0.0, 1e5, why="control_toolbox PID p")
GAIN_I = Range("i gain", "", 0.0, 1e5, why="control_toolbox PID i")
GAIN_D = Range("d gain", "", 0.0, 1e4, why="control_toolbox PID d")
GAINS = {"p": GAIN_P, "i": GAIN_I, "d": GAIN_D}  # a PID gain's range by its key
I_CLAMP = Range("i_clamp", "", -1e5, 1e5, why="the integral term's clamp")
TIMESTEP = Range("time step", "s", 1e-5, 0.01, why="above 10 ms contacts turn to mush; below 10 us "
                 "nothing moves in a session")
GRAVITY = Range("gravity component", "m/s^2", -1000.0, 1000.0, why="100 g")
DURATION = Range("duration", "s", 1e-3, 1e9, why="of sim time: one 1 ms step to 'until Ctrl-C'")
RTF = Range("real-time factor", "", 0.0, 100.0, why="0 runs as fast as possible")
IMPULSE = Range("push impulse", "N s", 0.0, 1000.0)
PUSH_DURATION = Range("push duration", "s", 1e-3, 5.0)
PLOT_WINDOW = Range("plot window", "s", 0.1, 60.0, why="sim seconds a plot pane shows")
STEP_SIZE = Range("step response size", "rad", -3.0, 3.0, why="the GUI's step response")
STEPS = Range("steps", "", 1, 100_000, integer=True, why="Step N on the page")
PORT = Range("port", "", 0, 65535, integer=True, why="0 picks a free port")
MESH_SCALE = Range("mesh scale", "", 0.0, 1e3, low_open=True, why="an STL in mm has scale 0.001")
TIMEOUT = Range("timeout", "s", 0.0, 1e6, why="a ROS service's timeout (0: none)")
FORCE = Range("force", "N or N m", -1e6, 1e6, why="a pushed force or torque, an applied joint "
              "effort (signed)")
# the divergence watchdog's limits (physics/divergence.py): a body set moving faster is a divergence
SPEED = Range("speed", "m/s", -50.0, 50.0, why="a set linear velocity (component and length)")
SPIN = Range("spin", "rad/s", -500.0, 500.0, why="a set angular velocity (component and length)")
CONTROL_PERIOD = Range("control period", "s", 1e-5, 10.0, why="the controllers' period (at least "
                       "the physics step): 0.1 Hz is no controller")
UPDATE_RATE = Range("update rate", "Hz", 0.1, 1e5, why="a Python controller's update_rate (at most "
                    "one update per physics step)")
UPDATE_TIME = Range("max update time", "s", 1e-6, 10.0, why="wall time a Python controller's update "
                    "may take before it counts as an overrun")
OVERRUNS = Range("max overruns", "", 1, 1_000_000, integer=True, why="consecutive overrunning "
                 "updates that stop a Python controller")
HANG_TIMEOUT = Range("hang timeout", "s", 0.05, 3600.0, why="wall time after which an update that "
                     "has not returned is interrupted")
SAMPLE_PERIOD = Range("sampling period", "s", 1e-5, 0.1, why="a linear model's (linearize's period, a "
                      "design file's dt): each of its steps is a finite difference of the "
                      "physics; past 0.1 s it takes minutes and describes no robot")
DESIGN_VALUES = Range("values in a design array", "", 0, 1_000_000, integer=True,
                      why="one array of a design file (K: joints x states, at most 1000 x 1000): "
                      "a file declaring more is broken or hostile, refused before it is read")
COMPARE_DURATION = Range("comparison duration", "s", 1e-3, 600.0, why="design.compare runs the lab "
                         "for it, in the caller's thread: ten minutes of sim time is a mistake")
SWITCH_NAMES = Range("controllers named in one switch request", "", 0, 1000, integer=True,
                     why="a ROS switch_controller's activate + deactivate lists: a robot has tens")
REPLAY_FPS = Range("replay frames per second", "Hz", 1.0, 120.0,
                   why="a notebook's inline replay: each frame is a pose per body in the page")
REPLAY_SECONDS = Range("seconds simulated in one call", "s", 0.0, 3600.0,
                       why="notebook.simulate; the replay holds every frame in memory")

RANGES: tuple[Range, ...] = tuple(v for v in globals().values() if isinstance(v, Range))


def range_of(name: str) -> Range:
    """The range named `name` ('mass', 'p gain'), or an error listing the names."""
    for r in RANGES:
        if r.name == name:
            return r
    raise KeyError(f"no range '{name}'; the ranges are: {', '.join(r.name for r in RANGES)}")


def markdown_table() -> str:
    """The docs' table of valid ranges, generated here so it cannot drift from the checks."""
    rows = ["| quantity | valid values | why |", "|---|---|---|"]
    rows += [f"| {r.name} | {r.describe().removeprefix('a finite number ')} | {r.why} |"
             for r in RANGES]
    return "\n".join(rows)


def docs_page() -> str:
    """docs/ranges.md, written when the docs are built (docs/_ext/mexone_docs.py); never kept in git."""
    return ("# Valid ranges\n\n"
            "Every number a user sets (on the command line, on the page, in the model editor, in a ROS\n"
            "service call, in a model or world file) is checked against its quantity's range here, and\n"
            "refused in one line outside it. Generated from `mexone/ranges.py` (their one home) when\n"
            "these pages are built; `python -m mexone.ranges` prints the same.\n\n"
            + markdown_table() + "\n")


if __name__ == "__main__":
    print(docs_page(), end="")
