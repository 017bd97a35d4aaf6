"""RoutineRunner: run routine files (or shipped routines by name) against a Lab, in lockstep.

One runner holds the routines of one lab (one or several at once, e.g. a balance routine and an
arm routine) and the Scheduler they share, so their runs stay deterministic.
"""

from __future__ import annotations

import re
import sys
import threading
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from mexone import signals, yamlio
from mexone.description.urdf import write_urdf
from mexone.errors import InputError, RoutineError
from mexone.lab import Lab
from mexone.routines import processes, sandbox
from mexone.routines.runtime import STALL_SECONDS, RoutineContext, Scheduler, Shutdown, bind

__all__ = ["RoutineRunner", "Routine", "resolve_routine", "shipped_routines", "parse_param_args",
           "routine_choices"]

# the shipped routines are Mex-One's programs, beside its ROS nodes: this package only runs them
SHIPPED_DIR = Path(__file__).resolve().parents[1] / "robots" / "mex_one" / "routines"
DEFAULT_DURATION = 10.0  # s of sim time a run lasts when neither its caller nor its routine says
_BASE_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")  # a ROS base name (a node's)
LOG_KEEP = 10_000  # routine log lines a runner keeps in memory at least (log_lines)
SHIPPED = {"joint_steps": "joint_steps.py", "arms": "arms.py", "home": "home.py", "balance": "balance.py",
           "walk": "walk.py", "excitation": "excitation.py", "walk_cmd_vel": "walk_cmd_vel.py",
           "reach_goals": "reach_goals.py"}


def shipped_routines() -> dict[str, Path]:
    return {name: SHIPPED_DIR / file for name, file in SHIPPED.items()}


def routine_choices(folders: list[Path] | None = None) -> dict[str, Path]:
    """The routines a page may start, by name: the shipped ones and the .py files directly in
    `folders` (default: the current folder). A page picks a name; it never sends a path."""
    choices: dict[str, Path] = dict(shipped_routines())
    folders = [Path.cwd()] if folders is None else folders
    for folder in folders:
        for path in sorted(Path(folder).glob("*.py")):
            if path.is_file():
                name = path.name if len(folders) == 1 else f"{Path(folder).name}/{path.name}"
                choices.setdefault(name, path.resolve())
    return choices


RENAMED = {"sweep": "joint_steps"}  # former shipped names (issue 40), for one release


def resolve_routine(name_or_path: str | Path) -> Path:
    """A routine file, or one of the shipped routines by name."""
    if str(name_or_path) in RENAMED:
        from mexone.errors import warn_renamed

        warn_renamed(f"the routine '{name_or_path}'", f"'{RENAMED[str(name_or_path)]}' (a gain "
                     "sweep is `mexone sweep`)")
        name_or_path = RENAMED[str(name_or_path)]
    shipped = shipped_routines()
    if str(name_or_path) in shipped:
        return shipped[str(name_or_path)]
    path = Path(name_or_path)
    if not path.is_file():
        raise InputError(f"no routine '{name_or_path}'",
                         hint="give a Python file or one of: " + ", ".join(shipped))
    if path.suffix != ".py":
        raise InputError("a routine is a Python file", file=path, hint="name it .py")
    return path


def parse_param_args(args: list[str]) -> dict[str, object]:
    """ROS-style `name:=value` arguments; `_name:=v` sets the node's private ~name (under its
    init_node name, as rospy), `__name:=n` renames the node. Values are YAML, as rosrun reads
    them (safe types only)."""
    out = {}
    for arg in args:
        shown = arg if len(arg) <= 60 else arg[:57] + "..."
        name, sep, text = arg.partition(":=")
        if not sep or not name:
            raise InputError(f"argument '{shown}' is not name:=value",
                             hint="e.g. _joint:=r_elbow for the routine's ~joint parameter")
        if name.startswith("__") and name != "__name":
            raise InputError(f"argument '{shown}': {name} is a ROS remapping routines do not take",
                             hint="__name:=NODE renames the routine's node; _x:=v sets its ~x")
        if name == "__name" and not _BASE_NAME.fullmatch(text):
            raise InputError(f"argument '{shown}': a node name is a letter then letters, "
                             "digits or _", hint="e.g. __name:=left_arm")
        if name == "__name":
            out[name] = text
            continue
        try:
            out[name] = yamlio.load(text) if text else ""
        except InputError as exc:
            raise InputError(f"parameter '{shown}': {exc.what}",
                             hint="values are YAML: quote text, e.g. _name:=\"'[x'\"") from None
    return out


def _flatten(prefix: str, value, out: dict) -> None:
    if isinstance(value, dict):
        for key, sub in value.items():
            _flatten(f"{prefix}/{key}", sub, out)
    else:
        out[prefix] = value


@dataclass
class Routine:
    """One routine thread."""

    path: Path
    context: RoutineContext
    private: dict[str, object]
    thread: threading.Thread | None = None
    error: str | None = None
    line: int | None = None  # the routine's line that raised (its innermost frame in its file)

    @property
    def running(self) -> bool:
        return self.thread is not None and self.thread.is_alive() and self.context.abandoned is None


class RoutineRunner:
    def __init__(self, lab: Lab, routine: str | Path | None = None,
                 args: dict[str, object] | None = None,
                 log: Callable[[str, str], None] | None = None, stall: float = STALL_SECONDS,
                 poll: float | None = None):
        self.lab = lab
        self.scheduler = Scheduler(time=lab.sim.time, stall=stall)
        if poll is not None:
            self.scheduler.poll = poll
        self.params: dict[str, object] = {}  # the parameter server the routines share
        if lab.manager:  # the controller YAML, as it was read
            _flatten("", lab.manager.config.parameters, self.params)
        self.params["/robot_description"] = write_urdf(lab.sim.robot)  # as on a ROS master
        # the latest LOG_KEEP to 2 x LOG_KEEP lines (a long run's routine may log without end)
        self.log_lines: list[tuple[float, str, str]] = []
        self._sink = log
        self.routines: list[Routine] = []
        self._children: set[int] | None = None  # this process's children before the routines ran
        self.left_running: list[str] = []  # programs the routines started and left running
        if routine is not None:
            self.add(routine, args)

    def add(self, routine: str | Path, args: dict[str, object] | None = None) -> Routine:
        """Another routine to run with the others (started by start())."""
        path = resolve_routine(routine)
        context = RoutineContext(self.lab, self.scheduler, self.params, self._log,
                                 node_name=f"/{path.stem}", source=str(path))
        entry = Routine(path, context, dict(args or {}))
        self.routines.append(entry)
        return entry

    @property
    def path(self) -> Path:
        return self.routines[0].path

    def param(self, key: str, default: object = None) -> object:
        """The first routine's private parameter ~key (under its node name, init_node's)."""
        return self.params.get(f"{self.routines[0].context.node_name}/{key}", default)

    @property
    def error(self) -> str | None:
        errors = [r.error for r in self.routines if r.error]
        errors += [e for r in self.routines for e in r.context.errors] + self.left_running
        return "\n".join(errors) or None

    @property
    def running(self) -> bool:
        return any(r.running for r in self.routines)

    @property
    def notices(self) -> list[str]:
        """mexone's warnings about the routines (a command topic nobody subscribes to)."""
        return [text for r in self.routines for text in r.context.notices]

    def _log(self, level: str, text: str) -> None:
        self.log_lines.append((self.lab.sim.time, level, text))
        if len(self.log_lines) >= 2 * LOG_KEEP:
            del self.log_lines[:LOG_KEEP]
        if self._sink:
            self._sink(level, text)

    def start(self) -> None:
        """Start every routine not yet started; each holds the clock until it first waits."""
        sandbox.install()
        if self._children is None:
            self._children = processes.children()
        for entry in self.routines:
            if entry.thread is None:
                ready = threading.Event()
                entry.thread = threading.Thread(target=self._main, args=(entry, ready), daemon=True,
                                                name=f"routine {entry.path.stem}")
                entry.thread.start()
                ready.wait()

    def _main(self, entry: Routine, ready: threading.Event) -> None:
        context = entry.context
        bind(context)
        self.scheduler.enter(context)
        ready.set()
        try:
            self._arguments(entry)
            sandbox.run_path(entry.path)
        except Shutdown:  # rospy's ROSInterruptException is one
            pass
        except sandbox.RoutineExit as exc:
            entry.error = str(exc)
        except SystemExit as exc:
            if exc.code not in (None, 0):
                entry.error = f"routine exited with status {exc.code}"
        except BaseException:  # noqa: BLE001 - the student's error, shown as their traceback
            entry.error = _students_traceback(entry.path)
            entry.line = _students_line(entry.path)
        finally:
            if context.abandoned and not entry.error:
                entry.error = context.abandoned
            self.scheduler.leave()
            bind(None)

    def _arguments(self, entry: Routine) -> None:
        """The routine's name:=value arguments, where rosrun puts them (its thread, first)."""
        context = entry.context
        for key, value in entry.private.items():
            if key == "__name":
                context.name_remap = str(value)
            elif key.startswith("_"):  # ~x under the node's name: init_node moves it
                context.private[key[1:]] = value
                self.params[f"{context.node_name}/{key[1:]}"] = value
            else:
                self.params["/" + key.lstrip("/")] = value

    def run(self, duration: float | None, on_tick=None, tick: float = 0.05,
            default: float = DEFAULT_DURATION, hold: bool = False) -> None:
        """Simulate until every routine ends or `duration` s of sim time pass (a routine that
        stops yielding is abandoned after the stall time, with an error). duration None: as
        long as the routines declare (declared_duration), else `default` s. hold: when the
        routines end first (without an error), simulate on to the duration with the
        controllers holding their last commands, so what a routine's last lines set off (a
        push, a step) shows: the CLI's runs last their duration.

        Raises RoutineError (after the run ended and the routines stopped) when a routine
        failed: its FILE:LINE and exception in one line, the whole report in `.details` (also
        `self.error`). A signal (Ctrl-C) ends the run without an error."""
        self.start()
        sim = self.lab.sim
        if duration is None:
            # each routine runs to its first wait (served meanwhile): by then it has declared
            while (self.scheduler.active and self.scheduler.horizon() is None
                   and not signals.requested()):
                sim.work.drain()
            duration = self.declared_duration() or default
        remaining = duration
        try:  # a signal (Ctrl-C, SIGTERM) ends the run at the next tick; the routines stop
            while remaining > sim.timestep / 2 and self.scheduler.active and not signals.requested():
                remaining -= sim.run(remaining, on_tick=on_tick, tick=tick, gate=self.scheduler,
                                     until=lambda: not self.scheduler.active or signals.requested())
        finally:
            self.stop()
        self.check()
        while hold and remaining > sim.timestep / 2 and not signals.requested():
            remaining -= sim.run(remaining, on_tick=on_tick, tick=tick, until=signals.requested)

    def check(self) -> None:
        """Raise RoutineError if a routine failed (run() calls it; a caller of start() may)."""
        if (details := self.error) is None:
            return
        failed = next((r for r in self.routines if r.error), None)
        first = (failed.error if failed else details).strip().splitlines()[-1]
        path = failed.path if failed else self.path
        raise RoutineError(first, file=path, line=failed.line if failed else None,
                           details=details)

    def declared_duration(self) -> float | None:
        """The longest ~duration (s of sim time) the routines set themselves, e.g.
        rospy.set_param("~duration", 40.0) before they first wait: how long `mexone run` runs
        them when not told (walk sets its course's length)."""
        declared = []
        for entry in self.routines:
            value = self.params.get(f"{entry.context.node_name}/duration")
            if isinstance(value, int | float) and not isinstance(value, bool) and 0 < value < 1e9:
                declared.append(float(value))
        return max(declared, default=None)

    def stop(self, join: float = 1.0) -> None:
        """Stop every routine (they get ROSInterruptException at their next wait)."""
        self.scheduler.stop()
        for entry in self.routines:
            if entry.thread is not None:
                entry.thread.join(timeout=join)
            if entry.context.abandoned and not entry.error:
                entry.error = entry.context.abandoned
        if self._children is not None:  # what the routines started ends with them
            self.left_running += sandbox.stop_children(self._children)
        for entry in self.routines:
            if entry.thread is not None and not entry.thread.is_alive():
                for line in sandbox.stop_threads(entry.context):
                    entry.context.notices.append(line)
                    self._log("WARN", line)


def _students_line(path: Path) -> int | None:
    """The line of the routine's file where the exception being handled passed last."""
    lines = [f.lineno for f in traceback.extract_tb(sys.exc_info()[2]) if f.filename == str(path)]
    return lines[-1] if lines else None


def _students_traceback(path: Path) -> str:
    """The traceback of the exception being handled, with only the student's frames: not
    runpy's, not threading's, not mexone's."""
    exc_type, exc, tb = sys.exc_info()
    if exc_type is KeyboardInterrupt:
        exc = KeyboardInterrupt("the routine raised KeyboardInterrupt (only the simulation "
                                "stops routines)")
    return sandbox.students_traceback(exc, path, tb)
