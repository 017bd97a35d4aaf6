"""The process table, for ending what a routine started: a process's children, descendants and
group, and stopping them (SIGTERM, then SIGKILL). Linux reads /proc; elsewhere the table is empty
and only a process group can be ended (os.killpg)."""

from __future__ import annotations

import contextlib
import os
import select
import signal
import time
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Proc", "table", "children", "descendants", "group", "describe", "stop",
           "reap_zombies", "die_with_parent", "STOP_GRACE"]

STOP_GRACE = 1.0  # s a process gets to end on SIGTERM before SIGKILL
_PROC = Path("/proc")


@dataclass(frozen=True)
class Proc:
    pid: int
    ppid: int
    pgrp: int
    state: str  # "Z": a zombie, which has ended (only its exit status waits to be read)

    @property
    def running(self) -> bool:
        return self.state not in ("Z", "X")


def _read(pid: int) -> Proc | None:
    try:
        stat = (_PROC / str(pid) / "stat").read_text()
    except (FileNotFoundError, ProcessLookupError, PermissionError):
        return None
    # pid (comm) state ppid pgrp ...: comm may hold spaces and parentheses
    fields = stat[stat.rindex(")") + 2:].split()
    return Proc(pid, int(fields[1]), int(fields[2]), fields[0])


def table() -> dict[int, Proc]:
    """Every process visible now (empty without /proc)."""
    out = {}
    if not _PROC.is_dir():
        return out
    for entry in _PROC.iterdir():
        if entry.name.isdigit() and (proc := _read(int(entry.name))) is not None:
            out[proc.pid] = proc
    return out


def children(pid: int | None = None) -> set[int]:
    """The running child processes of `pid` (default: this process)."""
    pid = os.getpid() if pid is None else pid
    tasks = _PROC / str(pid) / "task"
    try:  # the kernel's own list, per thread (CONFIG_PROC_CHILDREN): no scan of every process
        listed = {int(c) for t in tasks.iterdir() for c in (t / "children").read_text().split()}
        return {c for c in listed if (proc := _read(c)) is not None and proc.running}
    except (FileNotFoundError, NotADirectoryError, ProcessLookupError, PermissionError):
        return {p.pid for p in table().values() if p.ppid == pid and p.running}


def descendants(root: int, procs: dict[int, Proc] | None = None) -> list[int]:
    """Every process below `root` (children, their children, ...), running or not."""
    procs = table() if procs is None else procs
    below: dict[int, list[int]] = {}
    for p in procs.values():
        below.setdefault(p.ppid, []).append(p.pid)
    out, todo = [], list(below.get(root, []))
    while todo:
        pid = todo.pop()
        out.append(pid)
        todo += below.get(pid, [])
    return out


def group(pgid: int, procs: dict[int, Proc] | None = None) -> list[int]:
    procs = table() if procs is None else procs
    return [p.pid for p in procs.values() if p.pgrp == pgid]


def describe(pid: int) -> str:
    """'1234 (sleep 1000)': the process and its command line, shortened."""
    try:
        words = (_PROC / str(pid) / "cmdline").read_bytes().split(b"\0")
        text = " ".join(w.decode(errors="replace") for w in words if w)
    except OSError:
        text = ""
    text = text if len(text) <= 60 else text[:57] + "..."
    return f"{pid} ({text})" if text else str(pid)


def _gone(pid: int) -> bool:
    """Ended (reaped here if it is this process's child)."""
    try:
        done, _ = os.waitpid(pid, os.WNOHANG)
        if done:
            return True
    except ChildProcessError:  # not ours: look it up
        proc = _read(pid)
        return proc is None or not proc.running
    return False


def stop(pids: list[int], grace: float = STOP_GRACE) -> None:
    """End these processes: SIGTERM (and SIGCONT, for a stopped one), SIGKILL those still
    there after `grace` s; this process's own children among them are reaped."""
    for sig in (signal.SIGTERM, signal.SIGCONT):
        for pid in pids:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, sig)
    end = time.monotonic() + grace
    left = [pid for pid in pids if not _gone(pid)]
    while left and time.monotonic() < end:
        select.select([], [], [], 0.02)  # poll: they are not our children to wait on
        left = [pid for pid in left if not _gone(pid)]
    for pid in left:
        try:
            os.kill(pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            continue
    end = time.monotonic() + grace
    while left and time.monotonic() < end:
        left = [pid for pid in left if not _gone(pid)]
        if left:
            select.select([], [], [], 0.01)


def reap_zombies() -> None:
    """Read the exit status of every child that has ended (orphans handed to a subreaper)."""
    while True:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if not pid:
            return


def die_with_parent(parent: int) -> None:
    """Linux: this process gets SIGKILL when its parent (the thread that started it) ends, so a
    chain of them (a grader's fork server, a run, a routine's process) ends with the grader
    even when it is killed; if `parent` has ended already, this process ends now. Elsewhere:
    nothing."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:
        os.kill(os.getpid(), signal.SIGKILL)
