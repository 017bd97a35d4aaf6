"""Routines in lockstep with sim time: the machinery behind ``mexone.rospy``.

A routine runs in its own thread, as a ROS node is its own process; several can run at once.
Whenever one waits (Rate.sleep, rospy.sleep, wait_for_message, spin) it hands the clock to the
simulation, which steps until the earliest wake-up and hands it back. Messages for a routine's
subscribers are queued and delivered in the routine's own thread while it waits, so student code
never runs in the simulation thread. A headless run is as fast as the physics and deterministic;
a GUI run keeps real time. A routine that stops yielding (a loop without rate.sleep(), a long
time.sleep) is abandoned after `stall` seconds of wall time instead of freezing the lab; mexone's
own long computations (reach's IK) say so with `busy()` and are not mistaken for one.
A process the routine forks has no simulation (only the thread that forked is copied): its first
rospy call ends it (`Forked`), instead of waiting forever for a clock nobody advances.
"""

from __future__ import annotations

import ctypes
import math
import os
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from mexone.errors import MexoneError

if TYPE_CHECKING:  # a routine's own process (routines.remote) has no lab: no MuJoCo to import
    from mexone.lab import Lab

__all__ = ["Scheduler", "RoutineContext", "Shutdown", "Forked", "current", "bind", "busy",
           "STALL_SECONDS", "BUSY_SECONDS"]

STALL_SECONDS = 5.0  # wall seconds a routine may compute without yielding to the simulation
BUSY_SECONDS = 120.0  # wall seconds one of mexone's own computations (busy()) may take at most
_POLL = 0.05  # wall seconds the simulation waits for routines before returning to its caller


class Shutdown(BaseException):
    """The simulation ended (or gave up on the routine) while it ran or waited; rospy raises
    ROSInterruptException. A BaseException, so a routine's `except Exception` cannot swallow it."""


class Forked(Shutdown):
    """A process the routine forked called rospy: only the routine's own process has the
    simulation (a fork copies the forking thread alone), so the copy ends (routines.sandbox)."""


@dataclass
class RoutineContext:
    """One routine: its lab, its node name and parameters, its mailbox and its log."""

    lab: Lab
    scheduler: Scheduler
    params: dict[str, object]
    log: Callable[[str, str], None]  # (level, text)
    node_name: str = "/unnamed"
    shutdown_hooks: list[Callable[[], None]] = field(default_factory=list)
    shutdown_reason: str | None = None
    mailbox: deque[tuple[Callable, object]] = field(default_factory=deque)
    abandoned: str | None = None  # why the simulation stopped waiting for it
    warned_topics: set[str] = field(default_factory=set)
    notices: list[str] = field(default_factory=list)  # mexone's own warnings (unheard topics)
    source: str = ""  # the routine's file: its frames tell its threads from the lab's own
    errors: list[str] = field(default_factory=list)  # found besides its own end (a thread raised)
    # `_x:=v` arguments (~x: v), kept under the node's name, init_node's as in rospy
    private: dict[str, object] = field(default_factory=dict)
    name_remap: str | None = None  # `__name:=n`: init_node's name is n (as rosrun)
    # what a library the routine calls keeps for this routine's life (motion's IK), by library
    kept: dict[str, object] = field(default_factory=dict)

    @property
    def time(self) -> float:
        return self.lab.sim.time

    def deliver(self, callback: Callable, msg: object) -> None:
        """Queue a message for one of this routine's subscribers (from any thread)."""
        self.mailbox.append((callback, msg))

    def run_callbacks(self) -> None:
        """Run queued subscriber callbacks, in the routine's thread."""
        while self.mailbox:
            callback, msg = self.mailbox.popleft()
            callback(msg)


@dataclass
class _Wait:
    wake: float
    ready: Callable[[], bool] | None = None
    released: bool = False


@dataclass
class _Thread:
    context: RoutineContext
    running_since: float | None = None  # wall time it last got the clock (None: it waits)
    wait: _Wait | None = None
    busy: list[str] = field(default_factory=list)  # mexone's computations running (busy())
    native: int = 0  # the OS's thread id (its scheduler statistics)
    queued: tuple[float, float | None] | None = None  # (running_since, run queue wait then)


def _queued(native: int) -> float | None:
    """s the thread has waited, runnable, for a CPU the machine gave others (Linux's
    schedstat), or None where that is not known."""
    try:
        with open(f"/proc/self/task/{native}/schedstat") as stats:
            return int(stats.read().split()[1]) / 1e9
    except (OSError, ValueError, IndexError):
        return None


class Scheduler:
    """Implements physics.simulation.Gate for the routine threads of one lab."""

    def __init__(self, time: float = 0.0, stall: float = STALL_SECONDS, poll: float = _POLL):
        self.time = time
        self.stall = stall
        self.poll = poll
        self.stopped = False
        self._cond = threading.Condition()
        self._threads: dict[int, _Thread] = {}
        self.stalled: list[str] = []  # messages about routines given up on
        self.pid = os.getpid()  # the process with the simulation (a fork of it has none)

    # ----- routine side ------------------------------------------------------------------------
    def enter(self, context: RoutineContext) -> None:
        with self._cond:
            self._threads[threading.get_ident()] = _Thread(context, time.perf_counter(),
                                                          native=threading.get_native_id())

    def leave(self) -> None:
        with self._cond:
            self._threads.pop(threading.get_ident(), None)
            self._cond.notify_all()

    def wait(self, wake: float, ready: Callable[[], bool] | None = None) -> None:
        """Block until sim time reaches `wake` or `ready()` holds, running this routine's
        subscriber callbacks as their messages arrive."""
        if os.getpid() != self.pid:
            raise Forked  # before touching a lock another thread may have held at the fork
        me = threading.get_ident()
        if math.isnan(wake):
            raise ValueError("cannot wait until a NaN time")
        while True:
            with self._cond:
                entry = self._threads.get(me)
                if self.stopped or entry is None:
                    raise Shutdown
                context = entry.context
            context.run_callbacks()
            if (ready is not None and ready()) or self.time >= wake - 1e-9:
                return
            with self._cond:
                if self.stopped or me not in self._threads:
                    raise Shutdown
                waiting = entry.wait = _Wait(wake, ready)
                entry.running_since = None
                self._cond.notify_all()
                self._cond.wait_for(lambda w=waiting: w.released or self.stopped
                                    or me not in self._threads)
                entry.wait = None
                entry.running_since = time.perf_counter()
                if self.stopped or me not in self._threads:
                    raise Shutdown

    # ----- simulation side (physics.simulation.Gate) -------------------------------------------
    def _all_waiting(self) -> bool:
        return self.stopped or all(t.wait is not None and not t.wait.released
                                   for t in self._threads.values())

    def horizon(self) -> float | None:
        with self._cond:
            if not self._cond.wait_for(self._all_waiting, timeout=self.poll):
                self._abandon_stalled()
                return None
            if self.stopped:  # the routines are ending: none of them gates the simulation now
                return math.inf
            now = []
            for t in self._threads.values():
                due = t.context.mailbox or (t.wait.ready is not None and t.wait.ready())
                now.append(self.time if due else t.wait.wake)
            return min(now, default=math.inf)

    def advance(self, sim_time: float) -> None:
        with self._cond:
            self.time = sim_time
            for t in self._threads.values():
                wait = t.wait
                if wait is not None and not wait.released and (
                        sim_time >= wait.wake - 1e-9 or t.context.mailbox
                        or (wait.ready is not None and wait.ready())):
                    wait.released = True
            self._cond.notify_all()

    def _abandon_stalled(self) -> None:
        """Give up on routines that have not yielded for `stall` s: the simulation goes on.
        The time a routine waited, runnable, while the machine ran other processes is not its
        own: on a loaded machine it is discounted (measured from the first poll that sees the
        routine running, 50 ms after it got the clock), so a watchdog meant for a routine's own
        loop does not abandon one the machine starved."""
        now = time.perf_counter()
        for tid, t in list(self._threads.items()):
            limit = BUSY_SECONDS if t.busy else self.stall
            if t.running_since is None:
                continue
            queued = _queued(t.native)
            if t.queued is None or t.queued[0] != t.running_since:  # first seen running: from now
                t.queued = (t.running_since, queued)
                continue
            ran = now - t.running_since
            if queued is not None and t.queued[1] is not None:
                ran -= queued - t.queued[1]
            if ran > limit:
                reason = (f"mexone's {t.busy[-1]} ran for {limit:g} s without yielding to the "
                          "simulation (a mexone bug: please report it)" if t.busy else
                          f"routine did not yield to the simulation for {self.stall:g} s "
                          "(call rate.sleep())")
                t.context.abandoned = reason
                self.stalled.append(reason)
                del self._threads[tid]
                _interrupt(tid)
        self._cond.notify_all()

    def stop(self) -> None:
        """End every routine: those waiting wake to Shutdown; those running their own code (a
        busy loop that never yields) are interrupted, so no thread spins on after Stop."""
        with self._cond:
            self.stopped = True
            for tid, t in self._threads.items():
                if t.running_since is not None:
                    _interrupt(tid)
            self._cond.notify_all()

    @property
    def active(self) -> bool:
        with self._cond:
            return bool(self._threads)

    @contextmanager
    def busy(self, what: str) -> Iterator[None]:
        """The calling routine thread runs one of mexone's own computations: the watchdog allows
        it BUSY_SECONDS, not `stall`, and the routine's own clock starts again after it."""
        with self._cond:
            entry = self._threads.get(threading.get_ident())
            if entry is not None:
                entry.busy.append(what)
        try:
            yield
        finally:
            if entry is not None:
                with self._cond:
                    entry.busy.pop()
                    if entry.running_since is not None:
                        entry.running_since = time.perf_counter()


def _interrupt(thread_id: int) -> None:
    """Raise Shutdown in a routine thread at its next Python instruction (a busy loop ends; a
    blocking call such as time.sleep ends when it returns)."""
    ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(thread_id), ctypes.py_object(Shutdown))


_local = threading.local()
_active: list[RoutineContext] = []  # routines running in this process, for threads they start


def bind(context: RoutineContext | None) -> None:
    """Make `context` the current routine of this thread (None: unbind)."""
    if context is None:
        old = getattr(_local, "context", None)
        if old in _active:
            _active.remove(old)
    else:
        _active.append(context)
    _local.context = context


def current() -> RoutineContext:
    """This thread's routine; in a thread the routine started itself, the only routine running."""
    context = getattr(_local, "context", None)
    if context is None and len(_active) == 1:
        context = _active[0]
    if context is None:
        raise MexoneError("no simulation is running for this routine",
                          hint="run it with 'mexone run FILE' (or from the GUI's Routines panel)")
    if os.getpid() != context.scheduler.pid:
        raise Forked
    return context


@contextmanager
def busy(what: str) -> Iterator[None]:
    """`with busy("reach's IK"):` -- mexone's own long computation in a routine (many IK
    restarts on a loaded machine take seconds of wall time without yielding): the routine
    watchdog must not take it for a student's busy loop. Outside a routine it does nothing."""
    context = getattr(_local, "context", None)
    if context is None:
        yield
        return
    with context.scheduler.busy(what):
        yield
