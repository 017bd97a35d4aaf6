"""Control design on the simulated robot: linear models (`linearize`) at operating points
(`operating_point`), as python-control systems; designs deployed into the loop (`deploy`). A
core layer above `control` (it reads the hardware's actuator layout)
and `dynamics`; it imports no front end."""

from mexone.design.check import (
    Comparison,
    FrequencyResponse,
    closed_loop,
    compare,
    loop_gain,
    measure_frequency_response,
    plot_comparison,
    plot_frequency_response,
)
from mexone.design.deploy import (
    METHODS,
    LinearController,
    StateFeedback,
    deploy,
    load_design,
    lqr,
    save_design,
)
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
           "INPUT_KINDS", "SUPPORTS", "deploy", "StateFeedback", "LinearController", "save_design",
           "load_design", "lqr", "METHODS", "compare", "Comparison", "plot_comparison",
           "measure_frequency_response", "FrequencyResponse", "plot_frequency_response",
           "closed_loop", "loop_gain"]
