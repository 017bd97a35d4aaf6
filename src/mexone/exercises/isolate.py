"""Run a student's submission in its own process: CPU-time, memory and wall-clock limits, its
output captured, whatever it started stopped. The grading process never runs student code.

The child is never a fork of the grading process: that one holds the secret seed and draws the
hidden variation, and a fork would copy them into the student's reach. A fork server (a fresh
interpreter started once, with MuJoCo and mexone imported, nothing of a grader's) forks each run;
it gets only the call (the grader's target and its arguments, pickled, through a pipe), in its
own process group, with resource.setrlimit applied before it reads the call.
It sends back one picklable value through a pipe; anything else (a crash, os._exit, a kill by
the kernel, a hang) is a `SubmissionFailed` with one line saying why, never the grader's crash.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import os
import pickle
import resource
import select
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass

from mexone import signals
from mexone.errors import MexoneError
from mexone.routines import processes

__all__ = ["Limits", "SubmissionFailed", "run_isolated", "active_limits", "prewarm"]

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


_ACTIVE: Limits | None = None  # in an isolated child: its limits
SECRET_ENV = "MEXONE_EXERCISE_SECRET"  # a teacher's own secret (grading): never in a run's env


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
    time. `target` must be importable code of the grader's, never the student's (a function of
    a module or of the exercise's grader.py, not a lambda): it is the one that loads and runs
    the student's part. The child is forked from the fork server (a fresh interpreter with
    MuJoCo and mexone imported, never anything of a grader's): it holds only the call (target
    and arguments), never this process's state (the secret seed, the episode's seed,
    $MEXONE_EXERCISE_SECRET)."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):
            stream.flush()
    call = _call_bytes(target, args, kwargs)
    out = tempfile.TemporaryFile()  # noqa: SIM115 - closed in the finally below
    call_read, call_write = os.pipe()
    read_fd, write_fd = os.pipe()
    status_read, status_write = os.pipe()
    try:
        try:
            try:
                _server().start(limits, (call_read, write_fd, out.fileno(), status_write))
            except OSError:  # it ended meanwhile (killed?): a new one
                _server(restart=True).start(limits, (call_read, write_fd, out.fileno(),
                                                     status_write))
        finally:
            for fd in (call_read, write_fd, status_write):
                os.close(fd)
        threading.Thread(target=_write_all, args=(call_write, call), daemon=True,
                         name="isolated call").start()
        call_write = None
        pid = _read_int(status_read, timeout=60.0)
        if pid is None:
            raise MexoneError("the grader's fork server did not start the submission's process",
                              hint="see its output above; is the machine out of memory?")
        return _collect(pid, read_fd, status_read, out, limits)
    finally:
        for fd in (read_fd, status_read, call_write):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        out.close()


class _ForkServer:
    """A fresh interpreter (python -m mexone.exercises.child --server) that imports MuJoCo and
    mexone once and forks one run per request: a run costs a fork, not an interpreter's start,
    and holds nothing of the grading process's (it never forks the grader). It ends when this
    process closes its socket (ends)."""

    def __init__(self) -> None:
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        env = {k: v for k, v in os.environ.items() if k != SECRET_ENV}
        env["MEXONE_GRADER_PID"] = str(os.getpid())  # the server ends with this process
        try:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "mexone.exercises.child", "--server",
                 str(theirs.fileno())], pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL, env=env, process_group=0)
        finally:
            theirs.close()
        self.sock = ours
        self.lock = threading.Lock()

    @property
    def alive(self) -> bool:
        return self.process.poll() is None

    def start(self, limits: Limits, fds: tuple[int, int, int, int]) -> None:
        """Fork a run: (call read end, result write end, output file, status write end)."""
        request = f"{limits.cpu:g} {int(limits.memory_mb)}".encode()
        with self.lock:
            socket.send_fds(self.sock, [request], list(fds))


_servers: list[_ForkServer] = []
_servers_lock = threading.Lock()


def _server(restart: bool = False) -> _ForkServer:
    with _servers_lock:
        if restart or not _servers or not _servers[0].alive:
            if _servers:
                with contextlib.suppress(OSError):
                    _servers[0].sock.close()
            _servers[:] = [_ForkServer()]
        return _servers[0]


def prewarm() -> None:
    """Start the fork server now (it imports MuJoCo while the grader prepares the first run)."""
    _server()


def _read_int(fd: int, timeout: float) -> int | None:
    """One 4-byte integer from the run's status pipe (None: it closed, or nothing in time)."""
    data = b""
    deadline = time.monotonic() + timeout
    while len(data) < 4:
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            return None
        chunk = os.read(fd, 4 - len(data))
        if not chunk:
            return None
        data += chunk
    return struct.unpack("!i", data)[0]


def serve(fd: int) -> None:
    """The fork server's loop: one run forked per request, until the grader hangs up."""
    import mexone.lab  # noqa: F401 - what every run imports (MuJoCo), imported once
    import mexone.routines.isolated  # noqa: F401

    sock = socket.socket(fileno=fd)
    processes.die_with_parent(int(os.environ.pop("MEXONE_GRADER_PID", "0")))
    server = os.getpid()
    while True:
        with contextlib.suppress(ChildProcessError):
            while os.waitpid(-1, os.WNOHANG)[0] > 0:  # the monitors that ended
                pass
        if not select.select([sock], [], [], 0.5)[0]:
            continue
        request, fds, _, _ = socket.recv_fds(sock, 256, 4)
        if not request:
            os._exit(0)
        if len(fds) != 4:
            for x in fds:
                os.close(x)
            continue
        if os.fork() == 0:
            sock.close()
            _monitor(fds, server, *request.decode().split())
        for x in fds:
            os.close(x)


def _monitor(fds: list[int], server: int, cpu: str, memory_mb: str) -> None:
    """Between the fork server and one run: forks the run (its own process group), tells the
    grader its pid, waits for it and tells the grader how it ended."""
    call_fd, result_fd, out_fd, status_fd = fds
    code = 0
    try:
        processes.die_with_parent(server)
        monitor = os.getpid()
        pid = os.fork()
        if pid == 0:
            processes.die_with_parent(monitor)
            os.setpgid(0, 0)
            os.close(status_fd)
            null = os.open(os.devnull, os.O_RDONLY)
            os.dup2(null, 0)
            os.dup2(out_fd, 1)
            os.dup2(out_fd, 2)
            for x in (null, out_fd):
                os.close(x)
            child_main([str(call_fd), str(result_fd), cpu, memory_mb])
        with contextlib.suppress(OSError):
            os.setpgid(pid, pid)
        for x in (call_fd, result_fd, out_fd):
            os.close(x)
        os.write(status_fd, struct.pack("!i", pid))
        _, status = os.waitpid(pid, 0)
        os.write(status_fd, struct.pack("!i", status))
    except BaseException:  # noqa: BLE001 - the grader sees the pipe close
        code = 3
    finally:
        os._exit(code)


def _call_bytes(target: Callable, args: tuple, kwargs: dict) -> bytes:
    """What the child needs to make the call: this process's sys.path, the target's module
    (a grader.py is loaded from its file) and the call, pickled by reference."""
    module = sys.modules.get(getattr(target, "__module__", None) or "")
    modules = []
    if module is not None and getattr(module, "__file__", None):
        modules.append((module.__name__, module.__file__))
    payload = pickle.dumps((target, args, kwargs), protocol=pickle.HIGHEST_PROTOCOL)
    return pickle.dumps((list(sys.path), modules, payload), protocol=pickle.HIGHEST_PROTOCOL)


def _write_all(fd: int, data: bytes) -> None:
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]
    except OSError:
        pass  # the child ended before reading it: _collect says why
    finally:
        os.close(fd)


def child_main(argv: list[str]) -> None:
    """The child (python -m mexone.exercises.child CALL_FD RESULT_FD CPU MB): limits first,
    then the call, then one pickled ("ok", value) or ("failed", reason) to RESULT_FD."""
    call_fd, write_fd, cpu, memory_mb = argv[:4]
    write_fd = int(write_fd)
    limits = Limits(cpu=float(cpu), memory_mb=int(memory_mb))
    code = 0
    try:
        sys.stdout.reconfigure(line_buffering=True)
        sys.stderr.reconfigure(line_buffering=True)
        _limit(limits)
        global _ACTIVE
        _ACTIVE = limits
        try:
            target, args, kwargs = _read_call(int(call_fd))
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


def _read_call(fd: int) -> tuple:
    chunks = []
    while chunk := os.read(fd, 1 << 16):
        chunks.append(chunk)
    os.close(fd)
    path, modules, payload = pickle.loads(b"".join(chunks))
    sys.path.extend(p for p in path if p not in sys.path)
    for name, file in modules:
        if name in sys.modules:
            continue
        try:
            importlib.import_module(name)
        except ImportError:  # a grader.py, known by its file
            spec = importlib.util.spec_from_file_location(name, file)
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            spec.loader.exec_module(module)
    return pickle.loads(payload)


def active_limits() -> Limits:
    """The limits of the isolated child this code runs in (Limits() outside one): what a
    routine's own process started from there gets too."""
    return _ACTIVE or Limits()


def _collect(pid: int, fd: int, status_fd: int, out, limits: Limits):
    deadline = time.monotonic() + limits.time
    chunks: list[bytes] = []
    status = None
    timed_out = False
    while status is None:
        if signals.requested():  # Ctrl-C or SIGTERM to the grader: the run ends with it
            _kill(pid)
            signals.check()
        left = deadline - time.monotonic()
        if left <= 0:
            timed_out = True
            _signal_group(pid)
            status = _read_int(status_fd, timeout=10.0)
            if status is None:
                status = signal.SIGKILL
            break
        ready = select.select([fd, status_fd], [], [], min(left, 0.05))[0]
        if fd in ready:
            data = os.read(fd, 1 << 16)
            if data:
                chunks.append(data)
                continue
        if status_fd in ready:
            status = _read_int(status_fd, timeout=10.0)
            if status is None:
                status = signal.SIGKILL
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
