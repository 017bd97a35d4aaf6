"""ros_control controller YAML (the seed's Listing 3.17) -> ControlConfig, with line numbers.

Accepts the file as ``rosparam load`` sees it: controllers under a namespace key
(``mex_rb: {joint_state_controller: ..., l_knee_position_controller: ...}``) or at the top
level, plus ``gazebo_ros_control/pid_gains/<joint>`` as gazebo_ros_control reads it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from mexone import yamlio
from mexone.control.controllers import CONTROLLER_TYPES
from mexone.control.resolve import (
    RESERVED_KEYS,
    Plugin,
    check_settings,
    resolve_class,
    validate_params,
)
from mexone.control.spec import ControlConfig, ControllerSpec, PidGains
from mexone.control.student import declared_lengths
from mexone.errors import InputError
from mexone.inputs import read_input_text

__all__ = [
    "PidGains",
    "ControllerSpec",
    "ControlConfig",
    "CONTROLLER_TYPES",
    "load_control_config",
    "parse_control_config",
    "check_chains",
    "chain_order",
]


def load_control_config(path: Path | str, classes: dict[str, type] | None = None,
                        in_process: bool = False) -> ControlConfig:
    """A ros_control controller YAML (what `rosparam load` and the controller_manager read), every
    mistake one line at the file's line. A student's class its `type:` names runs in a process
    of its own (control/worker.py); `classes` maps `type:` names to classes handed over in
    Python (a notebook's own), which run in this process. `in_process`: every class the YAML
    names is imported here, as a notebook's would be -- for an analysis that reaches into the
    controller's object (`mexone certify`, design.linearize_loop) on the user's own machine;
    never for grading, whose controllers stay in their workers."""
    path = Path(path)
    text = read_input_text(path)
    config = parse_control_config(text, path, classes)
    if not in_process:
        return config
    imported = dict(classes or {})
    for spec in config.controllers.values():
        plugin = spec.plugin
        if plugin is not None and plugin.isolated and plugin.type not in imported:
            imported[plugin.type] = resolve_class(plugin.type, plugin.yaml_dir, [])[0]
    return parse_control_config(text, path, imported)


class _Reader:
    def __init__(self, path: Path | None) -> None:
        self.path = path

    def error(self, node: yaml.Node, what: str, hint: str | None = None) -> InputError:
        return InputError(what, file=self.path or "<yaml>", line=node.start_mark.line + 1, hint=hint)

    def mapping(self, node: yaml.Node, what: str) -> list[tuple[str, yaml.Node, yaml.Node]]:
        if not isinstance(node, yaml.MappingNode):
            raise self.error(node, f"{what} must be a mapping of names to settings")
        return [(str(k.value), k, v) for k, v in node.value]

    def value(self, node: yaml.Node) -> Any:
        try:
            return yamlio.construct(node)
        except InputError as exc:
            raise exc.located(self.path or "<yaml>") from None

    def boolean(self, node: yaml.Node, what: str) -> bool:
        """true/false (and YAML 1.1's yes/no/on/off, as rosparam reads them); never a string:
        bool('no') is True."""
        value = self.value(node)
        if not isinstance(value, bool):
            style = getattr(node, "style", None)  # a scalar's quoting
            quoted = " (quoted, so a string)" if isinstance(value, str) and style in ("'", '"') else ""
            raise self.error(node, f"{what}: '{node.value}'{quoted} is not a boolean",
                             "write true or false, without quotes")
        return value

    def number(self, node: yaml.Node, what: str) -> float:
        value = self.value(node)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(node, f"{what}: '{node.value}' is not a number")
        if not math.isfinite(value):
            raise self.error(node, f"{what}: '{node.value}' is not finite", "use a finite number")
        return float(value)


def parse_control_config(text: str, path: Path | None = None,
                         classes: dict[str, type] | None = None) -> ControlConfig:
    """A controller YAML's text (`path` names it in messages): see load_control_config."""
    reader = _Reader(path)
    root = yamlio.compose(text, path)
    if root is None:
        raise InputError("empty controller file", file=path or "<yaml>",
                         hint="expected the ros_control schema of the seed's Listing 3.17")
    entries = reader.mapping(root, "the file")
    if any(_is_controller(v) for _, _, v in entries):
        namespace, body = None, root
    else:
        spaces = [(name, key, v) for name, key, v in entries if isinstance(v, yaml.MappingNode)]
        if len(spaces) != 1:
            raise reader.error(root, f"expected one robot namespace holding the controllers, "
                                     f"found {len(spaces)}", "e.g. 'mex_rb:' with controllers below")
        namespace, _, body = spaces[0]
    from mexone.control.worker import reading

    with reading():  # the controllers' processes a refused file started end with the refusal
        _prestart(reader, body, classes)
        parameters = yamlio.construct(root)
        config = ControlConfig(namespace=namespace, source=path,
                               parameters=parameters if isinstance(parameters, dict) else {})
        for name, key, node in reader.mapping(body, f"namespace '{namespace}'"):
            if name == "gazebo_ros_control":
                _pid_gains(reader, node, config)
            elif _is_controller(node):
                config.controllers[name] = _controller(reader, name, key, node, classes)
            else:
                raise reader.error(key, f"'{name}' is not a controller: it has no 'type'",
                                   "every controller needs type: <package>/<Controller>")
        check_chains(config)
    return config


def _prestart(reader: _Reader, body: yaml.Node, classes: dict[str, type] | None) -> None:
    """Start the processes of the file's student controllers side by side (control/worker.py),
    before each is described in turn."""
    from mexone.control.worker import prestart

    if not isinstance(body, yaml.MappingNode):
        return
    count = 0
    for _, node in body.value:
        if _is_controller(node):
            ctype = next((v.value for k, v in node.value if k.value == "type"), None)
            if isinstance(ctype, str) and ctype not in CONTROLLER_TYPES and \
                    ctype not in (classes or {}) and not ctype.startswith(("mexone/", "mexone.")):
                count += 1
    if count > 1:
        prestart(count, (reader.path.resolve().parent,) if reader.path is not None else ())


def _is_controller(node: yaml.Node) -> bool:
    return isinstance(node, yaml.MappingNode) and any(k.value == "type" for k, _ in node.value)


def _controller(reader: _Reader, name: str, key: yaml.Node, node: yaml.Node,
                classes: dict[str, type] | None = None) -> ControllerSpec:
    fields = {k: (knode, v) for k, knode, v in reader.mapping(node, f"controller '{name}'")}
    type_node = fields["type"][1]
    ctype = str(reader.value(type_node))
    if ctype not in CONTROLLER_TYPES:
        return _plugin(reader, name, key, ctype, type_node, fields, classes)
    cls, single = CONTROLLER_TYPES[ctype].cls, CONTROLLER_TYPES[ctype].single_joint
    joints: tuple[str, ...] = ()
    if cls.drives_joints:
        if single:
            if "joint" not in fields:
                raise reader.error(key, f"controller '{name}' ({ctype}) has no 'joint'")
            joints = (str(reader.value(fields["joint"][1])),)
        else:
            if "joints" not in fields:
                raise reader.error(key, f"controller '{name}' ({ctype}) has no 'joints' list")
            value = reader.value(fields["joints"][1])
            if not isinstance(value, list) or not value:
                raise reader.error(fields["joints"][1], f"controller '{name}': 'joints' must be a "
                                                        "non-empty list of joint names")
            joints = tuple(str(j) for j in value)
    pid = _pid(reader, name, fields["pid"][1]) if "pid" in fields else None
    rate = None
    if "publish_rate" in fields:
        rate = reader.number(fields["publish_rate"][1], f"controller '{name}': publish_rate")
        if rate <= 0:
            raise reader.error(fields["publish_rate"][1], f"controller '{name}': publish_rate must be > 0")
    gains = None
    if "gains" in fields:
        gains = {joint: _pid(reader, f"{name}/gains/{joint}", node)
                 for joint, _, node in reader.mapping(fields["gains"][1], f"'{name}' gains")}
    ideal = False
    if "ideal_servo" in fields:
        ideal = reader.boolean(fields["ideal_servo"][1], f"'{name}' ideal_servo")
        if not cls.tracks_position:
            raise reader.error(fields["ideal_servo"][1], f"'{name}': ideal_servo is for position "
                                                         "controllers")
    return ControllerSpec(name, ctype, joints, pid, rate, key.start_mark.line + 1, gains, ideal,
                          reader.path)


def _pid(reader: _Reader, owner: str, node: yaml.Node) -> PidGains:
    fields = {k: (knode, v) for k, knode, v in reader.mapping(node, f"'{owner}' pid")}
    if "p" not in fields:
        raise reader.error(node, f"'{owner}' pid has no 'p' gain", "add p: <gain>")
    values = {}
    for key in ("p", "i", "d", "i_clamp_min", "i_clamp_max", "i_clamp"):
        if key in fields:
            values[key] = reader.number(fields[key][1], f"'{owner}' pid {key}")
    if "i_clamp" in values:  # control_toolbox's symmetric shorthand
        clamp = abs(values.pop("i_clamp"))
        values.setdefault("i_clamp_min", -clamp)
        values.setdefault("i_clamp_max", clamp)
    antiwindup = reader.boolean(fields["antiwindup"][1], f"'{owner}' pid antiwindup") \
        if "antiwindup" in fields else False
    return PidGains(antiwindup=antiwindup, **values)


def _pid_gains(reader: _Reader, node: yaml.Node, config: ControlConfig) -> None:
    fields = {k: v for k, _, v in reader.mapping(node, "gazebo_ros_control")}
    if "pid_gains" in fields:
        for joint, _, gains in reader.mapping(fields["pid_gains"], "pid_gains"):
            config.pid_gains[joint] = _pid(reader, f"pid_gains/{joint}", gains)


def _plugin(reader: _Reader, name: str, key: yaml.Node, ctype: str, type_node: yaml.Node,
            fields: dict[str, tuple[yaml.Node, yaml.Node]],
            classes: dict[str, type] | None = None) -> ControllerSpec:
    """A student's Python controller (control/resolve.py): its class found as pluginlib finds
    C++ types (and described by its own process, control/worker.py), its declared parameters
    and settings checked with this file's lines."""
    from mexone.control.worker import resolve

    where = reader.path or "<yaml>"
    yaml_dir = reader.path.resolve().parent if reader.path is not None else Path.cwd()
    try:
        cls, origin = resolve(ctype, yaml_dir, list(CONTROLLER_TYPES), classes=classes)
    except InputError as exc:
        exc.what = f"controller '{name}': {exc.what}"
        raise exc.located(where, type_node.start_mark.line + 1) from None
    if "joints" in fields:
        value = reader.value(fields["joints"][1])
        if not isinstance(value, list) or not all(isinstance(j, str) for j in value):
            raise reader.error(fields["joints"][1], f"controller '{name}': 'joints' must be a "
                                                    "list of joint names ([] for none: a chained "
                                                    "controller that only exports)")
        joints = tuple(value)
    elif "joint" in fields:
        joints = (str(reader.value(fields["joint"][1])),)
    else:
        raise reader.error(key, f"controller '{name}' ({ctype}) has no 'joints' list",
                           "add joints: [joint, ...]")
    if len(set(joints)) != len(joints):
        raise reader.error((fields.get("joints") or fields["joint"])[1],
                           f"controller '{name}' names a joint twice")
    lines = {k: (reader.value(v), v.start_mark.line + 1) for k, (_, v) in fields.items()}
    settings = check_settings(lines, name, where)
    raw = {k: lines[k] for k in fields if k not in RESERVED_KEYS}
    try:
        params = validate_params(cls, raw, name, where)
    except InputError as exc:  # a class that cannot run at all: at its type's line
        raise exc.located(where, type_node.start_mark.line + 1) from None
    pid = _pid(reader, name, fields["pid"][1]) if "pid" in fields else None
    gains = None
    if "gains" in fields:
        gains = {joint: _pid(reader, f"{name}/gains/{joint}", node)
                 for joint, _, node in reader.mapping(fields["gains"][1], f"'{name}' gains")}
    inputs = _inputs(reader, name, cls, key, fields.get("inputs"))
    plugin = Plugin(ctype, cls, origin, yaml_dir, raw, params, source=reader.path,
                    line=key.start_mark.line + 1, lines={k: n for k, (_, n) in lines.items()},
                    inputs=inputs, handed=classes is not None and ctype in classes, **settings)
    return ControllerSpec(name, ctype, joints, pid, None, key.start_mark.line + 1, gains, False,
                          reader.path, plugin)


def _inputs(reader: _Reader, name: str, cls: type, key: yaml.Node,
            field: tuple[yaml.Node, yaml.Node] | None) -> dict[str, str]:
    """A chained controller's `inputs:` (declared input -> "controller/export"): every input the
    class declares bound, nothing else. Whether the exporter exists is `check_chains`'s."""
    declared = declared_lengths(cls, "inputs")
    bound: dict[str, str] = {}
    if field is not None:
        for local, knode, vnode in reader.mapping(field[1], f"controller '{name}': inputs"):
            if local not in declared:
                raise reader.error(knode, f"controller '{name}': inputs names '{local}', which "
                                          f"{cls.__name__} does not declare",
                                   "its inputs: " + (", ".join(declared) or "none"))
            source = reader.value(vnode)
            if not isinstance(source, str) or source.count("/") != 1 or "" in source.split("/"):
                raise reader.error(vnode, f"controller '{name}': input '{local}' must name "
                                          "'<controller>/<export>'", "e.g. estimator/tilt")
            bound[local] = source
    optional = set(getattr(cls, "optional_inputs", ()))
    missing = [k for k in declared if k not in bound and k not in optional]
    if missing:
        raise reader.error(field[0] if field is not None else key,
                           f"controller '{name}': input '{missing[0]}' is not bound",
                           f"add inputs: {{{missing[0]}: <controller>/<export>}}")
    return bound


def check_chains(config: ControlConfig) -> None:
    """Chained controllers: every bound input names a Python controller of the configuration
    that exports it, with the declared length, and no controller reads itself through a chain
    (the manager updates exporters before readers). One InputError at the reader's line."""
    specs = config.controllers
    for name, spec in specs.items():
        plugin = spec.plugin
        if plugin is None or not plugin.inputs:
            continue
        wanted = declared_lengths(plugin.cls, "inputs")
        line = plugin.lines.get("inputs", spec.line)
        where = spec.source or "<controllers>"
        for local, source in plugin.inputs.items():
            owner, export = source.split("/")
            other = specs.get(owner)
            if other is None or other.plugin is None:
                python = [n for n, s in specs.items() if s.plugin is not None and n != name]
                raise InputError(f"controller '{name}': input '{local}' reads '{source}', but "
                                 f"'{owner}' is not a Python controller of this file",
                                 file=where, line=line,
                                 hint="Python controllers: " + (", ".join(python) or "none"))
            exports = declared_lengths(other.plugin.cls, "exports")
            if export not in exports:
                raise InputError(f"controller '{name}': input '{local}' reads '{source}', but "
                                 f"'{owner}' ({other.plugin.cls.__name__}) does not export "
                                 f"'{export}'", file=where, line=line,
                                 hint="its exports: " + (", ".join(exports) or "none"))
            if exports[export] != wanted[local]:
                raise InputError(f"controller '{name}': input '{local}' is {wanted[local]} long "
                                 f"but '{source}' is {exports[export]} long", file=where,
                                 line=line)
    order = chain_order(specs)
    if order is None:
        cycle = _cycle(specs)
        spec = specs[cycle[0]]
        raise InputError("chained controllers read each other in a circle: "
                         + " -> ".join([*cycle, cycle[0]]), file=spec.source or "<controllers>",
                         line=spec.plugin.lines.get("inputs", spec.line),
                         hint="an exporter cannot read its own readers' exports")


def _readers_of(specs: Mapping[str, Any]) -> dict[str, set[str]]:
    """controller -> the controllers whose exports it reads."""
    out: dict[str, set[str]] = {}
    for name, spec in specs.items():
        plugin = getattr(spec, "plugin", None)
        if plugin is not None:
            out[name] = {source.split("/")[0] for source in plugin.inputs.values()} & set(specs)
    return out


def chain_order(specs: Mapping[str, Any]) -> list[str] | None:
    """The controllers' names (any mapping name -> object with `.plugin`) with every exporter
    before its readers, otherwise in their own order; None if they read each other in a
    circle."""
    order, left = _kahn(specs)
    return None if left else order


def _kahn(specs: Mapping[str, Any]) -> tuple[list[str], list[str]]:
    """Kahn's algorithm, stable: (the ordered names, those left in or behind a circle)."""
    needs = _readers_of(specs)
    done: list[str] = []
    left = list(specs)
    while left:
        ready = [n for n in left if needs.get(n, set()) <= set(done)]
        if not ready:
            break
        done += ready
        left = [n for n in left if n not in ready]
    return done, left


def _cycle(specs: Mapping[str, Any]) -> list[str]:
    """One circle of chained controllers (for the message): among those Kahn could not place,
    each reads another of them, so following the reads comes back around."""
    needs = _readers_of(specs)
    _, left = _kahn(specs)
    path = [left[0]]
    while True:
        nxt = min(needs[path[-1]] & set(left))
        if nxt in path:
            return path[path.index(nxt):]
        path.append(nxt)
