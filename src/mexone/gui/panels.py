"""GUI panels as plug-ins: one interface and one registry, as controllers have (a new panel is
one module), and the small host interface every panel talks to instead of the app.

A panel is a folder of the page (or an overlay of the 3D view). The page (gui/app.py's GuiApp,
one `PanelHost`) makes one instance of each registered panel for the page's life and drives it
from the simulation thread, the only thread that touches MuJoCo:

- `build()` adds its widgets: at start, and again after Load opened another robot (Load clears
  the page, so every handle is new; state the panel keeps in `self` survives);
- `update()` every `period` frames (the GUI draws FPS = 30 frames a second);
- `reset(world)` before Reset model (world=False) or Reset world (True) puts the robot back;
- `status_line()` a line for the page's status line, or None;
- `unload()` before Load tears the page down (stop what belongs to the old robot);
- `stop()` once, when the page closes.

`self.host` is the page (`PanelHost` below): `host.lab` (the robot loaded now: read it in each
call, Load replaces it), `host.server`, `host.do(fn)` (run fn in the simulation thread, between
frames; a widget's callback runs in viser's thread and must hand its work over this way),
`host.refuse(text)` (a one-line refusal on the page), `host.notify(title, text)`,
`host.panel(name)` (another panel, e.g. the Plots panel a step response shows its joint in).
Every value a page sends is checked in the panel, on the server.

A panel registers itself with `@register_panel`; the shipped ones are imported from
`BUILTIN_PANELS`, a package's from the `mexone.gui_panels` entry-point group
(`name = "package.module"`: importing the module registers it).
"""

from __future__ import annotations

import importlib
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

if TYPE_CHECKING:
    from collections import deque

    import viser

    from mexone.gui.fields import NumberFields
    from mexone.gui.plots import SignalLog
    from mexone.gui.scene import RobotScene
    from mexone.lab import Lab
    from mexone.physics.compile import CompileOptions, Spawn
    from mexone.routines.runner import RoutineRunner

__all__ = ["Panel", "PanelHost", "PageSettings", "register_panel", "panel_types", "PANELS",
           "BUILTIN_PANELS", "ENTRY_POINT_GROUP", "FPS"]

log = logging.getLogger(__name__)

FPS = 30.0  #: frames the page draws per second of wall time (a panel's `period` counts them)

#: the entry-point group a package's GUI panels are found in (`name = "package.module"`)
ENTRY_POINT_GROUP = "mexone.gui_panels"
#: the modules of the shipped panels (importing one registers its panels)
BUILTIN_PANELS = ("mexone.gui.simulation", "mexone.gui.view", "mexone.gui.joints",
                  "mexone.gui.plots", "mexone.gui.stepresponse", "mexone.gui.inspector",
                  "mexone.gui.sensors", "mexone.gui.routines", "mexone.gui.physics",
                  "mexone.gui.topics", "mexone.gui.controllers", "mexone.gui.load",
                  "mexone.gui.exercises", "mexone.gui.walkpad", "mexone.gui.handles",
                  "mexone.gui.walkplan")
#: the registry: panel name -> Panel class (filled by register_panel)
PANELS: dict[str, type[Panel]] = {}


@dataclass(frozen=True)
class PageSettings:
    """What the page was started with (`mexone sim`'s options), for the panels that need it."""

    model_folder: Path = field(default_factory=Path.cwd)  # Load's list: robot files under it
    record_folder: Path | None = None  # Record and Screenshot write here (None: the cwd)
    routine_dirs: list[Path] | None = None  # the Routines list's folders (None: the cwd)
    start_paused: bool = False  # --paused: wait for Play after a start, a Load or a reset
    exercise: Any = None  # an ExerciseTarget (gui/exercises.py) for the Exercises panel


class PanelHost(Protocol):
    """What a panel may use of the page that holds it (gui/app.py's GuiApp is one). Panels
    import this, never the app."""

    lab: Lab  # the robot loaded now: Load replaces it, so read it in each call
    server: viser.ViserServer
    settings: PageSettings
    options: CompileOptions  # the physics options Load and Reset world compile with
    scene: RobotScene  # the robot in the 3D view (new after Load)
    log: SignalLog  # every plottable signal, sampled in sim time (new after Load)
    fields: NumberFields  # the page's number fields, checked on the server (new after Load)
    console: deque[str]  # the page's console: warnings and the routine's log
    model_label: str  # the file the robot came from
    target_rtf: float  # the real-time factor asked for (0: as fast as possible)
    pause_after_reset: bool  # wait for Play after a reset or a Load
    extra_routines: dict[str, Path]  # routines a panel offers (an exercise's) by name
    routine: RoutineRunner | None  # the routine running in lockstep now, if any

    def do(self, action: Callable[[], None]) -> None:
        """Run `action` in the simulation thread, between frames."""

    def refuse(self, text: str) -> None:
        """A one-line refusal on the page (what it asked for, why not)."""

    def notify(self, title: str, body: str, color: str = "red") -> None:
        """A notification on every open page."""

    def panel(self, name: str) -> Panel | None:
        """The panel called `name` on this page, if it is there and working."""

    def load(self, path: Path | None, controllers: Path | str = ...,
             spawn: Spawn | None = None) -> None:
        """Open another robot (simulation thread): every panel unloaded and built again."""

    def reset_model(self) -> None:
        """The robot back to its spawn pose at home, sim time 0."""

    def reset_world(self) -> None:
        """Reset model, with the settings that wait for it applied (self-collision)."""

    def toggle_pause(self) -> None:
        """Pause a running simulation, or resume a paused one."""

    def step_n(self, n: float) -> None:
        """Advance n physics steps, paused, spread over frames."""


class Panel:
    """One folder of the page (see the module's doc for when each method runs)."""

    name: ClassVar[str] = ""  # unique: the registry's key, host.panels' key
    order: ClassVar[int] = 100  # panels are built in this order (smaller first)
    period: ClassVar[int] = 5  # frames between update() calls

    def __init__(self, host: PanelHost):
        self.host = host

    @property
    def app(self) -> PanelHost:
        """The host's former name (gui/panels.py before the host interface)."""
        return self.host

    @property
    def lab(self) -> Lab:
        """The robot loaded now (Load replaces it)."""
        return self.host.lab

    @property
    def server(self) -> viser.ViserServer:
        """The page's viser server (its gui and scene)."""
        return self.host.server

    def do(self, action: Callable[[], None]) -> None:
        """Run `action` in the simulation thread, between frames."""
        self.host.do(action)

    def refuse(self, text: str) -> None:
        """Say on the page, in one line, why something the page asked for was refused."""
        self.host.refuse(text)

    @classmethod
    def wanted(cls, host: PanelHost) -> bool:
        """Whether this page shows the panel at all (e.g. Exercises: only with --exercise)."""
        return True

    def build(self) -> None:
        """Add the panel's widgets (simulation thread)."""
        raise NotImplementedError

    def update(self) -> None:
        """Refresh what it shows (simulation thread, every `period` frames)."""

    def reset(self, world: bool) -> None:
        """Before Reset model (world=False) or Reset world (True) puts the robot back."""

    def status_line(self) -> str | None:
        """A line for the page's status line (Markdown), or None."""
        return None

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
