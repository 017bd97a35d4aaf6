"""Control design on the simulated robot: linear models (`linearize`) at operating points
(`operating_point`), as python-control systems. A core layer above `control` (it reads the
hardware's actuator layout) and `dynamics`; it imports no front end."""

from mexone.design.linear import (
    INPUT_KINDS,
    SUPPORTS,
    Linearization,
    OperatingPoint,
    linearize,
    operating_point,
    state_deviation,
)

__all__ = ["linearize", "operating_point", "OperatingPoint", "Linearization", "state_deviation",
           "INPUT_KINDS", "SUPPORTS"]
