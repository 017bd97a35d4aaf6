"""How a student's process ended, in words, and where its code was: the one home of the lines
mexone prints when a student's process exits, crashes or is stopped (a controller's worker, a
routine's process).

Where: the student's process runs `faulthandler` onto a pipe mexone reads (`dump_to`): a crash
(SIGSEGV from a stack overflow, SIGFPE, SIGABRT) writes the Python stack there from C, and so
does `WHERE_SIGNAL`, which mexone sends before it ends a process that does not answer -- even
one blocked inside C code. `student_line` finds the student's file in that text.
"""

from __future__ import annotations

import contextlib
import faulthandler
import os
import re
import select
import signal
import time
from collections.abc import Callable
from pathlib import Path

__all__ = ["why_ended", "student_line", "dump_to", "read_dump", "WHERE_SIGNAL"]

WHERE_SIGNAL = signal.SIGUSR1  # mexone asks a process where it is (faulthandler answers)
_THREAD = re.compile(r"^(?:Current thread|Thread) 0x([0-9a-f]+) .*$", re.MULTILINE)
_FRAME = re.compile(r'^\s*File "(.*)", line (\d+) in ', re.MULTILINE)
_DUMP_MAX = 1 << 16  # bytes of a dump read (faulthandler writes at most 100 frames a thread)


def why_ended(status: int | None, cpu: float | None = None, whose: str = "its") -> str:
    """The words for a process's exit status (Popen's: negative for a signal): "its process
    ended (exit status 3)", "its process crashed (SIGSEGV) ...", ... `cpu`: its CPU limit, s;
    `whose`: "its", "the routine's"."""
    if status is None:
        return f"{whose} process stopped answering"
    if status >= 0:
        return f"{whose} process ended (exit status {status})"
    sig = -status
    if sig == signal.SIGXCPU:
        return f"{whose} process used more than {cpu:g} s of CPU time" if cpu else \
            f"{whose} process used up its CPU time"
    if sig == signal.SIGKILL:
        return f"{whose} process was killed (out of memory?)"
    try:
        name = signal.Signals(sig).name
    except ValueError:
        name = f"signal {sig}"
    cause = " (a stack overflow? unbounded recursion?)" if sig == signal.SIGSEGV else ""
    return f"{whose} process crashed ({name}){cause}"


def dump_to(fd: int) -> None:
    """In the student's process: a crash, and WHERE_SIGNAL, write every thread's Python stack to
    `fd` (the write end of a pipe mexone reads)."""
    faulthandler.enable(file=fd, all_threads=True)
    faulthandler.register(WHERE_SIGNAL, file=fd, all_threads=True, chain=False)


def read_dump(fd: int, timeout: float, done: Callable[[str], bool] | None = None) -> str:
    """What a process wrote on its dump pipe (its non-blocking read end): until the pipe closes
    (every writer ended), `done(text)` says enough, or `timeout` s passed."""
    chunks: list[bytes] = []
    poll = select.poll()
    poll.register(fd, select.POLLIN)
    size = 0
    deadline = time.monotonic() + timeout
    while size < _DUMP_MAX:
        left = deadline - time.monotonic()
        if left <= 0 or not poll.poll(left * 1e3):
            break
        try:
            data = os.read(fd, _DUMP_MAX - size)
        except BlockingIOError:
            continue
        except OSError:
            break
        if not data:
            break
        chunks.append(data)
        size += len(data)
        if done is not None and done(b"".join(chunks).decode(errors="replace")):
            break
    return b"".join(chunks).decode(errors="replace")


def student_line(dump: str, file: str, thread: int | None = None) -> int | None:
    """The innermost line of `file` in a faulthandler dump (each thread's frames listed most
    recent call first): in thread `thread` (threading.get_ident() there) if it is in `file`,
    else in any thread."""
    wanted = _resolved(file)
    sections = _THREAD.split(dump)  # [before, ident, frames, ident, frames, ...]
    ordered = [sections[i + 1] for i in range(1, len(sections) - 1, 2)
               if thread is not None and int(sections[i], 16) == thread]
    for text in [*ordered, dump]:
        for match in _FRAME.finditer(text):
            if match.group(1) == file or _resolved(match.group(1)) == wanted:
                return int(match.group(2))
    return None


def _resolved(path: str) -> str:
    with contextlib.suppress(OSError, ValueError):
        return str(Path(path).resolve())
    return path
