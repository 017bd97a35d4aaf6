"""The one line said for each mistake a student's controller makes in what its update returns,
and its `self.log`: shared by the in-process runner (control/controllers/python.py) and a
controller's own process (control/worker_main.py), so both say the same."""

from __future__ import annotations

import dis
import logging
import math
import time
from collections.abc import Callable, MutableMapping
from typing import Any

import numpy as np

from mexone.ranges import number_text

__all__ = ["StudentLog", "LogLimit", "LOG_LINES_PER_SECOND", "dropped_lines", "not_numbers",
           "wrong_count", "non_finite", "return_lines"]


LOG_LINES_PER_SECOND = 20  # of one controller's self.log, on the wall clock


class LogLimit:
    """At most `per_second` lines of one controller's `self.log` a second (wall clock) reach the
    lab's log: a line logged every update at 1 kHz would bury everything else (was: 7000 lines
    in 2 s on stderr). The lines over are counted, and said (dropped_lines) before the next line
    let through, or when the controller ends."""

    def __init__(self, per_second: int = LOG_LINES_PER_SECOND,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.per_second, self.clock = per_second, clock
        self.since, self.count, self.dropped = -math.inf, 0, 0

    def admit(self) -> tuple[bool, int]:
        """(whether this line is shown, how many lines were dropped before it: say that first)."""
        now = self.clock()
        if now - self.since >= 1.0:
            self.since, self.count = now, 0
        if self.count >= self.per_second:
            self.dropped += 1
            return False, 0
        self.count += 1
        return True, self.flush()

    def flush(self) -> int:
        """The lines dropped since last said (and now said)."""
        dropped, self.dropped = self.dropped, 0
        return dropped

    def let_through(self, logger: logging.Logger, name: str) -> bool:
        """Whether controller `name`'s next line is logged; the lines dropped before it are
        said on `logger` first."""
        shown, dropped = self.admit()
        self.say(logger, name, dropped)
        return shown

    def say(self, logger: logging.Logger, name: str, dropped: int | None = None) -> None:
        """The line saying how many of `name`'s lines were dropped (None: those not said yet),
        if any were."""
        if dropped is None:
            dropped = self.flush()
        if dropped:
            logger.warning("%s", dropped_lines(name, dropped, self.per_second))


def dropped_lines(name: str, count: int, per_second: int) -> str:
    """The line that says a controller's log lines were dropped."""
    return (f"{name}: {count} line{'s' if count != 1 else ''} of its log not shown (more than "
            f"{per_second} a second)")


class StudentLog(logging.LoggerAdapter[logging.Logger]):
    """`self.log` of a Python controller: its lines prefixed with the controller's name; with a
    LogLimit (extra "limit"), at most its lines a second."""

    def process(self, msg: object, kwargs: MutableMapping[str, Any]
                ) -> tuple[object, MutableMapping[str, Any]]:
        return f"{self.extra['name']}: {msg}", kwargs  # type: ignore[index]  # extra is given

    def log(self, level: int, msg: object, *args: Any, **kwargs: Any) -> None:
        extra = self.extra or {}
        limit = extra.get("limit")
        if isinstance(limit, LogLimit) and self.isEnabledFor(level) and \
                not limit.let_through(self.logger, str(extra.get("name"))):
            return
        super().log(level, msg, *args, **kwargs)


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
