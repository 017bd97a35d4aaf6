"""The routine sandbox inside the lab's process: whatever a routine does to the process it shares
with the simulation ends the routine with one clear error, never the lab, and nothing it starts
outlives it. What a routine's code (its file's frames, in any thread) may not do:

- `os._exit(n)` or `os.exec*()`: they would end or replace the lab's process (the GUI's too).
  They raise RoutineExit there instead: the routine ends with that error.
- `os.fork()`: the copy has only the forking thread, not the simulation. The fork is an error of
  the routine; the copy ends at its first rospy call (runtime.Forked) or when the routine's code
  returns, and if it runs on, it is stopped with the routine.
- a thread it started that raises: an error of the routine (a ROS node's thread prints a
  traceback and the node goes on; here the run goes on and then fails with the traceback).
- a program it started and left running: stopped when the routine ends (with its children),
  an error of the routine. A thread it started and left running is stopped then too (a
  warning): in the GUI it would run on in the lab's process.

`sys.exit(0)` (or `sys.exit()`) ends a routine like returning; `sys.exit(n)` with n != 0 is its
error. `mexone run` adds the process boundary (routines.supervisor): what no guard here catches
(posix._exit, a segfault, SIGKILL, a process that detaches) ends that run with one line too.
"""

from __future__ import annotations

import contextlib
import os
import runpy
import sys
import threading
import traceback
from collections.abc import Callable
from pathlib import Path
from types import TracebackType

import mexone
from mexone.routines import processes, runtime
from mexone.routines.runtime import Forked, RoutineContext, Shutdown

__all__ = ["RoutineExit", "install", "run_path", "routine_of_caller", "students_traceback",
           "stop_children", "stop_threads"]

_PACKAGE = str(Path(mexone.__file__).resolve().parent)
_GUARDED = ("_exit", "execv", "execve")  # os.execl/execlp/execvp/... all end in execv or execve
_real: dict[str, Callable] = {}  # the os functions guarded, as they were


class RoutineExit(BaseException):
    """A routine tried to end or replace the lab's process; it ends instead, with this error.
    A BaseException, so the routine's `except Exception` cannot swallow it."""


def install() -> None:
    """Guard this process (code outside routines is not affected): os._exit and os.exec*
    called from a routine's code raise RoutineExit, a fork from it is recorded, and a thread it
    started that raises becomes its error."""
    if not _real:
        for name in _GUARDED:
            _real[name] = original = getattr(os, name)
            setattr(os, name, _guard(name, original))
        os.register_at_fork(after_in_parent=_forked)
    if not getattr(threading.excepthook, "mexone_sandbox", False):  # again if someone put theirs
        previous = threading.excepthook

        def hook(args) -> None:
            _thread_raised(args, previous)

        hook.mexone_sandbox = True
        threading.excepthook = hook


def routine_of_caller(depth: int = 2, guess: bool = False) -> RoutineContext | None:
    """The routine whose code is calling (its thread, or one of its frames in a thread it
    started), in the process that has its simulation; None for everything else. With `guess`,
    a thread other than the main one while exactly one routine runs is that routine's (a thread
    whose target is os._exit itself has no frame of the routine's)."""
    context = getattr(runtime._local, "context", None)
    if context is not None:
        return context if context.scheduler.pid == os.getpid() else None
    context = _routine_in(_frames(sys._getframe(depth)))
    if context is None and guess and threading.current_thread() is not threading.main_thread():
        running = [c for c in list(runtime._active) if c.scheduler.pid == os.getpid()]
        context = running[0] if len(running) == 1 else None
    return context


def _frames(frame) -> list[str]:
    files = []
    while frame is not None:
        files.append(frame.f_code.co_filename)
        frame = frame.f_back
    return files


def _routine_in(files: list[str]) -> RoutineContext | None:
    sources = {c.source: c for c in list(runtime._active) if c.source}
    for name in files:
        context = sources.get(name)
        if context is not None and context.scheduler.pid == os.getpid():
            return context
    return None


def _guard(name: str, original: Callable) -> Callable:
    def guarded(*args, **kwargs):
        context = routine_of_caller(guess=True)
        if context is None:
            return original(*args, **kwargs)
        shown = repr(args[0]) if args else ""
        if name == "_exit":
            message = (f"the routine called os._exit({shown}), which would end the lab with it: "
                       "the routine was stopped there (end a routine by returning, or with "
                       "sys.exit(n))")
        else:
            message = (f"the routine called os.{name}({shown}, ...), which would replace the "
                       "lab's process: the routine was stopped there (start a program with "
                       "subprocess)")
        if getattr(runtime._local, "context", None) is None:  # a thread the routine started
            name_ = threading.current_thread().name
            context.errors.append(f"{message} (in thread '{name_}', which the routine started)")
        raise RoutineExit(message)

    guarded.__name__ = guarded.__qualname__ = name
    guarded.__doc__ = original.__doc__
    return guarded


def _forked() -> None:
    """After os.fork(), in the parent: a fork from a routine's code is that routine's error."""
    files = _frames(sys._getframe(1))
    if any(name.endswith("subprocess.py") for name in files):
        return  # Popen(preexec_fn=...): the copy execs a program at once
    context = routine_of_caller(depth=3)
    message = ("the routine forked the lab's process (os.fork): the copy has no simulation (use "
               "a thread, or subprocess for a program); the copy was ended with the routine")
    if context is not None and message not in context.errors:
        context.errors.append(message)


def _thread_raised(args, previous) -> None:
    """threading.excepthook: an exception in a thread running a routine's code is the routine's
    error; every other thread's goes to the hook there was."""
    files = []
    tb = args.exc_traceback
    while tb is not None:
        files.append(tb.tb_frame.f_code.co_filename)
        tb = tb.tb_next
    if issubclass(args.exc_type, RoutineExit | Shutdown):
        return  # its guard recorded it; mexone stopped the thread (the routine had ended)
    context = _routine_in(files)
    if context is None:
        previous(args)
        return
    if issubclass(args.exc_type, SystemExit):
        return  # sys.exit ends a thread
    name = args.thread.name if args.thread is not None else "?"
    shown = students_traceback(args.exc_value, Path(context.source), args.exc_traceback)
    context.errors.append(f"in thread '{name}', which the routine started:\n{shown}")


def students_traceback(exc: BaseException, path: Path, tb: TracebackType | None = None) -> str:
    """`exc`'s traceback with only the student's frames: not runpy's, threading's or mexone's."""
    tb = exc.__traceback__ if tb is None else tb
    frames = [f for f in traceback.extract_tb(tb)
              if f.filename == str(path) or not (f.filename.startswith(_PACKAGE)
                                                 or f.filename.endswith(("runpy.py", "threading.py"))
                                                 or "<frozen runpy>" in f.filename)]
    lines = ["Traceback (most recent call last):\n", *traceback.format_list(frames),
             *traceback.format_exception_only(type(exc), exc)]
    return "".join(lines).rstrip()


def run_path(path: Path) -> None:
    """Run the routine's file as __main__. In a process the routine forked, the routine's end
    (or its first rospy call) ends that process: it has no simulation to go back to."""
    pid = os.getpid()
    try:
        runpy.run_path(str(path), run_name="__main__")
    except BaseException as exc:
        if os.getpid() == pid:
            raise
        _end_fork(exc, path)
    if os.getpid() != pid:
        _end_fork(None, path)


def _end_fork(exc: BaseException | None, path: Path) -> None:
    if isinstance(exc, Forked):
        line, code = (f"mexone: process {os.getpid()}, which the routine forked, called rospy: "
                      "only the routine's own process has the simulation; it ends"), 1
    elif exc is None or (isinstance(exc, SystemExit) and exc.code in (None, 0)):
        line, code = None, 0
    elif isinstance(exc, KeyboardInterrupt):  # stopped with the routine (SIGTERM)
        line, code = None, 1
    elif isinstance(exc, SystemExit) and isinstance(exc.code, int):
        line, code = None, exc.code
    else:
        last = students_traceback(exc, path).splitlines()[-1]
        line, code = f"mexone: process {os.getpid()}, which the routine forked: {last}", 1
    if line:
        print(line, file=sys.stderr)
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):
            stream.flush()
    _real.get("_exit", os._exit)(code)


def stop_children(before: set[int]) -> list[str]:
    """End the child processes of this process that were not there `before` (a routine's
    programs and forks), with everything they started; one line for each that still ran."""
    new = sorted(processes.children() - before)
    if not new:
        return []
    procs = processes.table()
    shown = {pid: processes.describe(pid) for pid in new}
    alive = processes.children()  # not one that was ending by itself meanwhile
    lines = [f"the routine left process {shown[pid]} running: mexone stopped it" for pid in new
             if pid in alive]
    tree = [pid for root in new for pid in (root, *processes.descendants(root, procs))]
    processes.stop(tree)
    return lines


def stop_threads(context: RoutineContext) -> list[str]:
    """Interrupt the threads still running the routine's code (threads it started and left
    running; its own thread the scheduler stops); one line for each."""
    me = threading.get_ident()
    names = {t.ident: t.name for t in threading.enumerate()}
    lines = []
    for tid, frame in sys._current_frames().items():
        if tid != me and tid in names and context.source in _frames(frame):
            runtime._interrupt(tid)
            lines.append(f"the routine left thread '{names[tid]}' running: mexone stopped it")
    return lines
