"""Ctrl-C, SIGTERM and SIGHUP stop a run once; a file being finished is never cut short.

The CLI calls `stop_on_signals()` before anything else. The first signal raises KeyboardInterrupt
in the main thread, so a verb unwinds through its `finally` blocks and closes its bag. While a
recording is open (`hold`), later signals do not interrupt that unwinding: a second Ctrl-C 0-60 ms
after the first used to cut a bag's closing short and leave it unreadable. While a file is being
finished (`finishing`), even the first signal waits until it is done.
"""

from __future__ import annotations

import signal
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

__all__ = ["stop_on_signals", "exit_code", "hold", "release", "finishing", "uninterrupted",
           "ignore_from_now"]

SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP")
                if hasattr(signal, name))
GRACE = 1.0  # s after the first signal in which another one (a double Ctrl-C) is not a new stop


@dataclass
class _State:
    installed: bool = False
    first: int | None = None  # the first signal received, for the exit code
    raised_at: float | None = None  # when KeyboardInterrupt was raised: the run is unwinding
    finishing: int = 0  # files being finished right now
    held: list[str] = field(default_factory=list)  # recordings open
    pending: int | None = None  # a signal that waited for a file to be finished
    noted: bool = False


_state = _State()


def _on_signal(signum: int, _frame) -> None:
    state = _state
    if state.first is None:
        state.first = signum
    unwinding = state.raised_at is not None
    recent = unwinding and time.monotonic() - state.raised_at < GRACE
    if state.finishing or (unwinding and (state.held or recent)):
        if not unwinding and state.pending is None:
            state.pending = signum
        if unwinding and state.held and not state.noted:
            state.noted = True
            print(f"mexone: still stopping: closing {state.held[-1]}, one moment "
                  "(kill -9 abandons it)", file=sys.stderr, flush=True)
        return
    state.raised_at = time.monotonic()  # the first, or one long after it: a stop that hangs
    raise KeyboardInterrupt


def stop_on_signals() -> None:
    """Make SIGINT, SIGTERM and SIGHUP end the run like Ctrl-C (main thread only). A signal the
    parent set to be ignored (nohup, a background job) stays ignored."""
    if threading.current_thread() is not threading.main_thread():
        return
    for signum in SIGNALS:
        current = signal.getsignal(signum)
        if current is signal.SIG_IGN:
            continue
        signal.signal(signum, _on_signal)
    _state.installed = True


def ignore_from_now() -> None:
    """The CLI is returning after a signal: nothing is left to stop, and a late second Ctrl-C
    must not turn a clean exit into a KeyboardInterrupt traceback (exit -2)."""
    if _state.first is not None and threading.current_thread() is threading.main_thread():
        for signum in SIGNALS:
            if signal.getsignal(signum) is _on_signal:
                signal.signal(signum, signal.SIG_IGN)


def exit_code() -> int:
    """128 + the signal number, as a shell reports a process a signal ended (130 for Ctrl-C)."""
    return 128 + (_state.first or signal.SIGINT)


def hold(name: str) -> None:
    """A recording is open: after the first signal, further ones must not interrupt its closing."""
    _state.held.append(name)


def release(name: str) -> None:
    if name in _state.held:
        _state.held.remove(name)


def _deliver_pending() -> None:
    """A signal waited for a file to be finished: now it stops the run (once)."""
    state = _state
    if state.pending is None or state.finishing:
        return
    state.pending = None
    if state.raised_at is None:
        state.raised_at = time.monotonic()
        raise KeyboardInterrupt


class _Uninterrupted:
    """`with signals.uninterrupted:` -- cheap enough for every message a recorder writes (a
    KeyboardInterrupt inside the mcap library's record writing leaves a corrupt record)."""

    def __init__(self, deliver: bool = True):
        self.deliver = deliver  # False: the caller re-delivers to a library user's handlers

    def __enter__(self) -> None:
        _state.finishing += 1

    def __exit__(self, *_exc) -> None:
        _state.finishing -= 1
        if self.deliver and _state.pending is not None:
            _deliver_pending()


uninterrupted = _Uninterrupted()


@contextmanager
def finishing() -> Iterator[None]:
    """No signal interrupts the block (closing a bag, renaming it into place); one that arrives
    meanwhile is delivered when the block ends. Also in a library user's process, where the
    signals are not ours: there they are deferred, then re-delivered to the user's handlers."""
    state = _state
    swapped = {}
    if not state.installed and threading.current_thread() is threading.main_thread():
        swapped = {s: signal.getsignal(s) for s in SIGNALS
                   if signal.getsignal(s) not in (signal.SIG_IGN, None)}
        for signum in swapped:
            signal.signal(signum, _on_signal)
    try:
        with _Uninterrupted(deliver=not swapped):
            yield
    finally:
        if swapped:
            for signum, handler in swapped.items():
                signal.signal(signum, handler)
            pending, state.pending, state.first = state.pending, None, None
            if pending is not None:
                signal.raise_signal(pending)  # to the handler the library user had
