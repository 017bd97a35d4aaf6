"""Controller gains and physics settings as ROS 2 parameters of the simulator's node (what
`ros2 param set /mexone ...` and rcl_interfaces' SetParameters change):

- `<controller>.gains.<joint>.{p,i,d,i_clamp_min,i_clamp_max}` (double) and `.antiwindup`
  (bool): ros2_control's PID parameter names, under the controller's name;
- `physics.time_step` (s), `physics.gravity` (double[3], m/s^2), `physics.real_time_factor`
  (0: as fast as possible) and `physics.solver_iterations` (integer).

A value of the wrong type, out of its range (`mexone.ranges`) or not finite is refused: the set
fails with the reason, a warning goes to /rosout, and nothing changes. An accepted set is applied
in the simulation thread before the call returns.
"""

from __future__ import annotations

import dataclasses
import logging
import math

from mexone.errors import InputError, printable
from mexone.ranges import GAIN_D, GAIN_I, GAIN_P, GRAVITY, I_CLAMP, RTF, TIMESTEP, number_text

__all__ = ["Parameters", "GAIN_FIELDS", "PHYSICS"]

log = logging.getLogger("mexone.ros2")

GAIN_FIELDS = {"p": GAIN_P, "i": GAIN_I, "d": GAIN_D, "i_clamp_min": I_CLAMP,
               "i_clamp_max": I_CLAMP, "antiwindup": None}
PHYSICS = ("time_step", "gravity", "real_time_factor", "solver_iterations")


class Parameters:
    """Declares the parameters on the bridge's node and applies accepted sets."""

    def __init__(self, bridge) -> None:
        from rcl_interfaces.msg import ParameterDescriptor

        self.bridge, self.lab = bridge, bridge.lab
        node = bridge.node
        any_type = ParameterDescriptor(dynamic_typing=True)  # our callback checks the types
        for name, value in self._current().items():  # attach() runs in the simulation thread
            node.declare_parameter(name, value, any_type)
        node.add_on_set_parameters_callback(self._on_set)
        from rclpy.parameter_service import ParameterService

        self.service = ParameterService(node)  # now: every set meets _on_set

    def _current(self) -> dict[str, object]:
        sim = self.lab.sim
        values: dict[str, object] = {
            "physics.time_step": float(sim.timestep),
            "physics.gravity": [float(v) for v in sim.gravity],
            "physics.real_time_factor": float(sim.target_rtf or 0.0),
            "physics.solver_iterations": int(sim.model.opt.iterations)}
        manager = self.lab.manager
        for name, ctrl in (manager.controllers.items() if manager is not None else ()):
            if ctrl.gains is None:
                continue
            for joint, gains in zip(ctrl.joints, ctrl.gains, strict=True):
                for key in GAIN_FIELDS:
                    value = getattr(gains, key)
                    values[f"{name}.gains.{joint}.{key}"] = bool(value) if key == "antiwindup" \
                        else float(value)
        return values

    def _on_set(self, parameters):
        from rcl_interfaces.msg import SetParametersResult

        try:
            for parameter in parameters:  # rclpy lets an empty name through as a success
                if not parameter.name or not parameter.name.isprintable():
                    raise InputError(f"parameter name {printable(parameter.name, 80)!r} is not "
                                     "a parameter's name", hint="`ros2 param list` names them")
            changes = [self._check(p.name, p.value) for p in parameters
                       if p.name.startswith("physics.") or ".gains." in p.name]
            if changes:
                self.bridge.call(lambda: self._apply(changes))
        except Exception as exc:  # noqa: BLE001 - a refused set is a warning, never a crash
            text = printable(exc.one_line() if isinstance(exc, InputError) else f"{exc}")
            log.warning("parameter refused: %s", text)
            return SetParametersResult(successful=False, reason=text)
        return SetParametersResult(successful=True)

    def _check(self, name: str, value) -> tuple[str, object]:
        """(name, checked value), or InputError naming the parameter and what to send."""
        if name.startswith("physics."):
            key = name.split(".", 1)[1]
            if key == "time_step":
                return name, TIMESTEP.check(_number(name, value), name)
            if key == "real_time_factor":
                return name, RTF.check(_number(name, value), name)
            if key == "solver_iterations":
                if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 1000:
                    raise InputError(f"{name} must be an integer from 1 to 1000, not {value!r}")
                return name, value
            if key == "gravity":
                if not isinstance(value, list | tuple) or len(value) != 3:
                    raise InputError(f"{name} must be 3 doubles (x y z in m/s^2), not {value!r}")
                return name, [GRAVITY.check(_number(name, v), name) for v in value]
            raise InputError(f"{name} is not a physics parameter", hint=f"one of {PHYSICS}")
        controller, _, rest = name.partition(".gains.")
        joint, _, key = rest.rpartition(".")
        manager = self.lab.manager
        ctrl = manager.controllers.get(controller) if manager is not None else None
        if ctrl is None or ctrl.gains is None or joint not in ctrl.joints or key not in GAIN_FIELDS:
            raise InputError(f"{name}: no such gain", hint="`ros2 param list` names them")
        if key == "antiwindup":
            if not isinstance(value, bool):
                raise InputError(f"{name} must be a bool, not {value!r}")
            return name, value
        return name, GAIN_FIELDS[key].check(_number(name, value), name)

    def _apply(self, changes: list[tuple[str, object]]) -> None:  # simulation thread
        sim, manager = self.lab.sim, self.lab.manager
        for name, value in changes:
            if name == "physics.time_step":
                sim.set_timestep(value)
            elif name == "physics.gravity":
                sim.set_gravity(value)
            elif name == "physics.real_time_factor":
                sim.target_rtf = value or None
                if not sim.paused:
                    sim.resume()  # pacing restarts from now, at the new rate
            elif name == "physics.solver_iterations":
                sim.model.opt.iterations = value
            else:
                controller, _, rest = name.partition(".gains.")
                joint, _, key = rest.rpartition(".")
                ctrl = manager.controllers[controller]
                gains = list(ctrl.gains)
                index = ctrl.joints.index(joint)
                gains[index] = dataclasses.replace(gains[index], **{key: value})
                manager.set_gains(controller, gains)
            sim.note_input(f"ROS 2 parameter {name} = {_show(value)}")


def _number(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{name} must be a double, not {value!r}")
    if not math.isfinite(value):
        raise InputError(f"{name} must be finite, not {value}")
    return float(value)


def _show(value) -> str:
    if isinstance(value, list):
        return " ".join(number_text(v) for v in value)
    return number_text(value) if isinstance(value, float) else str(value)
