"""GUI panels as plug-ins: one interface and one registry, as controllers have (a new panel is
one module).

A panel is a folder of the page. GuiApp makes one instance of each registered panel for the
page's life and drives it from the simulation thread, the only thread that touches MuJoCo:

- `build()` adds its widgets: at start, and again after Load opened another robot (Load clears
  the page, so every handle is new; state the panel keeps in `self` survives);
- `update()` every `period` frames (the GUI draws FPS = 30 frames a second);
- `unload()` before Load tears the page down (stop what belongs to the old robot);
- `stop()` once, when the page closes.

`self.app` is the GuiApp: `app.lab` (the robot now loaded: read it in each call, Load replaces
it), `app.server`, `app.do(fn)` (run fn in the simulation thread, between frames; a widget's
callback runs in viser's thread and must hand its work over this way), `app.refuse(text)` (a
one-line refusal on the page), `app.notify(title, text)`. Every value a page sends is checked in
the panel, on the server.

A panel registers itself with `@register_panel`; the shipped ones are imported from
`BUILTIN_PANELS`, a package's from the `mexone.gui_panels` entry-point group
(`name = "package.module"`: importing the module registers it).
"""

from __future__ import annotations

import importlib
import logging
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, ClassVar

if TYPE_CHECKING:
    from mexone.gui.app import GuiApp

__all__ = ["Panel", "register_panel", "panel_types", "PANELS", "BUILTIN_PANELS",
           "ENTRY_POINT_GROUP"]

log = logging.getLogger(__name__)

ENTRY_POINT_GROUP = "mexone.gui_panels"
BUILTIN_PANELS = ("mexone.gui.topics", "mexone.gui.controllers", "mexone.gui.load",
                  "mexone.gui.exercises")
PANELS: dict[str, type[Panel]] = {}


class Panel:
    """One folder of the page (see the module's doc for when each method runs)."""

    name: ClassVar[str] = ""  # unique: the registry's key, app.panels' key
    order: ClassVar[int] = 100  # panels are built in this order (smaller first)
    period: ClassVar[int] = 5  # frames between update() calls

    def __init__(self, app: GuiApp):
        self.app = app

    @classmethod
    def wanted(cls, app: GuiApp) -> bool:
        """Whether this page shows the panel at all (e.g. Exercises: only with --exercise)."""
        return True

    def build(self) -> None:
        """Add the panel's widgets (simulation thread)."""
        raise NotImplementedError

    def update(self) -> None:
        """Refresh what it shows (simulation thread, every `period` frames)."""

    def unload(self) -> None:
        """Before Load replaces the robot and clears the page."""

    def stop(self) -> None:
        """The page closes: end what the panel started (threads, processes)."""


def register_panel(cls: type[Panel]) -> type[Panel]:
    """Class decorator: add a Panel subclass to the registry under its `name`."""
    if not (isinstance(cls, type) and issubclass(cls, Panel)) or not cls.name:
        raise TypeError(f"{cls!r}: a panel is a Panel subclass with a name")
    seen = PANELS.get(cls.name)
    if seen is not None and seen.__qualname__ != cls.__qualname__:
        raise TypeError(f"two panels are named '{cls.name}': {seen.__module__} and {cls.__module__}")
    PANELS[cls.name] = cls
    return cls


def panel_types() -> list[type[Panel]]:
    """Every registered panel, the shipped ones and the entry points', in build order. A
    package's panel that fails to import is logged and left out (the page still opens)."""
    for module in BUILTIN_PANELS:
        importlib.import_module(module)
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        try:
            importlib.import_module(ep.value)
        except Exception as exc:  # noqa: BLE001 - someone else's package: the page goes on
            log.warning("GUI panel %s (%s) did not load: %s", ep.name, ep.value, exc)
    return sorted(PANELS.values(), key=lambda cls: (cls.order, cls.name))
