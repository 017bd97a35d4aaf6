"""The one line said for each mistake a student's controller makes in what its update returns,
and its `self.log`: shared by the in-process runner (control/controllers/python.py) and a
controller's own process (control/worker_main.py), so both say the same."""

from __future__ import annotations

import dis
import logging
from collections.abc import MutableMapping
from typing import Any

import numpy as np

from mexone.ranges import number_text

__all__ = ["StudentLog", "not_numbers", "wrong_count", "non_finite", "return_lines"]


class StudentLog(logging.LoggerAdapter[logging.Logger]):
    """`self.log` of a Python controller: its lines prefixed with the controller's name."""

    def process(self, msg: object, kwargs: MutableMapping[str, Any]
                ) -> tuple[object, MutableMapping[str, Any]]:
        return f"{self.extra['name']}: {msg}", kwargs  # type: ignore[index]  # extra is given


def not_numbers(out: object, where: str) -> str:
    """The fault of an update whose return value is not numbers."""
    try:
        text = str(out)[:40]
    except Exception:  # noqa: BLE001 - a __str__ of the student's that raises
        text = "?"
    return f"update returned {type(out).__name__} {text!r}, not numbers ({where})"


def wrong_count(size: int, n: int, where: str) -> str:
    """The fault of an update that returned `size` numbers for `n` joints."""
    return f"update returned {size} values for {n} joints ({where})"


def non_finite(joints: list[str], values: np.ndarray, t: float, where: str) -> str:
    """The fault of an update that returned NaN or inf: the joints and values named."""
    bad = [f"{joints[i]} {number_text(values[i])}" for i in np.flatnonzero(~np.isfinite(values))]
    return f"update returned {', '.join(bad)} at t = {t:.3f} s ({where})"


def return_lines(fn: object) -> list[int]:
    """The lines of `fn`'s return statements that return a value (a bare `return` or falling
    off the end returns None: not these)."""
    code = getattr(fn, "__code__", None)
    if code is None:
        return []
    lines: set[int] = set()
    previous = None
    for ins in dis.get_instructions(code):
        if (ins.opname == "RETURN_VALUE" and not (previous is not None and previous.opname ==
                                                   "LOAD_CONST" and previous.argval is None)) or \
                (ins.opname == "RETURN_CONST" and ins.argval is not None):
            line = ins.positions.lineno if ins.positions is not None else None
            if line:
                lines.add(line)
        previous = ins
    return sorted(lines)
