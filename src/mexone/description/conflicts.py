"""Values a robot file states twice: which statement the simulators use, and a finding naming both.

Gazebo's URDF parser lets a ``<gazebo reference>`` block override the URDF's own value (and a
later block, or a later tag in one block, an earlier one); urdfdom reads only the first of a
repeated element. Either way one statement is silently dead, and a student who edits it sees
nothing change, so `mexone check` names both lines and the one that wins.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from lxml import etree

from mexone.description.findings import Finding

__all__ = ["Statement", "Statements", "leaves", "CONFLICT_CODE"]

CONFLICT_CODE = "value-conflict"


@dataclass(frozen=True)
class Statement:
    """One place a value is written."""

    text: str  # as written
    where: str  # the element that says it: '<dynamics>', '<gazebo reference="l_knee">'
    line: int | None


def _meaning(text: str) -> object:
    """What a value means, so "0.5" and "0.50", "true" and "1" agree."""
    words = text.split()
    try:
        return tuple(float(w) for w in words)
    except ValueError:
        pass
    return {"true": (1.0,), "false": (0.0,)}.get(text.strip().lower(), text.strip())


class Statements:
    """Every value a file states, by element and quantity; a second, different one is reported."""

    def __init__(self, label: str, findings: list[Finding]) -> None:
        self.label, self.findings = label, findings
        self._said: dict[tuple[str, str], Statement] = {}

    def state(self, element: str, quantity: str, said: Statement, overrides: bool, why: str) -> None:
        """Record `said`; `overrides`: it replaces an earlier statement (else the earlier stays)."""
        key = (element, quantity)
        earlier = self._said.get(key)
        if earlier is None or overrides:
            self._said[key] = said
        if earlier is None or _meaning(earlier.text) == _meaning(said.text):
            return
        winner, loser = (said, earlier) if overrides else (earlier, said)
        self.findings.append(Finding(
            CONFLICT_CODE, "warning", element,
            f"{quantity} given twice: {loser.text} at {self._at(loser)} ({loser.where}) and "
            f"{winner.text} at {self._at(winner)} ({winner.where}); {winner.text} wins ({why}), "
            "so editing the other changes nothing: keep one", loser.line))

    def _at(self, said: Statement) -> str:
        return f"{self.label}:{said.line}"


def leaves(el: etree._Element, skip: tuple[str, ...] = ()) -> Iterator[tuple[str, etree._Element]]:
    """(path below el, element) of every element without element children, in file order;
    subtrees whose tag is in `skip` are left out."""
    for child in el:
        if not isinstance(child.tag, str) or child.tag in skip:
            continue
        inner = [c for c in child if isinstance(c.tag, str)]
        if not inner:
            yield child.tag, child
        else:
            for path, leaf in leaves(child, skip):
                yield f"{child.tag}/{path}", leaf
