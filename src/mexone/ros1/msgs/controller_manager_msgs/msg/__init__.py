from ._ControllerState import *
from ._ControllerStatistics import *
from ._ControllersStatistics import *
from ._HardwareInterfaceResources import *
