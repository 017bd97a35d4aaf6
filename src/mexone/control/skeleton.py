"""`mexone controllers new NAME`: a commented skeleton Python controller and the YAML that runs it.

The controller holds Mex-One's left arm by PD about where it started (with gravity compensation
once `self.dynamics` is there); the YAML is Mex-One's shipped controllers with the left arm's
three position controllers replaced by it, so the robot stands while the student's code runs.
"""

from __future__ import annotations

import keyword
import re

import yaml

from mexone.errors import InputError
from mexone.robots import mex_one

__all__ = ["skeleton_files", "class_name", "ARM_JOINTS"]

ARM_JOINTS = ("l_shoulder_pitch", "l_shoulder_roll", "l_elbow")

_CONTROLLER = '''\
"""{cls}: my own controller for Mex-One's left arm (see docs/controllers.md).

Runs in the simulation thread at `update_rate` (controllers.yaml), inside the controller
manager's read -> update -> write. Edit, save, press Reload on the page: no restart needed.
"""

import numpy as np

from mexone.control import Param, PythonController


class {cls}(PythonController):
    """PD about the pose the arm had when the controller started: tau = kp (q0 - q) - kd dq."""

    # what update() returns, per joint: "effort" (N m), "position" (rad) or "velocity" (rad/s)
    command_interface = "effort"

    # declared parameters: typed by their default, checked against [low, high]; controllers.yaml
    # sets them (with its file:line on a bad value) and the page changes them live
    kp = Param(20.0, low=0.0, high=1e4, doc="stiffness", unit="N m/rad")
    kd = Param(1.0, low=0.0, high=1e3, doc="damping", unit="N m s/rad")
    gravity_compensation = Param(False, doc="add g(q) from self.dynamics")

    def configure(self) -> None:
        """Once, after the parameters were checked. Already set: self.name, self.joints,
        self.dofs (the joints' indices into nv-long vectors), self.params, self.log."""
        self.q0 = np.zeros(len(self.joints))

    def activate(self, state) -> None:
        """The controller takes over its joints: hold where they are now."""
        self.q0 = state.q.copy()
        self.log.info("holding %s at %s rad", ", ".join(self.joints),
                      ", ".join(f"{{q:.3f}}" for q in self.q0))

    def update(self, state, t, dt):
        """Every period: state.q, state.dq, state.effort (the claimed joints), state.all_q,
        state.all_dq, state.base, state.sensors["imu"]. Return one effort per joint (N m);
        the manager clamps it to the joint's effort limit."""
        tau = self.kp * (self.q0 - state.q) - self.kd * state.dq
        if self.gravity_compensation:
            tau = tau + self.dynamics.gravity()[self.dofs]
        return tau

    def deactivate(self) -> None:
        """The controller lets go of its joints (stopped, switched or faulted)."""
'''

_HEADER = '''\
# Mex-One's controllers with the left arm driven by {cls} ({stem}.py, next to this file).
# Run it:   mexone sim --controllers {yaml_name}
#           mexone sim --headless --duration 2 --controllers {yaml_name} --json
# Check it: mexone check --controllers {yaml_name}
mex_rb:
  {name}:
    type: {stem}/{cls}        # <file stem next to this YAML>/<class>, like pluginlib
    joints: [{joints}]
    update_rate: 1000         # Hz (default: every physics step)
    kp: 20.0                  # the class's declared Params; a bad value names this line
    kd: 1.0
    # on_fault: hold          # after an exception, NaN or overrun: hold (default) or damp
    # max_update_time: 0.001  # s of wall time an update may take (default: its period)
    # max_overruns: 10        # consecutive overruns that stop it
    # hang_timeout: 2.0       # s after which an update that never returns is interrupted
'''


def class_name(name: str) -> tuple[str, str]:
    """(file stem, class name) for NAME: my_pd -> (my_pd, MyPd); MyPd -> (my_pd, MyPd)."""
    if not name.isidentifier() or keyword.iskeyword(name):
        raise InputError(f"'{name}' is not a Python name",
                         hint="use letters, digits and _, e.g. my_controller")
    stem = re.sub(r"(?<=[a-z0-9])([A-Z])", r"_\1", name).lower()
    cls = "".join(part[:1].upper() + part[1:] for part in name.split("_") if part)
    return stem, cls


def skeleton_files(name: str, yaml_name: str = "controllers.yaml") -> dict[str, str]:
    """{file name: text}: `<stem>.py` and `controllers.yaml`, runnable as written."""
    stem, cls = class_name(name)
    shipped = yaml.safe_load(mex_one.controllers_path().read_text())
    namespace, controllers = next(iter(shipped.items()))
    kept = {k: v for k, v in controllers.items()
            if not (isinstance(v, dict) and ({v.get("joint")} | set(v.get("joints") or []))
                    & set(ARM_JOINTS))}
    header = _HEADER.format(cls=cls, stem=stem, name=f"{stem}_controller", yaml_name=yaml_name,
                            joints=", ".join(ARM_JOINTS))
    rest = yaml.safe_dump({namespace: kept}, sort_keys=False).split("\n", 1)[1]
    text = header + "  # Mex-One's shipped controllers for the other joints\n" + rest
    return {f"{stem}.py": _CONTROLLER.format(cls=cls), yaml_name: text}
