"""RoutineRunner: run a routine file (or a shipped routine by name) against a Lab."""

from __future__ import annotations

import runpy
import sys
import threading
import traceback
from collections.abc import Callable
from pathlib import Path

import yaml

from mexone.errors import InputError
from mexone.lab import Lab
from mexone.routines.runtime import RoutineContext, Scheduler, Shutdown, bind

__all__ = ["RoutineRunner", "resolve_routine", "shipped_routines", "parse_param_args"]

_HERE = Path(__file__).resolve().parent
SHIPPED = {"sweep": "sweep.py", "arms": "arms.py", "home": "home.py"}


def shipped_routines() -> dict[str, Path]:
    return {name: _HERE / "shipped" / file for name, file in SHIPPED.items()}


def resolve_routine(name_or_path: str) -> Path:
    shipped = shipped_routines()
    if name_or_path in shipped:
        return shipped[name_or_path]
    path = Path(name_or_path)
    if not path.is_file():
        raise InputError(f"no routine '{name_or_path}'",
                         hint="give a Python file or one of: " + ", ".join(shipped))
    if path.suffix != ".py":
        raise InputError("a routine is a Python file", file=path, hint="name it .py")
    return path


def parse_param_args(args: list[str]) -> dict[str, object]:
    """ROS-style `name:=value` arguments; `_name:=v` sets the node's private ~name."""
    out = {}
    for arg in args:
        name, sep, text = arg.partition(":=")
        if not sep or not name:
            raise InputError(f"argument '{arg}' is not name:=value",
                             hint="e.g. _joint:=r_elbow for the routine's ~joint parameter")
        out[name] = yaml.safe_load(text) if text else ""
    return out


def _flatten(prefix: str, value, out: dict) -> None:
    if isinstance(value, dict):
        for key, sub in value.items():
            _flatten(f"{prefix}/{key}", sub, out)
    else:
        out[prefix] = value


class RoutineRunner:
    """One routine thread in lockstep with the lab's simulation."""

    def __init__(self, lab: Lab, routine: str | Path, args: dict[str, object] | None = None,
                 log: Callable[[str, str], None] | None = None):
        self.lab = lab
        self.path = resolve_routine(str(routine))
        self.scheduler = Scheduler(time=lab.sim.time)
        self.params: dict[str, object] = {}
        if lab.controllers and lab.controllers.config.source:
            raw = yaml.safe_load(lab.controllers.config.source.read_text()) or {}
            _flatten("", raw, self.params)
        self.log_lines: list[tuple[float, str, str]] = []
        self._sink = log
        self.context = RoutineContext(lab, self.scheduler, self.params, self._log)
        self._private = dict(args or {})
        self.error: str | None = None
        self.thread: threading.Thread | None = None

    def _log(self, level: str, text: str) -> None:
        self.log_lines.append((self.lab.sim.time, level, text))
        if self._sink:
            self._sink(level, text)

    def start(self) -> None:
        bind(self.context)
        ready = threading.Event()
        self.thread = threading.Thread(target=self._main, args=(ready,), daemon=True,
                                       name=f"routine {self.path.stem}")
        self.thread.start()
        ready.wait()

    def _main(self, ready: threading.Event) -> None:
        self.scheduler.enter()
        ready.set()
        argv = sys.argv
        try:
            name = self.path.stem
            self.context.node_name = f"/{name}"
            for key, value in self._private.items():
                key = f"/{name}/{key[1:]}" if key.startswith("_") else "/" + key.lstrip("/")
                self.params[key] = value
            runpy.run_path(str(self.path), run_name="__main__")
        except (Shutdown, KeyboardInterrupt):
            pass
        except SystemExit as exc:
            if exc.code not in (None, 0):
                self.error = f"routine exited with status {exc.code}"
        except BaseException:
            frames = traceback.format_exc().splitlines()
            # the student's frames matter, not runpy's and ours
            keep = [i for i, line in enumerate(frames) if str(self.path) in line]
            start = keep[0] if keep else 0
            self.error = "\n".join([frames[0], *frames[start:]])
        finally:
            sys.argv = argv
            self.scheduler.leave()

    @property
    def running(self) -> bool:
        return self.thread is not None and self.thread.is_alive()

    def run(self, duration: float, on_tick=None, tick: float = 0.05) -> None:
        """Simulate until the routine ends or `duration` s of sim time pass."""
        if self.thread is None:
            self.start()
        try:
            self.lab.sim.run(duration, on_tick=on_tick, tick=tick, gate=self.scheduler,
                             until=lambda: not self.scheduler.active)
        finally:
            self.stop()

    def stop(self) -> None:
        self.scheduler.stop()
        if self.thread is not None:
            self.thread.join(timeout=5.0)
        bind(None)
