"""lint_controllers(model, config): what `mexone check --controllers` says about a controller YAML.

The rules that need both the robot and its controllers live here, above the description layer
(which knows nothing of controllers); they yield the same Findings as the model's lint, with
the YAML's file and line, and the `check` verb prints both lists.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterator

from mexone.control.notes import gazebo_differences
from mexone.control.spec import ControlConfig, ControllerSpec, PidGains
from mexone.description.findings import Finding
from mexone.description.model import RobotModel
from mexone.errors import InputError
from mexone.physics.world import default_world

__all__ = ["lint_controllers", "CONTROLLER_RULES"]

Rule = Callable[[RobotModel, ControlConfig], Iterator[Finding]]


def _element(spec: ControllerSpec) -> str:
    return f'controller "{spec.name}"'


def _finding(config: ControlConfig, code: str, severity: str, element: str, message: str,
             line: int | None) -> Finding:
    return Finding(code, severity, element, message, line,
                   str(config.source) if config.source is not None else None)


def _rule_joints(model: RobotModel, config: ControlConfig) -> Iterator[Finding]:
    for spec in config.controllers.values():
        for joint in spec.joints:
            if joint not in model.joints:
                yield _finding(config, "controller-unknown-joint", "error", _element(spec),
                               f"names joint '{joint}', which the model does not have", spec.line)
                continue
            tx = model.transmission_for(joint)
            if tx is None:
                yield _finding(config, "controller-no-transmission", "error", _element(spec),
                               f"drives joint '{joint}', which has no <transmission>: "
                               "gazebo_ros_control will not load it; add one", spec.line)
            elif spec.interface and not tx.hardware_interface.endswith(spec.interface):
                yield _finding(config, "controller-interface", "warning", _element(spec),
                               f"{spec.type} claims {spec.interface} but the transmission of "
                               f"'{joint}' offers {tx.hardware_interface}", spec.line)


def _rule_shared_joints(model: RobotModel, config: ControlConfig) -> Iterator[Finding]:
    """ros_control refuses to start a second controller on a claimed joint (resource conflict)."""
    owner: dict[str, ControllerSpec] = {}
    for spec in config.controllers.values():
        for joint in spec.joints:
            first = owner.setdefault(joint, spec)
            if first is not spec:
                yield _finding(config, "controller-joint-shared", "error", _element(spec),
                               f"drives joint '{joint}', which controller '{first.name}' (line "
                               f"{first.line}) already drives: ros_control refuses the second "
                               "(resource conflict); keep one", spec.line)


def _gains(spec: ControllerSpec) -> Iterator[tuple[str, PidGains]]:
    if spec.pid is not None:
        yield "pid", spec.pid
    for joint, gains in (spec.gains or {}).items():
        yield f"gains/{joint}", gains


def _pid_findings(config: ControlConfig, element: str, where: str, pid: PidGains,
                  line: int | None) -> Iterator[Finding]:
    if (problem := pid.problem()) is not None:  # the manager refuses the same gains when set live
        yield _finding(config, "pid-gains", "error", element, f"{where}: {problem}", line)


def _rule_pid(model: RobotModel, config: ControlConfig) -> Iterator[Finding]:
    for spec in config.controllers.values():
        for where, pid in _gains(spec):
            yield from _pid_findings(config, _element(spec), where, pid, spec.line)
    for note in gazebo_differences(config):  # what the manager also says when it loads them
        yield _finding(config, note.code, note.severity, _element(note.spec), note.text,
                       note.spec.line)
    for joint, pid in config.pid_gains.items():
        yield from _pid_findings(config, f'pid_gains "{joint}"', "gazebo_ros_control/pid_gains",
                                 pid, None)


def _rule_plugins(model: RobotModel, config: ControlConfig) -> Iterator[Finding]:
    """What a Python controller's own class refuses at configure (a StateFeedback's missing
    design file, a rate not the design's), asked of the class itself: what `mexone sim`
    refuses, said here, at the line of the key it concerns."""
    step = default_world().step
    for spec in config.controllers.values():
        if spec.plugin is None:
            continue
        try:
            check = spec.plugin.cls.check_entry
            robot = {"robot": model} if "robot" in inspect.signature(check).parameters else {}
            check(spec.name, tuple(spec.joints), spec.plugin, step, **robot)
        except InputError as exc:
            hint = f" ({exc.hint})" if exc.hint else ""
            prefix = f"controller '{spec.name}': "
            yield _finding(config, "controller-configure", "error", _element(spec),
                           f"{exc.what.removeprefix(prefix)}{hint}", exc.line or spec.line)


CONTROLLER_RULES: tuple[Rule, ...] = (_rule_joints, _rule_shared_joints, _rule_pid,
                                      _rule_plugins)


def lint_controllers(model: RobotModel, config: ControlConfig) -> list[Finding]:
    return [finding for rule in CONTROLLER_RULES for finding in rule(model, config)]
