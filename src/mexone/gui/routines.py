"""The Routines panel: start one of the shipped routines or a .py file of the folders `mexone
sim --routines` named (the page picks a name from the server's list, never a path), stop it,
and read its console.

The routine runs in lockstep with the simulation (routines/runner.py): while it runs, the page's
frame loop steps under its scheduler (`host.routine`). A reset or a Load stops it.
"""

from __future__ import annotations

from pathlib import Path

import viser

from mexone.errors import InputError, MexoneError
from mexone.gui.panels import FPS, Panel, register_panel
from mexone.routines.runner import RoutineRunner, routine_choices

__all__ = ["RoutinesPanel"]

STOP_JOIN = 0.5  # s a stopping routine's thread is waited for


@register_panel
class RoutinesPanel(Panel):
    """The routine list, Start, Stop and the console (see the module's doc)."""

    name = "routines"
    order = 8
    period = 1

    def build(self) -> None:
        gui = self.server.gui
        with gui.add_folder("Routines"):
            self.files = self.offered()
            names = tuple(self.files)
            self.choice = gui.add_dropdown("Routine", names, initial_value=names[0],
                                           hint="shipped routines and the .py files of "
                                                "the folders mexone sim --routines named")
            gui.add_button("Refresh list").on_click(lambda _: self.do(self.refresh))
            start = gui.add_button("Start", icon=viser.Icon.PLAYER_PLAY)
            start.on_click(lambda _: self.do(self.start))
            stop = gui.add_button("Stop", icon=viser.Icon.PLAYER_STOP)
            stop.on_click(lambda _: self.do(self.stop_routine))
            self.console_view = gui.add_markdown("*console: no routine yet*")

    def offered(self) -> dict[str, Path]:
        """The routines this page offers, by name: the shipped ones, the folders', a panel's."""
        return routine_choices(self.host.settings.routine_dirs) | self.host.extra_routines

    def refresh(self) -> None:
        self.files = self.offered()
        self.choice.options = tuple(self.files)

    def log(self, level: str, text: str) -> None:
        console = self.host.console
        console.append(f"[{level}] [{self.lab.sim.time:.3f}] {text}")
        self.console_view.content = "```\n" + "\n".join(console) + "\n```"

    def start(self) -> None:
        """Simulation thread: the routine picked, if it is one the server offers."""
        if self.lab.manager is None:
            raise MexoneError("no controllers loaded: a routine has nothing to command")
        choice = self.choice.value
        path = self.files.get(choice)  # never a path the page made up
        if path is None:
            raise InputError(f"'{choice}' is not one of the routines this server offers",
                             hint="pick one from the list (mexone sim --routines DIR adds a folder)")
        self.stop_routine()
        self.host.console.clear()
        runner = RoutineRunner(self.lab, path, log=self.log, poll=1.0 / FPS)
        self.host.routine = runner
        runner.start()
        self.log("INFO", f"started {runner.path.name}")

    def stop_routine(self) -> None:
        if self.host.routine is not None:
            self.host.routine.stop(join=STOP_JOIN)
            self._done()

    def _done(self) -> None:
        runner, self.host.routine = self.host.routine, None
        runner.stop(join=STOP_JOIN)
        if runner.error:
            self.log("ERROR", runner.error.splitlines()[-1])
            self.console_view.content += "\n```\n" + runner.error + "\n```"
        else:
            self.log("INFO", f"{runner.path.name} ended")

    def update(self) -> None:
        """Every frame: a routine that ended is said in the console."""
        if self.host.routine is not None and not self.host.routine.running:
            self._done()

    def reset(self, world: bool) -> None:
        self.stop_routine()

    def unload(self) -> None:
        self.stop_routine()

    def stop(self) -> None:
        if self.host.routine is not None:
            self.host.routine.stop(join=STOP_JOIN)
