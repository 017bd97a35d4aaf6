"""Ctrl-C, SIGTERM and SIGHUP stop a run once, at a point of mexone's choosing; a file being
finished is never cut short.

The CLI calls `stop_on_signals()` before anything else. The handler only records the request
(the first signal, for the exit code 128 + N): it never raises. A handler that raised landed
wherever Python happened to be -- a weakref callback, a `__del__` -- where the exception is
printed as "Exception ignored" and dropped, and a `mexone sim` kept simulating for 40 minutes
after a SIGTERM. Every long-running loop instead asks `requested()` at its natural points (a
tick of sim time, a frame of the GUI, a finished sweep run, a residual evaluation) and ends
cleanly; `check()` raises `Stop` (a KeyboardInterrupt) from mexone's own code where unwinding
is the clean way out.

The handler sets no threading.Event: `Event.set` takes the Event's lock, and a handler runs in
the main thread between two bytecodes, possibly while that same thread holds the lock inside
`Event.wait` -- a deadlock. Loops poll a plain attribute instead (they wake at least every
frame or tick, well under the 5 s a stop may take).

A second signal within GRACE of the first (a double Ctrl-C) is the same stop. One that comes
later while nothing is being written (`hold`, `finishing`) ends the process at once: a stop
that hangs is still ended by pressing Ctrl-C again. While a recording is open or a file is being
finished, it only says so: a bag's closing is never cut short.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field

__all__ = ["Stop", "stop_on_signals", "requested", "check", "exit_code", "hold", "release",
           "finishing", "uninterrupted", "ignore_from_now", "leave_to_parent", "interrupted",
           "final_status", "recover"]

SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP")
                if hasattr(signal, name))
GRACE = 1.0  # s after the first signal in which another one (a double Ctrl-C) is the same stop


class Stop(KeyboardInterrupt):
    """A signal asked the run to stop; raised by `check()` in mexone's own code, never by the
    handler (so it is a KeyboardInterrupt: every `except Exception` lets it through)."""


@dataclass
class _State:
    installed: bool = False  # the CLI's handlers are in place (not a library user's process)
    first: int | None = None  # the first signal received, for the exit code
    at: float = 0.0  # when it came (time.monotonic)
    finishing: int = 0  # files being finished right now
    held: list[str] = field(default_factory=list)  # recordings open
    pending: int | None = None  # library user's process: a signal deferred by finishing()
    noted: bool = False
    wakeup: int | None = None  # read end of the signal wakeup pipe (recover())


_state = _State()


def _say(text: str) -> None:
    """One line on stderr without Python's buffered stderr (whose lock the interrupted code may
    hold: print() from a handler can raise 'reentrant call')."""
    with suppress(OSError):
        os.write(2, f"mexone: {text}\n".encode())


def _on_signal(signum: int, _frame) -> None:
    """Record; never raise. (Runs in the main thread between two bytecodes of whatever it was
    doing, which may be a weakref callback or a __del__.)"""
    state = _state
    if not state.installed:  # inside finishing() in a library user's process: deliver later
        if state.pending is None:
            state.pending = signum
        return
    now = time.monotonic()
    if state.first is None:
        state.first, state.at = signum, now
        return
    if now - state.at < GRACE:
        return
    if state.finishing or state.held:
        if not state.noted:
            state.noted = True
            what = state.held[-1] if state.held else "a file"
            _say(f"still stopping: closing {what}, one moment (kill -9 abandons it)")
        return
    _say(f"stopping took too long; ended by a second {signal.Signals(signum).name}")
    os._exit(128 + state.first)


def stop_on_signals() -> None:
    """Make SIGINT, SIGTERM and SIGHUP request a stop (main thread only). A signal the parent
    set to be ignored (nohup, a background job) stays ignored."""
    if threading.current_thread() is not threading.main_thread():
        return
    for signum in SIGNALS:
        current = signal.getsignal(signum)
        if current is signal.SIG_IGN:
            continue
        signal.signal(signum, _on_signal)
    _state.installed = True
    if _state.wakeup is None:  # the C-level record of every signal (recover())
        read, write = os.pipe()
        os.set_blocking(read, False)
        os.set_blocking(write, False)
        try:
            signal.set_wakeup_fd(write, warn_on_full_buffer=False)
        except ValueError:  # another fd is set (an event loop's): leave it to its owner
            os.close(read)
            os.close(write)
        else:
            _state.wakeup = read
            os.register_at_fork(after_in_child=_forget_wakeup)


def _forget_wakeup() -> None:
    """A forked child's signals are its own: its handler must not write into its parent's pipe."""
    if _state.wakeup is None:
        return
    try:
        signal.set_wakeup_fd(-1)  # only the main thread may (a fork from another keeps it)
    except ValueError:
        return
    _state.wakeup = None


def recover() -> None:
    """Record a signal the handler never saw. An asynchronous exception pending in the main
    thread (a controller's hang watchdog interrupting an update blocked in C) is raised at the
    handler's first bytecode, before it records anything: Python's C-level handler has written
    the signal to the wakeup pipe all the same. Call it where such an exception is caught."""
    state = _state
    if state.wakeup is None:
        return
    try:
        data = os.read(state.wakeup, 512)
    except (BlockingIOError, OSError):
        return
    if state.first is None:
        for signum in data:
            if signum in SIGNALS:
                state.first, state.at = signum, time.monotonic()
                break


def requested() -> bool:
    """A signal asked the run to stop (cheap: an attribute; call it every tick)."""
    return _state.first is not None


def check() -> None:
    """Raise Stop if a signal asked the run to stop: for straight-line work between loops (the
    verbs' start-up, a bench's measurements, a fit's residual evaluations)."""
    if _state.first is not None:
        raise Stop(f"interrupted by {signal.Signals(_state.first).name}")


def interrupted() -> int:
    """Say that a signal stopped the run (one line) and return its exit status, 128 + n."""
    code = exit_code()
    print(f"mexone: interrupted by {signal.Signals(code - 128).name}", file=sys.stderr)
    return code


def final_status(code: int) -> int:
    """A verb's status as the process reports it: a verb that returned 0 after a signal stopped
    it early (its outputs written) ends with 130/143, as the README's rule says."""
    return interrupted() if code == 0 and requested() else code


def leave_to_parent() -> None:
    """In a pool's worker (a sweep's runs): SIGTERM ends it at once (its parent stops it that
    way) and SIGINT, which a terminal sends to the whole process group, is left to the parent,
    which stops its workers itself."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _after_fork_in_child() -> None:
    """fork copies the handlers: a child with ours would record SIGTERM and carry on. It gets
    the default dispositions (what an exec'd program gets too) and a fresh record."""
    global _state
    if not _state.installed:
        return
    _state = _State()
    try:
        for signum in SIGNALS:
            if signal.getsignal(signum) is _on_signal:
                signal.signal(signum, signal.SIG_DFL)
    except ValueError:  # not the main thread: keep ours, which now only record
        pass


os.register_at_fork(after_in_child=_after_fork_in_child)


def ignore_from_now() -> None:
    """The CLI is returning after a signal: nothing is left to stop, and a late second signal
    must not end a clean exit early."""
    if _state.first is not None and threading.current_thread() is threading.main_thread():
        for signum in SIGNALS:
            if signal.getsignal(signum) is _on_signal:
                signal.signal(signum, signal.SIG_IGN)


def exit_code() -> int:
    """128 + the signal number, as a shell reports a process a signal ended (130 for Ctrl-C)."""
    return 128 + (_state.first or signal.SIGINT)


def hold(name: str) -> None:
    """A recording is open: after the first signal, further ones must not end the process."""
    _state.held.append(name)


def release(name: str) -> None:
    if name in _state.held:
        _state.held.remove(name)


class _Uninterrupted:
    """`with signals.uninterrupted:` -- a write that a second signal must not cut short; cheap
    enough for every message a recorder writes."""

    def __enter__(self) -> None:
        _state.finishing += 1

    def __exit__(self, *_exc) -> None:
        _state.finishing -= 1


uninterrupted = _Uninterrupted()


@contextmanager
def finishing() -> Iterator[None]:
    """No signal interrupts the block (closing a bag, renaming it into place). In the CLI no
    signal interrupts anything anyway; in a library user's process, where the signals are not
    ours (Python's own SIGINT raises KeyboardInterrupt anywhere), one that arrives meanwhile is
    deferred, then re-delivered to the user's handlers when the block ends."""
    state = _state
    swapped = {}
    if not state.installed and threading.current_thread() is threading.main_thread():
        swapped = {s: signal.getsignal(s) for s in SIGNALS
                   if signal.getsignal(s) not in (signal.SIG_IGN, None)}
        for signum in swapped:
            signal.signal(signum, _on_signal)
    try:
        with uninterrupted:
            yield
    finally:
        if swapped:
            for signum, handler in swapped.items():
                signal.signal(signum, handler)
            pending, state.pending = state.pending, None
            if pending is not None:
                signal.raise_signal(pending)  # to the handler the library user had
