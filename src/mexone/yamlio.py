"""Safe YAML for a user's files: compose to line-numbered nodes, then construct values.

PyYAML's safe loader still lets a file hurt or fool us, so on top of it:

- aliases may expand to at most ``MAX_EXPANDED_NODES`` values (an alias bomb is 9^9 values
  from 600 bytes) and may not refer to themselves;
- flow nesting deeper than ``MAX_DEPTH`` is refused before parsing (libyaml's composer
  recurses in C and crashes the process at ~100k levels);
- a key given twice in one mapping is an error naming both lines (YAML keeps the second
  silently);
- every float a person writes is a float: YAML 1.1 reads ``1.0e9`` and ``1e9`` as strings;
  we add the YAML 1.2 forms (booleans stay YAML 1.1's, as ``rosparam`` reads them).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import yaml

from mexone.errors import InputError

__all__ = ["compose", "construct", "load", "MAX_EXPANDED_NODES", "MAX_DEPTH"]

MAX_EXPANDED_NODES = 1_000_000  # a controller file has hundreds
MAX_DEPTH = 1000  # a controller file nests about 5 deep

_BaseLoader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml: 5x faster when present


class _Loader(_BaseLoader):  # type: ignore[misc, valid-type]
    """The safe loader plus YAML 1.2 floats without a dot or with an unsigned exponent."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"""^(?:[-+]?[0-9][0-9_]*\.[0-9_]*[eE][-+]?[0-9]+
                   |[-+]?\.[0-9][0-9_]*(?:[eE][-+]?[0-9]+)?
                   |[-+]?[0-9][0-9_]*[eE][-+]?[0-9]+)$""", re.X),
    list("-+0123456789."),
)


def _label(path: Path | str | None) -> str:
    return str(path) if path is not None else "<yaml>"


def _flow_depth(text: str) -> tuple[int, int]:
    """(deepest bracket nesting, its offset): brackets in strings count too, which only errs
    on the safe side."""
    data = np.frombuffer(text.encode("utf-8", "replace"), dtype=np.uint8)
    step = np.isin(data, (ord("["), ord("{"))).astype(np.int32) - np.isin(data, (ord("]"), ord("}")))
    if not step.size:
        return 0, 0
    depth = np.cumsum(step)
    at = int(np.argmax(depth))
    return int(depth[at]), at


def compose(text: str, path: Path | str | None = None) -> yaml.Node | None:
    """The document's node tree (None if empty), vetted as the module docstring says."""
    label = _label(path)
    depth, at = _flow_depth(text)
    if depth > MAX_DEPTH:
        line = text.count("\n", 0, at) + 1
        raise InputError(f"YAML nests {depth} levels deep (the limit is {MAX_DEPTH})", file=label,
                         line=line, hint="a controller file nests a few levels; is it the right file?")
    try:
        root = yaml.compose(text, Loader=_Loader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise InputError(f"malformed YAML: {problem}", file=label,
                         line=mark.line + 1 if mark else None, hint="fix the YAML syntax") from None
    if root is not None:
        _vet(root, label)
    return root


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [n for pair in node.value for n in pair]
    return []


def _vet(root: yaml.Node, label: str) -> None:
    """Duplicate keys, self-referring aliases and the expanded size, in one iterative pass
    (aliases are shared nodes: each is sized once, counted every time it is used)."""
    size: dict[int, int] = {}
    on_path: set[int] = set()
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, done = stack.pop()
        key = id(node)
        if done:
            on_path.discard(key)
            size[key] = 1 + sum(size[id(c)] for c in _children(node))
            if size[key] > MAX_EXPANDED_NODES:
                raise InputError(f"YAML aliases expand to over {MAX_EXPANDED_NODES:,} values",
                                 file=label, line=node.start_mark.line + 1,
                                 hint="an alias bomb? write the values out or use fewer aliases")
            continue
        if key in size:
            continue
        if key in on_path:
            raise InputError("YAML alias refers to itself", file=label, line=node.start_mark.line + 1,
                             hint="a recursive structure cannot be a setting; write the values out")
        on_path.add(key)
        if isinstance(node, yaml.MappingNode):
            _no_duplicate_keys(node, label)
        stack.append((node, True))
        for child in _children(node):
            if id(child) in on_path:
                raise InputError("YAML alias refers to itself", file=label,
                                 line=child.start_mark.line + 1,
                                 hint="a recursive structure cannot be a setting; write the values out")
            if id(child) not in size:
                stack.append((child, False))


def _no_duplicate_keys(node: yaml.MappingNode, label: str) -> None:
    seen: dict[str, yaml.Node] = {}
    for key, _ in node.value:
        if not isinstance(key, yaml.ScalarNode) or key.tag == "tag:yaml.org,2002:merge":
            continue
        if key.value in seen:
            first = seen[key.value].start_mark.line + 1
            raise InputError(f"duplicate key '{key.value}' (first on line {first})", file=label,
                             line=key.start_mark.line + 1,
                             hint="YAML would silently keep the second; remove one")
        seen[key.value] = key


def construct(node: yaml.Node) -> object:
    """The Python value of a vetted node (ints, floats, strings, bools, lists, dicts)."""
    loader = _Loader("")
    try:
        return loader.construct_document(node)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None) or node.start_mark
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise InputError(f"YAML value: {problem}", line=mark.line + 1) from None
    finally:
        loader.dispose()


def load(text: str, path: Path | str | None = None) -> object:
    """compose + construct: the safe equivalent of ``yaml.safe_load``."""
    root = compose(text, path)
    if root is None:
        return None
    try:
        return construct(root)
    except InputError as exc:
        raise exc.located(_label(path)) from None
