"""`mexone run`'s process boundary: the run is a child process in its own process group, and the
`mexone` process the user started only supervises it.

The supervisor forwards Ctrl-C, SIGTERM and SIGHUP to the run (which stops its routine and prints
its report, as before), returns the run's exit status, and at the end stops every process the
run left: its group and, as a subreaper on Linux, any process that left the group (setsid, a
double fork). A run that ends without saying it got to its end (a routine's posix._exit, a
segfault, SIGKILL, an exec) is one line on stderr and exit 1, never a silent 0.

The child is a fork of the supervisor after the verbs are imported (MuJoCo, numpy, ...): a
millisecond, where a fresh interpreter (multiprocessing's spawn or forkserver) would import
them all again (about a second). It forks before any thread starts or the lab is built.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import select
import signal
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from mexone import signals
from mexone.routines import processes

__all__ = ["fork_run", "ended", "leave", "available", "END_GRACE", "EXEC_GRACE"]

END_GRACE = 10.0  # s the run may take to exit after its end (it only prints and exits then)
EXEC_GRACE = 1.0  # s the run may live on after closing its end of the pipe: else it exec'd
_POLL = 0.02  # s between looks at the run
_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n))
_PR_SET_PDEATHSIG = 1
_PR_SET_CHILD_SUBREAPER = 36


@dataclass
class _Child:
    pid: int
    fd: int  # write end of the pipe to the supervisor


_child: _Child | None = None  # set in the run's process
_forked_by: int | None = None  # the pid that forked the run (set in both processes)


def available() -> bool:
    """The sandbox applies in a `mexone` command's own process (never to a library caller of
    mexone.cli.main, whose code must not go on in a second process) where fork exists."""
    main = sys.modules.get("__main__")
    spec = getattr(main, "__spec__", None)
    as_cli = (spec is not None and spec.name in ("mexone", "mexone.__main__")) or \
        Path(sys.argv[0]).name == "mexone"
    return as_cli and hasattr(os, "fork") and hasattr(os, "setpgid")


def ended() -> None:
    """In the run: it got to its end (its report is printed, or its error is on the way out)."""
    if _child is not None and _child.pid == os.getpid() and _child.fd >= 0:
        with contextlib.suppress(OSError):
            os.write(_child.fd, b"end\n")
            os.close(_child.fd)
        _child.fd = -1


def leave(status: int) -> None:
    """End this process now with `status` if it is the supervisor or the run (both are the
    `mexone` command's own, their output flushed, their files closed): the interpreter's
    teardown of MuJoCo, numpy and the rest costs up to a second, twice. Else return."""
    if _forked_by is None or os.getpid() not in (_forked_by, getattr(_child, "pid", None)):
        return
    ended()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):
            stream.flush()
    os._exit(status)


def fork_run() -> int | None:
    """Fork the run. In the run (the child, in its own process group) return None: it goes on.
    In the supervisor, wait for it, stop whatever it left, and return the exit status."""
    global _child, _forked_by
    for stream in (sys.stdout, sys.stderr):  # else the child prints what was buffered again
        with contextlib.suppress(OSError, ValueError):
            stream.flush()
    _become_subreaper()
    read_fd, write_fd = os.pipe()
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, _SIGNALS)  # none lands between fork and setup
    _forked_by = os.getpid()
    try:
        pid = os.fork()
    except BaseException:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        raise
    if pid == 0:
        os.close(read_fd)
        with contextlib.suppress(OSError):
            os.setpgid(0, 0)
        _prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)  # a supervisor killed (-9) stops the run too
        if os.getppid() != _forked_by:  # it was, before that
            os._exit(128 + signal.SIGTERM)
        _child = _Child(os.getpid(), write_fd)
        _no_terminal_input()
        signals.stop_on_signals()  # fork gave the child default dispositions: the run stops cleanly
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        return None
    os.close(write_fd)
    with contextlib.suppress(OSError):
        os.setpgid(pid, pid)  # as the child does: whichever runs first
    watch = _Watch(pid, read_fd)
    previous = {s: signal.getsignal(s) for s in _SIGNALS}
    for signum, handler in previous.items():
        if handler is not signal.SIG_IGN:  # nohup's stays ignored
            signal.signal(signum, watch.on_signal)
    signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    try:
        return watch.run()
    finally:
        for signum, handler in previous.items():
            if handler is not None:
                signal.signal(signum, handler)
        os.close(read_fd)


def _no_terminal_input() -> None:
    """The run is not the terminal's foreground group: reading the terminal would stop it
    (SIGTTIN) for good. A routine reads an empty stdin instead (input() raises EOFError)."""
    with contextlib.suppress(OSError, ValueError):
        if os.isatty(0):
            null = os.open(os.devnull, os.O_RDONLY)
            os.dup2(null, 0)
            os.close(null)


def _become_subreaper() -> None:
    """Linux: orphans of the run (a process it started whose parent ended) come to us, not to
    init, so they can be found and stopped at the end."""
    _prctl(_PR_SET_CHILD_SUBREAPER, 1)


def _prctl(option: int, value: int) -> None:
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(option, value, 0, 0, 0)


@dataclass
class _Watch:
    pid: int
    fd: int
    signals: list[int] = field(default_factory=list)  # received, not yet forwarded
    first_signal: int | None = None
    ended_at: float | None = None
    closed_at: float | None = None
    killed: str | None = None  # why the supervisor ended the run itself

    def on_signal(self, signum: int, _frame) -> None:
        self.signals.append(signum)  # only recorded: the loop forwards it

    def run(self) -> int:
        status = self._wait()
        line, code = self._outcome(status)
        left = self._stop_leftovers()
        if left:
            shown = ", ".join(left[:3]) + (f" and {len(left) - 3} more" if len(left) > 3 else "")
            print(f"mexone: the routine left {'a process' if len(left) == 1 else 'processes'} "
                  f"running after the run ({shown}): mexone stopped "
                  f"{'it' if len(left) == 1 else 'them'}", file=sys.stderr)
            code = code or 1
        if line:
            print(f"mexone: {line}", file=sys.stderr)
        return code

    def _wait(self) -> int:
        while True:
            while self.signals:
                signum = self.signals.pop(0)
                self.first_signal = self.first_signal or signum
                with contextlib.suppress(ProcessLookupError):
                    os.kill(self.pid, signum)
            done, status = os.waitpid(self.pid, os.WNOHANG)
            if done:
                return status
            readable = [self.fd] if self.closed_at is None else []
            if select.select(readable, [], [], _POLL)[0]:
                data = os.read(self.fd, 64)
                if not data:
                    self.closed_at = time.monotonic()
                elif b"end" in data and self.ended_at is None:
                    self.ended_at = time.monotonic()
            now = time.monotonic()
            if self.killed is not None:
                continue  # killed: waitpid has its status next
            if self.ended_at is not None and now - self.ended_at > END_GRACE:
                self._kill("hung")
            elif self.ended_at is None and self.closed_at is not None and \
                    now - self.closed_at > EXEC_GRACE:
                self._kill("exec")

    def _kill(self, why: str) -> None:
        if why == "exec":
            why = f"exec:{processes.describe(self.pid)}"
        self.killed = why
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self.pid, signal.SIGKILL)
        with contextlib.suppress(ProcessLookupError):
            os.kill(self.pid, signal.SIGKILL)

    def _outcome(self, status: int) -> tuple[str | None, int]:
        """The line (None: the run said all) and exit status for how the run ended."""
        if self.killed == "hung":
            return (f"the run did not exit within {END_GRACE:g} s of its end (a thread the "
                    "routine started kept it alive?): mexone stopped it"), 1
        if self.killed is not None:
            program = self.killed.removeprefix("exec:")
            return (f"the routine replaced the run's process with another program ({program}): "
                    "no report; mexone stopped it (start a program with subprocess)"), 1
        if os.WIFEXITED(status):
            code = os.WEXITSTATUS(status)
            if self.ended_at is not None or (self.first_signal and code == 128 + self.first_signal):
                return None, code  # its report, or its line for the signal forwarded to it
            return (f"the routine ended the run's process (exit status {code}) before its "
                    "report: no tracking report (end a routine by returning, or with "
                    "sys.exit(n))"), 1
        signum = os.WTERMSIG(status)
        name = _signal_name(signum)
        if signum == self.first_signal:  # ours, forwarded, and the run did not catch it
            return f"interrupted by {name}", 128 + signum
        cause = ("by the routine, another program or the kernel's out-of-memory killer"
                 if signum == signal.SIGKILL else "a crash in the routine or a library it called")
        return f"the run's process was killed by {name} ({cause}): no tracking report", 1

    def _stop_leftovers(self) -> list[str]:
        """Stop the run's process group and every process below us (orphans came to us, the
        subreaper); lines naming those that still ran."""
        if _nothing_left(self.pid):
            return []
        procs = processes.table()
        me = os.getpid()
        pids = sorted(set(processes.group(self.pid, procs)) | set(processes.descendants(me, procs)))
        running = [pid for pid in pids if pid != me and procs[pid].running]
        shown = [processes.describe(pid) for pid in running]
        if running:
            processes.stop(running)
        if not procs:  # no /proc: the group is all there is to end
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(self.pid, signal.SIGKILL)
        processes.reap_zombies()
        return shown


def _nothing_left(pgid: int) -> bool:
    """No process in the run's group and no child of ours (an orphan would be one): the usual
    end, told without reading the whole process table."""
    try:
        os.killpg(pgid, 0)
        return False
    except ProcessLookupError:
        pass
    except PermissionError:
        return False
    try:
        os.waitpid(-1, os.WNOHANG)  # an orphan that ended is reaped; the scan finds the rest
    except ChildProcessError:
        return True
    return False


def _signal_name(signum: int) -> str:
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"
