from ._ListControllerTypes import *
from ._ListControllers import *
from ._LoadController import *
from ._ReloadControllerLibraries import *
from ._SwitchController import *
from ._UnloadController import *
