"""Routines in lockstep with sim time: the machinery behind ``mexone.rospy``.

A routine runs in its own thread, as a ROS node is its own process. Whenever it waits (Rate.sleep,
rospy.sleep, wait_for_message, spin) it hands the clock to the simulation, which steps until the
earliest wake-up and hands it back. So a routine sees sim time exactly as a use_sim_time node sees
/clock, headless runs are as fast as the physics and deterministic, and GUI runs keep real time.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field

from mexone.lab import Lab

__all__ = ["Scheduler", "RoutineContext", "Shutdown", "current", "bind"]


class Shutdown(Exception):
    """The simulation ended while the routine waited (rospy raises ROSInterruptException)."""


@dataclass
class _Wait:
    wake: float
    ready: Callable[[], bool] | None = None
    released: bool = False


@dataclass
class Scheduler:
    """Implements physics.simulation.Gate for routine threads."""

    time: float = 0.0
    stopped: bool = False
    _cond: threading.Condition = field(default_factory=threading.Condition)
    _threads: set[int] = field(default_factory=set)
    _waits: dict[int, _Wait] = field(default_factory=dict)

    # ----- routine side -------------------------------------------------------------------
    def enter(self) -> None:
        with self._cond:
            self._threads.add(threading.get_ident())

    def leave(self) -> None:
        with self._cond:
            self._threads.discard(threading.get_ident())
            self._waits.pop(threading.get_ident(), None)
            self._cond.notify_all()

    def wait(self, wake: float, ready: Callable[[], bool] | None = None) -> None:
        """Block until sim time reaches `wake` or `ready()` holds (checked by the sim thread)."""
        me = threading.get_ident()
        with self._cond:
            if self.stopped:
                raise Shutdown
            entry = self._waits[me] = _Wait(wake, ready)
            self._cond.notify_all()
            self._cond.wait_for(lambda: entry.released or self.stopped)
            self._waits.pop(me, None)
            if self.stopped and not entry.released:
                raise Shutdown

    # ----- simulation side (physics.simulation.Gate) -----------------------------------------
    def horizon(self) -> float:
        with self._cond:
            self._cond.wait_for(lambda: self.stopped or all(
                tid in self._waits and not self._waits[tid].released for tid in self._threads))
            pending = [w.wake for w in self._waits.values() if not w.released]
            return min(pending, default=float("inf"))

    def advance(self, sim_time: float) -> None:
        with self._cond:
            self.time = sim_time
            for wait in self._waits.values():
                if not wait.released and (sim_time >= wait.wake - 1e-9
                                          or (wait.ready is not None and wait.ready())):
                    wait.released = True
            self._cond.notify_all()

    def stop(self) -> None:
        with self._cond:
            self.stopped = True
            self._cond.notify_all()

    @property
    def active(self) -> bool:
        with self._cond:
            return bool(self._threads)


@dataclass
class RoutineContext:
    lab: Lab
    scheduler: Scheduler
    params: dict[str, object]
    log: Callable[[str, str], None]  # (level, text)
    node_name: str = "/unnamed"
    shutdown_hooks: list[Callable[[], None]] = field(default_factory=list)
    shutdown_reason: str | None = None

    @property
    def time(self) -> float:
        return self.lab.sim.time


_context: RoutineContext | None = None


def bind(context: RoutineContext | None) -> None:
    global _context
    _context = context


def current() -> RoutineContext:
    if _context is None:
        from mexone.errors import MexoneError

        raise MexoneError("no simulation is running for this routine",
                          hint="run it with 'mexone run FILE' (or from the GUI's Routines panel)")
    return _context
