"""Numbers typed on the page, checked on the server.

viser's number inputs filter keys in the browser: "1e9" arrives as 19, "-1" as 1 where the
minimum is 0, letters and NaN blank the field and never reach the server. So the page's numeric
fields are text fields: the server reads what was typed once the typing stops (SETTLE s without
a key), applies it or refuses it with a message, and then the field shows what the server holds.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import viser

from mexone.ranges import Range

__all__ = ["NumberFields", "parse_numbers", "SETTLE"]

SETTLE = 0.5  # s without a keystroke before a typed value is read


def parse_numbers(label: str, text: object, count: int = 1) -> list[float]:
    """`count` finite numbers from what a page sent (text, or a number a script sent)."""
    parts = [text] if not isinstance(text, str) else text.replace(",", " ").split()
    values = []
    for part in parts:
        try:
            if isinstance(part, bool):
                raise ValueError
            number = float(part)
        except (TypeError, ValueError):
            raise ValueError(f"{label}: '{text}' is not a number") from None
        if not math.isfinite(number):
            raise ValueError(f"{label}: '{text}' is not a finite number")
        values.append(number)
    if len(values) != count:
        raise ValueError(f"{label}: '{text}' is not {count} numbers" if count > 1 else
                         f"{label}: '{text}' is not a number")
    return values


def show(values: list[float]) -> str:
    return ", ".join(f"{v:.10g}" for v in values)


@dataclass
class _Field:
    handle: viser.GuiTextHandle
    apply: Callable[[list[float]], None]
    valid: Range
    count: int
    held: list[float]
    typed: object = None
    since: float = 0.0


class NumberFields:
    def __init__(self, gui, refuse: Callable[[str], None]):
        self.gui, self.refuse = gui, refuse
        self.fields: list[_Field] = []
        self.last_change: str | None = None  # "gravity = 0, 0, -981": what a divergence follows

    def add(self, label: str, initial: float | list[float], valid: Range, apply: Callable,
            hint: str | None = None) -> viser.GuiTextHandle:
        """A field holding one number (or several: `initial` a list), each in `valid` (the
        quantity's one range, ranges.py); `apply(value)` runs in the simulation thread, and may
        refuse by raising."""
        held = list(initial) if isinstance(initial, list | tuple) else [float(initial)]
        handle = self.gui.add_text(label, initial_value=show(held), hint=hint)
        count = len(held)
        entry = _Field(handle, (lambda v: apply(v)) if count > 1 else (lambda v: apply(v[0])),
                       valid, count, held)

        def typed(event) -> None:
            if event.client is None:
                return
            entry.typed, entry.since = handle.value, time.monotonic()

        handle.on_update(typed)
        self.fields.append(entry)
        return handle

    def held(self, handle) -> list[float]:
        return next(f.held for f in self.fields if f.handle is handle)

    def set_held(self, handle, values: list[float]) -> None:
        """The server changed the value itself (a reset): show it."""
        entry = next(f for f in self.fields if f.handle is handle)
        entry.held = list(values)
        entry.handle.value = show(entry.held)

    def commit(self, now: float | None = None, wait: float = SETTLE) -> None:
        """Read what was typed and has settled (the simulation thread, once a frame)."""
        now = time.monotonic() if now is None else now
        for entry in self.fields:
            if entry.typed is None or now - entry.since < wait:
                continue
            text, entry.typed = entry.typed, None
            label = entry.handle.label
            try:
                values = entry.valid.check_all(parse_numbers(label, text, entry.count), f"{label}:")
                entry.apply(values)
            except Exception as exc:  # noqa: BLE001 - every refusal is shown, the field restored
                message = exc.one_line() if hasattr(exc, "one_line") else str(exc)
                entry.handle.value = show(entry.held)
                self.refuse(message)
                if not isinstance(exc, ValueError) and not hasattr(exc, "one_line"):
                    raise
                continue
            entry.held = values
            entry.handle.value = show(values)
            self.last_change = f"{label} = {show(values)}"
