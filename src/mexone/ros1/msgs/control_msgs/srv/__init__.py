from ._QueryCalibrationState import *
from ._QueryTrajectoryState import *
