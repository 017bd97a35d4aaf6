"""Control design on the simulated robot: linear models (`linearize`) at operating points
(`operating_point`), as python-control systems; designs deployed into the loop (`deploy`);
checked against the robot (`compare`, `measure_frequency_response`) and why they differ
(`mismatch`, `friction_model`); observers in the loop (`kalman`, `luenberger`, `lqg`); the
margins of any controller (`linearize_loop`, `loop_margins`, `simulate_onset`), its saturation
and region of attraction, and all of it in one report (`certify`). A core layer above `control`
(it reads the hardware's actuator layout) and `dynamics`; it imports no front end."""

from mexone.design.certify import Certificate, certify
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
from mexone.design.friction import FrictionModel, friction_model
from mexone.design.linear import (
    INPUT_KINDS,
    SUPPORTS,
    Linearization,
    OperatingPoint,
    linearize,
    operating_point,
    state_deviation,
)
from mexone.design.loop import LoopModel, linearize_loop
from mexone.design.margins import LoopMargins, Margins, loop_margins, plot_margins
from mexone.design.mismatch import Mismatch, mismatch, plot_mismatch
from mexone.design.observers import (
    EstimateRun,
    Estimator,
    Lqg,
    LqgDesign,
    Observer,
    compare_estimate,
    kalman,
    load_estimator,
    lqg,
    luenberger,
    plot_estimate,
    rows_of,
    save_estimator,
)
from mexone.design.onset import Onset, simulate_onset
from mexone.design.region import Region, plot_region, region_of_attraction
from mexone.design.saturation import Saturation, saturation

__all__ = ["linearize", "operating_point", "OperatingPoint", "Linearization", "state_deviation",
           "INPUT_KINDS", "SUPPORTS", "deploy", "StateFeedback", "LinearController", "save_design",
           "load_design", "lqr", "METHODS", "compare", "Comparison", "plot_comparison",
           "measure_frequency_response", "FrequencyResponse", "plot_frequency_response",
           "closed_loop", "loop_gain",
           "mismatch", "Mismatch", "plot_mismatch", "friction_model", "FrictionModel",
           "kalman", "luenberger", "lqg", "Estimator", "LqgDesign", "Observer", "Lqg",
           "compare_estimate", "EstimateRun", "plot_estimate", "save_estimator", "load_estimator",
           "rows_of", "linearize_loop", "LoopModel", "loop_margins", "Margins", "LoopMargins",
           "plot_margins", "simulate_onset", "Onset", "saturation", "Saturation",
           "region_of_attraction", "Region", "plot_region", "certify", "Certificate"]
