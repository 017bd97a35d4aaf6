"""Run a student's submission in its own process: CPU-time, memory and wall-clock limits, its
output captured, whatever it started stopped. The grading process never runs student code.

The child is a fork of the grading process (MuJoCo and numpy already imported: a millisecond),
in its own process group, with resource.setrlimit applied before anything of the student's runs.
It sends back one picklable value through a pipe; anything else (a crash, os._exit, a kill by
the kernel, a hang) is a `SubmissionFailed` with one line saying why, never the grader's crash.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import resource
import select
import signal
import sys
import tempfile
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass

from mexone.routines import processes

__all__ = ["Limits", "SubmissionFailed", "run_isolated"]

TRACEBACK = "Traceback (most recent call last):"
OUTPUT_TAIL = 1500  # characters of the submission's own output kept for the report


@dataclass(frozen=True)
class Limits:
    """What one isolated run may use: wall seconds, CPU seconds, address space in MB."""

    time: float = 30.0
    cpu: float = 60.0
    memory_mb: int = 2048


class SubmissionFailed(Exception):  # noqa: N818 - it is what happened to the submission
    """The submission could not be graded: its reason is shown to the student (0 points)."""

    def __init__(self, reason: str, output: str = ""):
        super().__init__(reason)
        self.reason = reason
        self.output = output


def _limit(limits: Limits) -> None:
    cpu = max(1, int(limits.cpu))
    resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 1))
    mem = int(limits.memory_mb) * 1024 * 1024
    with contextlib.suppress(ValueError, OSError):
        resource.setrlimit(resource.RLIMIT_AS, (mem, mem))
    with contextlib.suppress(ValueError, OSError):
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))


def run_isolated(target: Callable, *args, limits: Limits = Limits(), **kwargs):
    """`target(*args, **kwargs)` in a child process under `limits`; its return value (picklable).
    Raises SubmissionFailed(reason) if it raised, ended the process, was killed or ran out of
    time. `target` must be importable code of the grader's, never the student's: it is the one
    that loads and runs the student's part."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):
            stream.flush()
    out = tempfile.TemporaryFile()  # noqa: SIM115 - closed in the finally below
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: never returns
        os.close(read_fd)
        code = 0
        try:
            os.setpgid(0, 0)
            null = os.open(os.devnull, os.O_RDONLY)
            os.dup2(null, 0)
            os.dup2(out.fileno(), 1)
            os.dup2(out.fileno(), 2)
            sys.stdout = open(1, "w", buffering=1, closefd=False)  # noqa: SIM115 - the fd's
            sys.stderr = open(2, "w", buffering=1, closefd=False)  # noqa: SIM115 - the fd's
            _limit(limits)
            try:
                payload = ("ok", target(*args, **kwargs))
                for stream in (sys.stdout, sys.stderr):  # its output, before it is judged
                    with contextlib.suppress(Exception):
                        stream.flush()
            except SubmissionFailed as exc:
                payload = ("failed", exc.reason)
            except MemoryError:
                payload = ("failed", f"ran out of memory (the limit is {limits.memory_mb} MB)")
            except BaseException as exc:  # noqa: BLE001 - reported as the submission's failure
                last = traceback.format_exception_only(type(exc), exc)[-1].strip()
                payload = ("failed", f"the grader could not run the submission: {last}")
            data = pickle.dumps(payload)
            view = memoryview(data)
            while view:
                view = view[os.write(write_fd, view):]
        except BaseException:  # noqa: BLE001
            code = 3
        finally:
            for stream in (sys.stdout, sys.stderr):
                with contextlib.suppress(Exception):
                    stream.flush()
            os._exit(code)
    os.close(write_fd)
    with contextlib.suppress(OSError):
        os.setpgid(pid, pid)
    try:
        return _collect(pid, read_fd, out, limits)
    finally:
        os.close(read_fd)
        out.close()


def _collect(pid: int, fd: int, out, limits: Limits):
    deadline = time.monotonic() + limits.time
    chunks: list[bytes] = []
    status = None
    timed_out = False
    while status is None:
        left = deadline - time.monotonic()
        if left <= 0:
            timed_out = True
            _signal_group(pid)
            try:
                _, status = os.waitpid(pid, 0)
            except ChildProcessError:  # reaped already
                status = signal.SIGKILL
            break
        if select.select([fd], [], [], min(left, 0.05))[0]:
            data = os.read(fd, 1 << 16)
            if data:
                chunks.append(data)
                continue
        done, st = os.waitpid(pid, os.WNOHANG)
        if done:
            status = st
    while data := _read_rest(fd):
        chunks.append(data)
    _kill(pid)  # whatever it left in its group
    output = _tail(out)
    if timed_out:
        raise SubmissionFailed(f"exceeded the time limit of {limits.time:g} s (a loop that never "
                               "ends, or too slow)", output)
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        if sig == signal.SIGXCPU:
            why = f"used more than {limits.cpu:g} s of CPU time"
        elif sig == signal.SIGKILL:
            why = "was killed (out of memory?)"
        else:
            why = f"crashed ({_signal_name(sig)})"
        raise SubmissionFailed(f"the submission {why}", output)
    if not chunks:
        code = os.WEXITSTATUS(status) if os.WIFEXITED(status) else -1
        raise SubmissionFailed(f"the submission ended the grading process (exit status {code}) "
                               "before its result", output)
    try:
        kind, value = pickle.loads(b"".join(chunks))
    except Exception:  # noqa: BLE001 - a truncated result is the submission's doing
        raise SubmissionFailed("the submission's run ended before its result was sent",
                               output) from None
    if kind == "failed":
        raise SubmissionFailed(value, output)
    if TRACEBACK in output:  # it caught its own error and printed it: a crash all the same
        last = [line for line in output.splitlines() if line.strip()][-1].strip()
        raise SubmissionFailed(f"the submission printed a traceback ({last[:200]})", output)
    return value


def _read_rest(fd: int) -> bytes:
    if select.select([fd], [], [], 0)[0]:
        with contextlib.suppress(OSError):
            return os.read(fd, 1 << 16)
    return b""


def _signal_group(pid: int) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pid, signal.SIGKILL)
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGKILL)


def _kill(pid: int) -> None:
    """End the run's process group: whatever the submission started goes with it."""
    _signal_group(pid)
    with contextlib.suppress(Exception):
        left = processes.group(pid)
        if left:
            processes.stop(left)


def _tail(out) -> str:
    with contextlib.suppress(OSError):
        out.seek(0, os.SEEK_END)
        size = out.tell()
        out.seek(max(0, size - OUTPUT_TAIL))
        return out.read().decode("utf-8", "replace")
    return ""


def _signal_name(signum: int) -> str:
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"
