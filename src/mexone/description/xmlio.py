"""Safe XML reading with line numbers and typed values that fail as one-line InputErrors.

defusedxml vets the bytes (entity declarations and external references are refused, which
stops XXE and entity-expansion bombs); lxml then parses for ``sourceline``, which the
standard library does not keep.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Literal, overload
from xml.etree.ElementTree import ParseError

import defusedxml.ElementTree as safe_et
from defusedxml import EntitiesForbidden, ExternalReferenceForbidden
from lxml import etree

from mexone.errors import InputError
from mexone.inputs import read_input

__all__ = ["XmlReader", "describe"]

_NUMBER_HINT = "write a plain number: URDF and SDF use metres, radians, kilograms and seconds, no units"


def _line_of(data: bytes, needle: bytes) -> int | None:
    at = data.find(needle)
    return data.count(b"\n", 0, at) + 1 if at >= 0 else None


def describe(el: etree._Element) -> str:
    """``<joint name="l_knee">`` for messages."""
    name = el.get("name")
    return f'<{el.tag} name="{name}">' if name is not None else f"<{el.tag}>"


class XmlReader:
    """Parses one file and turns its attributes and texts into checked values."""

    def __init__(self, path: Path | str, data: bytes | None = None, label: str | None = None) -> None:
        self.path = Path(path)
        self.label = label or str(path)
        if data is None:
            data = read_input(self.path, self.label)
        if not data.strip():
            raise InputError("empty file", file=self.label, hint="expected an XML robot description")
        self.root = self._parse(data)

    def _parse(self, data: bytes) -> etree._Element:
        try:
            safe_et.fromstring(data, forbid_dtd=False, forbid_entities=True, forbid_external=True)
        except EntitiesForbidden as exc:
            raise self.error(
                f"XML entity declaration '{exc.name}' refused",
                _line_of(data, b"<!ENTITY"),
                "entities can read local files or expand without bound; write the values out",
            ) from None
        except ExternalReferenceForbidden:
            raise self.error(
                "XML external reference refused",
                _line_of(data, b"<!DOCTYPE"),
                "a model must not pull in other files through the DTD",
            ) from None
        except ParseError as exc:
            line = exc.position[0] if exc.position else None
            msg = str(exc).split(":")[0]
            raise self.error(f"malformed XML: {msg}", line, "fix the XML syntax") from None
        parser = etree.XMLParser(
            resolve_entities=False, no_network=True, remove_comments=True, huge_tree=False
        )
        try:
            root = etree.fromstring(data, parser=parser)
        except etree.XMLSyntaxError as exc:
            if "Excessive depth" in exc.msg:
                raise self.error("XML nests deeper than 256 elements", exc.lineno,
                                 "a robot description nests a few levels; is it the right file?") from None
            msg = re.sub(r", line \d+, column \d+$", "", exc.msg)
            raise self.error(f"malformed XML: {msg}", exc.lineno, "fix the XML syntax") from None
        docinfo = root.getroottree().docinfo
        if docinfo.system_url or docinfo.public_id:
            raise self.error("external DTD refused", _line_of(data, b"<!DOCTYPE"),
                             "a model must not pull in other files through the DTD")
        return root

    # ----- errors --------------------------------------------------------------------------
    def error(self, what: str, line: int | None = None, hint: str | None = None) -> InputError:
        return InputError(what, file=self.label, line=line, hint=hint)

    def fail(self, el: etree._Element, what: str, hint: str | None = None) -> InputError:
        return self.error(f"{describe(el)} {what}", el.sourceline, hint)

    # ----- attributes ----------------------------------------------------------------------
    def attr(self, el: etree._Element, name: str, default: str | None = None) -> str:
        value = el.get(name, default)
        if value is None:
            raise self.fail(el, f"is missing attribute '{name}'")
        return value

    @overload
    def child(self, el: etree._Element, tag: str, required: Literal[True]) -> etree._Element: ...
    @overload
    def child(self, el: etree._Element, tag: str, required: bool = False) -> etree._Element | None: ...

    def child(self, el: etree._Element, tag: str, required: bool = False) -> etree._Element | None:
        """Child <tag> of `el`; with `required`, a missing one is this file's error at el's line."""
        found = el.find(tag)
        if found is None and required:
            raise self.fail(el, f"is missing its <{tag}> element")
        return found

    def number(self, el: etree._Element, text: str, what: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise self.fail(el, f"{what}: '{text}' is not a number", _NUMBER_HINT) from None
        if not math.isfinite(value):
            raise self.fail(el, f"{what}: '{text}' is not finite", "use a finite number")
        return value

    def numbers(self, el: etree._Element, text: str, count: int, what: str) -> tuple[float, ...]:
        parts = text.split()
        if len(parts) != count:
            raise self.fail(
                el, f"{what}: expected {count} numbers, got {len(parts)} ('{text.strip()}')"
            )
        return tuple(self.number(el, p, what) for p in parts)

    def float_attr(self, el: etree._Element, name: str, default: float | None = None) -> float:
        text = el.get(name)
        if text is None:
            if default is None:
                raise self.fail(el, f"is missing attribute '{name}'")
            return default
        return self.number(el, text, f"attribute '{name}'")

    def vector_attr(self, el: etree._Element, name: str, default: Sequence[float] | None = None,
                    count: int = 3) -> tuple[float, ...]:
        text = el.get(name)
        if text is None:
            if default is None:
                raise self.fail(el, f"is missing attribute '{name}'")
            return tuple(default)
        return self.numbers(el, text, count, f"attribute '{name}'")

    def text_number(self, el: etree._Element, tag: str, default: float | None = None) -> float:
        """Number held as the text of child <tag> (the SDF way)."""
        sub = el.find(tag)
        if sub is None or not (sub.text or "").strip():
            if default is None:
                raise self.fail(el, f"is missing <{tag}>")
            return default
        return self.number(sub, sub.text.strip(), "value")

    def text_bool(self, el: etree._Element, tag: str) -> bool | None:
        sub = el.find(tag)
        return None if sub is None else self.bool_of(sub)

    def bool_of(self, sub: etree._Element) -> bool:
        """The boolean an element's text says (true, false, 1 or 0)."""
        text = (sub.text or "").strip().lower()
        if text in ("1", "true"):
            return True
        if text in ("0", "false"):
            return False
        raise self.fail(sub, f"'{text}' is not a boolean", "write true, false, 1 or 0")

    def text(self, el: etree._Element, tag: str) -> str | None:
        sub = el.find(tag)
        return (sub.text or "").strip() if sub is not None else None
