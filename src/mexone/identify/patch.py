"""Write identified values back into the student's own files, changing nothing else.

The URDF is edited as text, located through lxml's parse (which element, on which line): every
other byte -- comments, attribute order, indentation, the values nobody identified -- stays. An XML
comment before each changed joint or link says what changed from what, and from which bags.
Joint damping and friction go where the simulator reads them from (a `<gazebo reference>`
override wins over `<dynamics>`, as in Gazebo), and into `<dynamics>` too where it states them, so
the two never disagree (`mexone check` reports a value given twice); armature is
`<dynamics armature>`. A xacro or SDF
cannot be patched faithfully as text (its values may be expressions): the expanded model is
written as a plain URDF instead, and the report says so. Controller gains are patched in the
controllers YAML the same way (`p:` and `d:` values, with a `#` comment).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from lxml import etree

from mexone import yamlio
from mexone.description.model import Inertial, Pose, RobotModel
from mexone.description.urdf import write_urdf

__all__ = ["Change", "patch_urdf", "patched_model_text", "patch_controllers", "value_text"]


@dataclass(frozen=True)
class Change:
    kind: str  # damping, frictionloss, armature, mass, com, gains
    target: str  # joint or link
    component: str  # "", x/y/z, p/d
    old: float
    new: float
    halfwidth: float | None = None

    def describe(self) -> str:
        label = {"frictionloss": "friction"}.get(self.kind, self.kind)
        if self.component:
            label = f"{label}.{self.component}" if self.kind == "com" else self.component
        pm = f" (+-{value_text(self.halfwidth)})" if self.halfwidth is not None \
            and np.isfinite(self.halfwidth) else ""
        return f"{label} {value_text(self.old)} -> {value_text(self.new)}{pm}"


def value_text(value: float) -> str:
    """Five significant digits: identified values are not known better than that."""
    value = float(value)
    return "0" if abs(value) < 1e-15 else format(value, ".5g")


@dataclass
class _Edit:
    start: int
    end: int
    text: str


def _line_offsets(text: str) -> list[int]:
    offsets, at = [0], 0
    for line in text.splitlines(keepends=True):
        at += len(line)
        offsets.append(at)
    return offsets


class _Source:
    """The file's text and its parse, with the text span of each element's start tag."""

    def __init__(self, text: str):
        self.text = text
        parser = etree.XMLParser(remove_comments=False, resolve_entities=False, no_network=True)
        self.root = etree.fromstring(text.encode(), parser)
        self.lines = _line_offsets(text)

    def start_tag(self, el: etree._Element) -> tuple[int, int]:
        """[start, end) of `<tag ...>` or `<tag .../>` (end just after '>')."""
        at = self.text.index("<" + el.tag, self.lines[el.sourceline - 1])
        quote = None
        for i in range(at, len(self.text)):
            c = self.text[i]
            if quote:
                quote = None if c == quote else quote
            elif c in "\"'":
                quote = c
            elif c == ">":
                return at, i + 1
        raise ValueError(f"unterminated <{el.tag}>")

    def indent(self, el: etree._Element) -> str:
        start = self.lines[el.sourceline - 1]
        line = self.text[start:self.start_tag(el)[0]]
        return line[:len(line) - len(line.lstrip())]

    def set_attr(self, el: etree._Element, name: str, value: str) -> _Edit:
        start, end = self.start_tag(el)
        tag = self.text[start:end]
        found = re.search(rf"(\s{re.escape(name)}\s*=\s*)([\"'])(.*?)\2", tag)
        if found:
            return _Edit(start + found.start(3), start + found.end(3), value)
        close = end - (2 if tag.endswith("/>") else 1)
        return _Edit(close, close, f' {name}="{value}"')

    def set_text(self, el: etree._Element, value: str) -> _Edit:
        _, end = self.start_tag(el)
        close = self.text.index("</" + el.tag, end)
        return _Edit(end, close, value)

    def insert_child(self, parent: etree._Element, xml: str) -> _Edit:
        _, end = self.start_tag(parent)
        indent = self.indent(parent) + "  "
        return _Edit(end, end, f"\n{indent}{xml}")

    def comment_before(self, el: etree._Element, text: str) -> _Edit:
        start = self.start_tag(el)[0]
        return _Edit(start, start, f"<!-- {text} -->\n{self.indent(el)}")


def _apply(text: str, edits: list[_Edit]) -> str:
    for edit in sorted(edits, key=lambda e: (e.start, e.end), reverse=True):
        text = text[:edit.start] + edit.text + text[edit.end:]
    return text


def patch_urdf(text: str, changes: list[Change], origin: str) -> str:
    """The URDF text with the changed values (and a comment per joint or link) written in."""
    src = _Source(text)
    root = src.root
    edits: list[_Edit] = []
    by_target: dict[tuple[str, str], list[Change]] = {}
    for c in changes:
        by_target.setdefault(("link" if c.kind in ("mass", "com") else "joint", c.target),
                             []).append(c)
    for (what, name), group in by_target.items():
        el = root.find(f"{what}[@name='{name}']")
        if el is None:
            raise ValueError(f"no {what} '{name}' in the URDF")
        if what == "joint":
            edits += _joint_edits(src, el, name, group)
        else:
            edits += _link_edits(src, el, group)
        summary = ", ".join(c.describe() for c in group)
        edits.append(src.comment_before(el, f"mexone identify ({origin}): {summary}"))
    return _apply(text, edits)


def _joint_edits(src: _Source, joint: etree._Element, name: str,
                 changes: list[Change]) -> list[_Edit]:
    edits = []
    dynamics = joint.find("dynamics")
    gazebo = src.root.find(f"gazebo[@reference='{name}']/axis/dynamics")
    missing = {}
    for c in changes:
        attr = {"damping": "damping", "frictionloss": "friction", "armature": "armature"}[c.kind]
        value = value_text(c.new)
        if attr != "armature" and gazebo is not None and gazebo.find(attr) is not None:
            edits.append(src.set_text(gazebo.find(attr), value))
            if dynamics is not None and dynamics.get(attr) is not None:  # the two stay equal:
                edits.append(src.set_attr(dynamics, attr, value))  # check reports them otherwise
        elif dynamics is not None:
            edits.append(src.set_attr(dynamics, attr, value))
        else:
            missing[attr] = value
    if missing:
        attrs = " ".join(f'{k}="{v}"' for k, v in missing.items())
        edits.append(src.insert_child(joint, f"<dynamics {attrs}/>"))
    return edits


def _link_edits(src: _Source, link: etree._Element, changes: list[Change]) -> list[_Edit]:
    inertial = link.find("inertial")
    if inertial is None:
        raise ValueError(f"link '{link.get('name')}' has no <inertial>")
    edits = []
    com = {c.component: c.new for c in changes if c.kind == "com"}
    for c in changes:
        if c.kind == "mass":
            edits.append(src.set_attr(inertial.find("mass"), "value", value_text(c.new)))
    if com:
        origin = inertial.find("origin")
        old = [float(v) for v in (origin.get("xyz", "0 0 0") if origin is not None
                                  else "0 0 0").split()]
        xyz = " ".join(value_text(com.get(a, old[i])) for i, a in enumerate("xyz"))
        if origin is not None:
            edits.append(src.set_attr(origin, "xyz", xyz))
        else:
            edits.append(src.insert_child(inertial, f'<origin xyz="{xyz}" rpy="0 0 0"/>'))
    return edits


def patched_model_text(robot: RobotModel, changes: list[Change], origin: str) -> str:
    """For a xacro or SDF: the expanded model with the changes, as a plain URDF."""
    joints, gazebo = dict(robot.joints), dict(robot.gazebo_joints)
    links = dict(robot.links)
    for c in changes:
        if c.kind in ("damping", "frictionloss", "armature"):
            field = {"damping": "damping", "frictionloss": "friction", "armature": "armature"}[c.kind]
            joints[c.target] = replace(joints[c.target], dynamics=replace(
                robot.joint_dynamics(c.target) if c.target in gazebo else joints[c.target].dynamics,
                **{field: c.new}))
            gazebo.pop(c.target, None)
        elif c.kind in ("mass", "com"):
            inertial = links[c.target].inertial or Inertial(0.0, (0.0,) * 6, Pose())
            if c.kind == "mass":
                inertial = replace(inertial, mass=c.new)
            else:
                xyz = list(inertial.origin.xyz)
                xyz["xyz".index(c.component)] = c.new
                inertial = replace(inertial, origin=replace(inertial.origin, xyz=tuple(xyz)))
            links[c.target] = replace(links[c.target], inertial=inertial)
    model = replace(robot, joints=joints, links=links, gazebo_joints=gazebo)
    summary = "; ".join(f"{c.target} {c.describe()}" for c in changes)
    return write_urdf(model, comment=f" mexone identify ({origin}), from {robot.source}: "
                                     f"{summary} ")


def patch_controllers(text: str, path: Path | None, changes: list[Change], joint_controller:
                      dict[str, str], origin: str) -> tuple[str, list[str]]:
    """The controllers YAML with identified p and d written in; returns notes for gains that
    could not be written (a pid shared by several joints)."""
    root = yamlio.compose(text, path)
    edits, notes = [], []
    lines = _line_offsets(text)
    comments: dict[int, list[str]] = {}
    for c in changes:
        controller = joint_controller.get(c.target)
        node = _pid_node(root, controller, c.target) if controller else None
        if node is None:
            notes.append(f"gains of {c.target}: no pid block of its own in the YAML; not written")
            continue
        value = next((v for k, v in node.value if k.value == c.component), None)
        if value is None:
            notes.append(f"gains of {c.target}: no '{c.component}:' to change; not written")
            continue
        edits.append(_Edit(value.start_mark.index, value.end_mark.index, value_text(c.new)))
        line = value.start_mark.line
        comments.setdefault(line, []).append(f"{c.component} {value_text(c.old)} -> "
                                             f"{value_text(c.new)}")
    for line, parts in comments.items():
        end = lines[line + 1] if line + 1 < len(lines) else len(text)
        stop = end - (1 if text[end - 1:end] == "\n" else 0)
        edits.append(_Edit(stop, stop, f"  # mexone identify ({origin}): {', '.join(parts)}"))
    return _apply(text, edits), notes


def _pid_node(root, controller: str, joint: str):
    """The mapping holding p/d for `joint` in `controller`: its gains/<joint>, or its pid when
    the controller drives this joint alone."""
    def child(node, key):
        if node is None or not hasattr(node, "value") or not isinstance(node.value, list):
            return None
        return next((v for k, v in node.value if getattr(k, "value", None) == key), None)

    body = child(root, controller)
    if body is None:  # under a namespace key
        for _, space in (root.value if isinstance(root.value, list) else []):
            body = body or child(space, controller)
    if body is None:
        return None
    specific = child(child(body, "gains"), joint)
    if specific is not None:
        return specific
    joints = child(body, "joints")
    if joints is not None and len(getattr(joints, "value", [])) > 1:
        return None
    return child(body, "pid")
