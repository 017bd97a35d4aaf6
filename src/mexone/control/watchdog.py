"""The watchdog over a student's code in the simulation thread: an update past its hang_timeout,
and importing the student's file, creating, configuring and activating the controller past
STUDENT_SETUP_TIMEOUT, are interrupted (PyThreadState_SetAsyncExc raises ControllerHang in that
thread at its next bytecode), so a student's infinite loop never freezes the lab: the controller
faults, or the load or Reload is refused with one line, and the lab runs on."""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import sys
import threading
import time
import traceback
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING

from mexone.ranges import number_text

try:
    import resource
except ImportError:  # Windows: no /proc either, so `sched` says None
    resource = None  # type: ignore[assignment]  # the standard optional-module idiom

if TYPE_CHECKING:
    from mexone.control.controllers.python import PythonRunner

__all__ = ["ControllerHang", "Watched", "GUARD", "STUDENT_SETUP_TIMEOUT", "where_running",
           "sched", "own_time", "Sched", "SchedOf"]

log = logging.getLogger("mexone.control")
# wall s for importing a student's file or creating/configuring/activating the controller: a
# module may import python-control or scipy and a configure may design an LQR, so far more than
# an update's hang_timeout; an infinite loop there still ends, and the lab with it runs on
STUDENT_SETUP_TIMEOUT = 30.0


class ControllerHang(BaseException):
    """Raised inside a student's code that ran past its time (a BaseException, so the student's
    own `except Exception` does not swallow it)."""

    def __str__(self) -> str:
        return "did not finish in time: interrupted by mexone's watchdog"


@dataclass(frozen=True)
class Watched:
    """What the watchdog names when it interrupts something other than an update."""

    label: str  # "controller 'arm'", "controller type 'my_pd/MyPd'"
    file: str  # the student's file (the line it is stuck on is looked up there)
    doing: str  # "import", "configure", ...
    timeout: float | None = None  # s; None: STUDENT_SETUP_TIMEOUT


class _HangGuard:
    """One watchdog thread: interrupts a student's update that has not returned after its
    hang_timeout, or a Watched setup past its timeout. It lives only while student code runs:
    idle for half a second, it ends. Entries are tracked per thread (two labs may step in two
    threads).

    PythonRunner.update inlines `enter` and `leave` (a few stores per update, the framework's
    cost of a Python controller): `entries`, `lock` and `injected` are the parts it touches, in
    the same order as these two methods."""

    _IDLE = 0.5  # s without updates after which the thread ends
    _POLL = 0.05  # s

    def __init__(self) -> None:
        self.lock = threading.Lock()  # the watchdog thread's and `leave`'s: never replaced
        # thread -> (since, runner or Watched) of the student's code in progress there
        self.entries: dict[int, tuple[float, PythonRunner | Watched]] = {}
        self.injected: set[int] = set()  # threads interrupted, their exception not yet withdrawn
        self.running = False  # the watchdog thread runs
        self.last = 0.0  # perf_counter() of the last enter: the thread ends _IDLE s after

    def enter(self, runner: PythonRunner | Watched, now: float) -> int:
        """A PythonRunner's update (or a Watched setup) starts in this thread (`now`:
        time.perf_counter()); returns the thread's id for `leave`."""
        self.last = now
        tid = _thread_id()
        self.entries[tid] = (now, runner)
        if not self.running:
            self.start()
        return tid

    def start(self) -> None:
        """Start the watchdog thread (an entry was just made and it was not running)."""
        self.running = True
        threading.Thread(target=self._watch, daemon=True, name="mexone controller watchdog").start()

    def leave(self, tid: int | None = None) -> bool:
        """The update returned (in thread `tid`, default this one); True if the watchdog had
        interrupted it (the pending exception is withdrawn: it must not land in the manager)."""
        if tid is None:
            tid = _thread_id()
        with self.lock:
            self.entries.pop(tid, None)
            if tid not in self.injected:
                return False
            self.withdraw(tid)
        return True

    def withdraw(self, tid: int) -> None:
        """Withdraw the ControllerHang injected into thread `tid` (with `lock` held): its code
        returned meanwhile, so the exception must not land in the caller."""
        self.injected.discard(tid)
        ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(tid), None)

    @contextmanager
    def watching(self, watched: Watched) -> Iterator[None]:
        """Student code other than an update, under the watchdog: ControllerHang is raised in it
        after `watched.timeout` s. A block inside another (an import inside a configure) leaves
        the outer one watched as it was."""
        tid = _thread_id()
        outer = self.entries.get(tid)
        if outer is not None:  # already watched: the outer entry's time runs on
            yield
            return
        self.enter(watched, time.perf_counter())
        try:
            yield
        finally:
            self.leave(tid)

    @staticmethod
    def _describe(what: PythonRunner | Watched) -> tuple[str, str, str, float]:
        if isinstance(what, Watched):
            timeout = STUDENT_SETUP_TIMEOUT if what.timeout is None else what.timeout
            return what.label, what.file, what.doing, timeout
        return f"controller '{what.name}'", what.plugin.file, "update", what.plugin.hang_timeout

    def _watch(self) -> None:
        said_stuck: set[tuple[int, float]] = set()
        while True:
            time.sleep(self._POLL)
            said: list[tuple[str, tuple[str, ...]]] = []
            with self.lock:
                now = time.perf_counter()
                if not self.entries:
                    said_stuck.clear()
                    if now - self.last > self._IDLE:
                        self.running = False
                        if not self.entries:
                            return
                        self.running = True
                    continue
                for tid, (since, what) in list(self.entries.items()):
                    label, file, doing, timeout = self._describe(what)
                    if now - since < timeout:
                        continue
                    where = where_running(tid, file)
                    if tid not in self.injected:
                        self.injected.add(tid)
                        ctypes.pythonapi.PyThreadState_SetAsyncExc(
                            ctypes.c_ulong(tid), ctypes.py_object(ControllerHang))
                        said.append(("%s: %s has not returned for %s s (%s): interrupting it",
                                     (label, doing, number_text(round(now - since, 2)), where)))
                    elif now - since > 2 * timeout + 1.0 and (tid, since) not in said_stuck:
                        said_stuck.add((tid, since))
                        said.append(("%s: %s cannot be interrupted: it is blocked outside Python "
                                     "(%s); the lab is frozen: press Ctrl-C twice to end it",
                                     (label, doing, where)))
            for text, args in said:  # outside the lock: a log handler may take its time
                log.error(text, *args)


def where_running(tid: int, file: str) -> str:
    """file:line where thread `tid` runs now, in `file` if it is there."""
    frame = sys._current_frames().get(tid)
    stack = traceback.extract_stack(frame) if frame is not None else []
    ours = [f for f in stack if f.filename == file]
    frame_info = ours[-1] if ours else (stack[-1] if stack else None)
    return f"{frame_info.filename}:{frame_info.lineno}" if frame_info else file


_schedstat: dict[int, int] = {}  # thread -> its open /proc schedstat

# (CPU s, s waited for a CPU, times it blocked) of a thread so far, as the kernel counts them:
# its CPU-time clock (exact; schedstat's figure is as of its last tick or switch, up to 4 ms
# behind), schedstat's wait, its voluntary context switches (a sleep, a lock, I/O)
Sched = tuple[float, float, int]


def sched() -> Sched | None:
    """The calling thread's `Sched` (CPU s, s waited for a CPU, times it blocked) so far; None
    where unknown. What tells a loaded or stalled machine's share of a wall time from the
    code's own (`own_time`)."""
    tid = threading.get_native_id()
    fd = _schedstat.get(tid)
    try:
        if fd is None:
            fd = _schedstat[tid] = os.open("/proc/thread-self/schedstat", os.O_RDONLY)
        fields = os.pread(fd, 100, 0).split()
        return (time.thread_time(), int(fields[1]) / 1e9,
                resource.getrusage(resource.RUSAGE_THREAD).ru_nvcsw)
    except (OSError, ValueError, IndexError, AttributeError):
        stale = _schedstat.pop(tid, None)
        if stale is not None:  # a thread of that id that has ended
            with contextlib.suppress(OSError):
                os.close(stale)
        return None


def own_time(elapsed: float, before: Sched | None, after: Sched | None, blocks: int = 0,
             also_waited: float = 0.0) -> float:
    """The part of an update's `elapsed` wall s that was the code's own, from its thread's
    `Sched` `before` and `after` it: its CPU time if it did not block (no more than `blocks`
    voluntary switches: a worker's wait for the next request), whatever else the wall time
    holds (waits for a CPU, and a virtual CPU its host stopped, steal time, which the kernel
    counts nowhere else); else the wall time less its waits for a CPU and `also_waited` (a
    worker's caller's: a sleep is the code's own), never less than its CPU time (the two waits
    may overlap: woken on its caller's CPU, a worker runs while the caller waits). `elapsed`
    where the kernel does not say (every overrun counts)."""
    if before is None or after is None:
        return elapsed
    cpu, waited = after[0] - before[0], after[1] - before[1]
    if after[2] - before[2] <= blocks:
        return cpu
    return max(cpu, elapsed - waited - also_waited)


GUARD = _HangGuard()
_thread_id = threading.get_ident





class SchedOf:
    """`sched` of another process, as the kernel counts it (its main thread's /proc schedstat,
    readable by any user; the CPU time of all its threads, every one the student's): what
    excuses a worker's slow update on a loaded machine is measured here, never a number the
    student's process reports (it could make one up)."""

    def __init__(self, pid: int):
        self.pid = pid
        self._cpu_clock = (~pid << 3) | 2  # Linux's CPU-time clock of process `pid` (CPUCLOCK_SCHED)
        self._fd: int | None = None
        self._status: int | None = None
        try:
            self._fd = os.open(f"/proc/{pid}/schedstat", os.O_RDONLY)
            self._status = os.open(f"/proc/{pid}/status", os.O_RDONLY)
        except OSError:
            self.close()  # the one opened, if any

    def __call__(self) -> Sched | None:
        """The process's main thread's schedstat so far (None where unknown)."""
        if self._fd is None or self._status is None:
            return None
        try:
            fields = os.pread(self._fd, 100, 0).split()
            status = os.pread(self._status, 4096, 0)
            at = status.index(b"\nvoluntary_ctxt_switches:") + 25
            return (time.clock_gettime(self._cpu_clock), int(fields[1]) / 1e9,
                    int(status[at:status.index(b"\n", at)]))
        except (OSError, ValueError, IndexError):
            return None

    def close(self) -> None:
        """Close its /proc file (the process ended, or another took its place)."""
        for fd in (self._fd, self._status):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._fd = self._status = None
