"""Graded runs, out of the grading process: the simulator, where no student code runs, and the
jail, where a student's part runs. The grading process never runs student code and reads
nothing from a run but JSON checked against a schema (mexone.sandbox.wire).

Both kinds of run are forks of a fork server: a fresh interpreter started once per grading,
with MuJoCo and mexone imported and nothing of a grader's (no secret in its environment, no
seed, no exercise), so a run costs a fork, not an interpreter's start.

- `run_trusted(target, ...)`: the **simulator**. `target` (the grader's function: build a lab,
  simulate, measure) runs in the fork itself, under an audit hook that refuses to execute code
  from any file outside Python's installation, mexone and the grader's own folder: a student's
  routine or controller in the lab it builds runs in a jail of its own (the routine's process,
  the controller's worker), and what `target` returns is what the simulator measured.
- `run_jailed(target, ...)` (`run_isolated`): the **jail**. The fork confines itself as
  mexone.sandbox says (namespaces, another uid, Landlock, seccomp, limits) before it runs
  `target`, which loads the student's part (an `estimate(bag)` function, a URDF); its files are
  copies in the jail's scratch folder. What it returns is the student's own answer.

What comes back is `target`'s return value as JSON, read against its return annotation (no
annotation: plain JSON). A run that raises, ends, hangs, is killed or sends what does not fit is
a `SubmissionFailed` with one line saying why, never the grader's crash.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import json
import math
import os
import pickle
import select
import shutil
import signal
import socket
import struct
import subprocess
import sys
import sysconfig
import tempfile
import threading
import time
import traceback
import typing
from collections.abc import Callable
from pathlib import Path

from mexone import signals
from mexone.control import worker as controller_worker
from mexone.errors import MexoneError
from mexone.routines import processes
from mexone.sandbox import Jail, Limits, StudentProcess, confine, isolation, spawn, trust, wire
from mexone.sandbox.spawn import (
    SECRET_ENV,
    Forked,
    environment,
    forget_probe,
    jail_plan,
    prepare,
    probe_now,
)
from mexone.sandbox.trust import UntrustedCode

__all__ = ["Limits", "SubmissionFailed", "run_isolated", "run_jailed", "run_trusted",
           "active_limits", "prewarm", "UntrustedCode", "SECRET_ENV"]

TRACEBACK = "Traceback (most recent call last):"
OUTPUT_TAIL = 1500  # characters of the submission's own output kept for the report
END_GRACE = 3.0  # s a run's relay gets to end its jail before it is killed


class SubmissionFailed(Exception):  # noqa: N818 - it is what happened to the submission
    """The submission could not be graded: its reason is shown to the student (0 points)."""

    def __init__(self, reason: str, output: str = ""):
        super().__init__(reason)
        self.reason = reason
        self.output = output


_ACTIVE: Limits | None = None  # in a run: its limits
DEFAULTS = Limits()


def run_trusted(target: Callable, *args, limits: Limits = DEFAULTS, **kwargs):
    """`target(*args, **kwargs)` in the simulator (see the module's docstring); its return
    value, read against its return annotation. `target` is importable code of the grader's
    (a function of a module or of the exercise's grader.py, not a lambda)."""
    return _run(target, args, kwargs, limits, None)


def run_jailed(target: Callable, *args, limits: Limits = DEFAULTS,
               readable: tuple[Path, ...] = (), **kwargs):
    """`target(*args, **kwargs)` in a jail (see the module's docstring); its return value, read
    against its return annotation. A `Path` among the arguments is copied into the jail's
    scratch folder and `target` gets the copy; `readable` folders it may read as they are."""
    jail = Jail(limits=limits, readable=tuple(readable), another_user=True)
    work, scratch, root, _, slot = prepare(jail)
    try:
        inputs = scratch / "inputs"
        inputs.mkdir()
        args = tuple(_copied(a, inputs, k) for k, a in enumerate(args))
        kwargs = {k: _copied(v, inputs, k) for k, v in kwargs.items()}
        if slot is not None:
            for folder, dirs, files in os.walk(scratch):
                for name in (folder, *(os.path.join(folder, f) for f in dirs + files)):
                    with contextlib.suppress(OSError):
                        os.chown(name, slot.uid, slot.uid, follow_symlinks=False)
        plan = jail_plan(jail, scratch, root, slot)
        plan.parent = 0  # the run's monitor, which the run itself fills in
        return _run(target, args, kwargs, limits, plan)
    finally:
        if slot is not None:
            slot.release()
        shutil.rmtree(work, ignore_errors=True)


run_isolated = run_jailed  # the name graders used: the student's part in a process of its own


def _copied(value: object, folder: Path, key: object) -> object:
    """A Path argument's copy in the jail's inputs (a folder of its own per argument)."""
    if not isinstance(value, Path):
        return value
    own = folder / str(key)
    own.mkdir()
    target = own / value.name
    if value.is_dir():
        shutil.copytree(value, target, symlinks=False)
    elif value.is_file():
        shutil.copyfile(value, target)
    else:
        return value
    for path in (own, target, *(target.rglob("*") if target.is_dir() else ())):
        with contextlib.suppress(OSError):
            os.chmod(path, 0o755 if path.is_dir() else 0o644)
    return target


def _run(target: Callable, args: tuple, kwargs: dict, limits: Limits,
         plan: confine.Plan | None):
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):
            stream.flush()
    returns = _returns(target)
    call = _call_bytes(target, args, kwargs)
    out = tempfile.TemporaryFile()  # noqa: SIM115 - closed in the finally below
    call_read, call_write = os.pipe()
    read_fd, write_fd = os.pipe()
    status_read, status_write = os.pipe()
    request = json.dumps({"cpu": limits.cpu, "memory_mb": int(limits.memory_mb),
                          "plan": None if plan is None else plan.dumps()}).encode()
    try:
        try:
            try:
                _server().start(request, (call_read, write_fd, out.fileno(), status_write))
            except OSError:  # it ended meanwhile (killed?): a new one
                _server(restart=True).start(request, (call_read, write_fd, out.fileno(),
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
        return _collect(pid, read_fd, status_read, out, limits, returns, plan)
    finally:
        for fd in (read_fd, status_read, call_write):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        out.close()


def _returns(target: Callable) -> object:
    """`target`'s return annotation: the schema its result is read against."""
    try:
        return typing.get_type_hints(target).get("return", wire.PLAIN)
    except Exception:  # noqa: BLE001 - an annotation that does not resolve: plain JSON
        return wire.PLAIN


class _ForkServer:
    """A fresh interpreter (python -m mexone.exercises.child --server) that imports MuJoCo and
    mexone once and forks one run per request: a run costs a fork, not an interpreter's start,
    and holds nothing of the grading process's (it never forks the grader). It ends when this
    process closes its socket (ends)."""

    def __init__(self) -> None:
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        env = {k: v for k, v in os.environ.items() if k != SECRET_ENV}
        env["MEXONE_GRADER_PID"] = str(os.getpid())  # the server ends with this process
        for key in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            env[key] = "1"  # as in a controller's worker it forks (numpy imported here, once)
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

    def start(self, request: bytes, fds: tuple[int, int, int, int]) -> None:
        """Fork a run: (call read end, result write end, output file, status write end)."""
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
    """Start the fork server now (it imports MuJoCo while the grader prepares the first run)
    and probe the machine's isolation (once per process)."""
    _server()
    isolation()


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


_door: socket.socket | None = None  # in a trusted run: its fork server's door for workers


def serve(fd: int) -> None:
    """The fork server's loop: one run forked per request, until the grader hangs up. Its
    trusted runs (the simulators) inherit a door of their own, through which they have their
    controllers' workers forked here too (`_start_worker`): warm (MuJoCo, numpy and the
    worker's modules imported once), from a process that holds nothing of the grader's."""
    import mexone.control.worker_main  # noqa: F401 - a controller's worker, forked warm
    import mexone.lab  # noqa: F401 - what every run imports (MuJoCo), imported once
    import mexone.routines.isolated  # noqa: F401

    global _door
    probe_now()  # once here, not in each simulator whose lab starts a worker
    sock = socket.socket(fileno=fd)
    door, _door = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    processes.die_with_parent(int(os.environ.pop("MEXONE_GRADER_PID", "0")))
    server = os.getpid()
    while True:
        with contextlib.suppress(ChildProcessError):
            while os.waitpid(-1, os.WNOHANG)[0] > 0:  # the monitors that ended
                pass
        ready = select.select([sock, door], [], [], 0.5)[0]
        if sock in ready:
            request, fds, _, _ = socket.recv_fds(sock, 1 << 16, 4)
            if not request:
                os._exit(0)
            if len(fds) == 4 and os.fork() == 0:
                sock.close()
                door.close()
                _monitor(fds, server, request)
            for x in fds:
                os.close(x)
        if door in ready:
            request, fds, _, _ = socket.recv_fds(door, 1 << 20, 5)
            if len(fds) == 5 and os.fork() == 0:
                for end in (sock, door, _door):
                    end.close()
                _monitor_worker(fds, server, request)
            for x in fds:
                os.close(x)


def _monitor(fds: list[int], server: int, request: bytes) -> None:
    """Between the fork server and one run: forks the run (its own process group), tells the
    grader its pid, waits for it and tells the grader how it ended."""
    call_fd, result_fd, out_fd, status_fd = fds
    code = 0
    try:
        processes.die_with_parent(server)
        monitor = os.getpid()
        pid = os.fork()
        if pid == 0:
            _forked(monitor, status_fd, out_fd)
            if json.loads(request).get("plan") and _door is not None:
                _door.close()  # a jailed run never reaches the fork server
            child_main(call_fd, result_fd, json.loads(request))
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


def _forked(monitor: int, status_fd: int, out_fd: int) -> None:
    """A monitor's child's start: it dies with the monitor, in a process group of its own, its
    output to `out_fd`, no input, and not the monitor's status pipe."""
    processes.die_with_parent(monitor)
    os.setpgid(0, 0)
    os.close(status_fd)
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    os.dup2(out_fd, 1)
    os.dup2(out_fd, 2)
    for x in (null, out_fd):
        os.close(x)


def _monitor_worker(fds: list[int], server: int, request: bytes) -> None:
    """Between the fork server and one controller's worker (a trusted run's): forks it, which
    confines itself (confine.jail, as `sandbox.spawn`'s jails: its relay, then the jail) before
    any student code and keeps only its three descriptors; tells the run the relay's pid, waits
    for it and tells the run how it ended. When the run lets go of the status pipe (it ended,
    or forgot the worker), the worker is killed: nothing outlives the lab it served."""
    *keep, out_fd, status_fd = fds
    code = 0
    try:
        processes.die_with_parent(server)
        order = json.loads(request)
        plan = confine.Plan.loads(order["plan"])
        monitor = os.getpid()
        pid = os.fork()
        if pid == 0:
            _worker_child(keep, out_fd, status_fd, monitor, plan, order["env"])
        for x in (*keep, out_fd):
            os.close(x)
        os.write(status_fd, struct.pack("!i", pid))
        status = _wait_or_end(pid, status_fd, plan)
        os.write(status_fd, struct.pack("!i", status))
    except BaseException:  # noqa: BLE001 - the run sees the pipe close
        code = 3
    finally:
        os._exit(code)


def _worker_child(keep: list[int], out_fd: int, status_fd: int, monitor: int,
                  plan: confine.Plan, env: dict[str, str]) -> None:
    """The worker's process, forked warm: its environment and output, then the jail, then
    control.worker_main as `python -m` would run it."""
    code = 3
    try:
        _forked(monitor, status_fd, out_fd)
        os.environ.clear()
        os.environ.update(env)
        plan.parent = monitor
        confine.jail(plan, keep_fds=tuple(keep))  # from here on: the jail
        forget_probe()
        from mexone.control import worker_main

        worker_main.main([str(fd) for fd in keep])
        code = 0
    finally:
        os._exit(code)


def _wait_or_end(pid: int, status_fd: int, plan: confine.Plan) -> int:
    """The wait status of the worker's relay `pid`; killed (and, by uid, swept) first if the
    run that asked for it closes its end of `status_fd`."""
    poll = select.poll()
    poll.register(status_fd, 0)  # POLLERR: the reader closed
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return status
        if poll.poll(100):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
            _, status = os.waitpid(pid, 0)
            if plan.mode == "uid":
                confine.sweep(plan)
            return status


def _start_worker(argv: list[str], jail: Jail, *, pass_fds: tuple[int, ...] = (),
                  env: dict[str, str] | None = None, stdout: int | None = None,
                  **kwargs: object) -> StudentProcess:
    """In a trusted run: a controller's worker forked by the fork server (`serve`), jailed as
    `sandbox.spawn` would jail it (the same folders, plan and environment, made here), without
    an interpreter's start; `spawn` itself for anything else, or if the server is gone."""
    if _door is None or argv[1:3] != ["-m", controller_worker.MAIN] or len(pass_fds) != 3 \
            or kwargs:
        return spawn(argv, jail, pass_fds=pass_fds, env=env, stdout=stdout, **kwargs)
    work, scratch, root, own, slot = prepare(jail)
    status_r, status_w = os.pipe()
    try:
        plan = jail_plan(jail, scratch, root, slot)
        order = {"plan": plan.dumps(), "env": environment(env, scratch)}
        socket.send_fds(_door, [json.dumps(order).encode()],
                        [*pass_fds, stdout if stdout is not None else 2, status_w])
        os.close(status_w)
        status_w = -1
        pid = _read_int(status_r, timeout=60.0)
        if pid is None:
            raise OSError("the fork server did not start the worker")
    except OSError:
        for fd in (status_r, status_w):
            with contextlib.suppress(OSError):
                os.close(fd)
        if slot is not None:
            slot.release()
        shutil.rmtree(work, ignore_errors=True)
        return spawn(argv, jail, pass_fds=pass_fds, env=env, stdout=stdout)
    return StudentProcess(Forked(pid, status_r), jail, scratch, work, own, plan, slot)


def _call_bytes(target: Callable, args: tuple, kwargs: dict) -> bytes:
    """What the run needs to make the call: this process's sys.path, the target's module (a
    grader.py is loaded from its file) and the call, pickled by reference. (From the grader to
    the fork server: the grader's own data, never read back from a run.)"""
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


def child_main(call_fd: int, result_fd: int, request: dict) -> None:
    """A run: its limits, the call, then (jailed: confined first; trusted: under the audit
    hook) the call made and its result, as JSON, to `result_fd`."""
    code = 0
    try:
        sys.stdout.reconfigure(line_buffering=True)
        sys.stderr.reconfigure(line_buffering=True)
        limits = Limits(cpu=float(request["cpu"]), memory_mb=int(request["memory_mb"]))
        global _ACTIVE
        _ACTIVE = limits
        try:
            target, args, kwargs, folders = _read_call(call_fd)
            if request.get("plan"):
                plan = confine.Plan.loads(request["plan"])
                plan.parent = os.getppid()
                confine.jail(plan, keep_fds=(result_fd,))  # from here on: the jail
                forget_probe()  # what the machine offered outside: a jail it starts probes in here
            else:
                _limit(limits)
                trust.trust_only(_trusted_roots(folders))
                _jail_controllers(limits)
            payload = {"ok": target(*args, **kwargs)}
            for stream in (sys.stdout, sys.stderr):  # its output, before it is judged
                with contextlib.suppress(Exception):
                    stream.flush()
        except SubmissionFailed as exc:
            payload = {"failed": exc.reason}
        except MemoryError:
            payload = {"failed": f"ran out of memory (the limit is {limits.memory_mb} MB)"}
        except BaseException as exc:  # noqa: BLE001 - reported as the submission's failure
            last = traceback.format_exception_only(type(exc), exc)[-1].strip()
            payload = {"failed": f"the grader could not run the submission: {last}"}
        try:
            data = wire.dumps(payload)
        except wire.WireError as exc:
            data = wire.dumps({"failed": f"the run's result cannot be sent: {exc}"})
        view = memoryview(data)
        while view:
            view = view[os.write(result_fd, view):]
    except BaseException:  # noqa: BLE001
        code = 3
    finally:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(code)


def _jail_controllers(limits: Limits) -> None:
    """In the simulator: a student's controller in the lab it builds runs in its worker
    (control/worker.py), jailed as a grader's run is (a uid of the pool as root), under the
    run's CPU and memory limits for as long as the lab lives."""
    controller_worker.set_jail(Jail(limits=Limits(time=math.inf, cpu=limits.cpu,
                                                  memory_mb=limits.memory_mb), another_user=True),
                               starter=_start_worker)


def _limit(limits: Limits) -> None:
    import resource

    cpu = max(1, int(limits.cpu))
    resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 1))
    mem = int(limits.memory_mb) * 1024 * 1024
    with contextlib.suppress(ValueError, OSError):
        resource.setrlimit(resource.RLIMIT_AS, (mem, mem))
    with contextlib.suppress(ValueError, OSError):
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))


def _read_call(fd: int) -> tuple:
    """The grader's call (its own pickle, from the grading process): target, args, kwargs and
    the folders of the grader's modules it imported."""
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
    target, args, kwargs = pickle.loads(payload)
    return target, args, kwargs, [str(Path(file).resolve().parent) for _, file in modules]


def _trusted_roots(folders: list[str]) -> list[str]:
    """Where the simulator's code may come from: Python's installation (its standard library
    and site-packages), mexone, and the folders of the grader's own modules."""
    import mexone

    roots = {sys.prefix, sys.base_prefix, sys.exec_prefix, sys.base_exec_prefix,
             str(Path(mexone.__file__).resolve().parent), *folders}
    roots |= {v for k, v in sysconfig.get_paths().items() if k in ("stdlib", "platstdlib",
                                                                     "purelib", "platlib")}
    roots |= {p for p in sys.path if p and os.path.basename(p) in ("site-packages",
                                                                    "dist-packages")}
    return sorted(roots)


def active_limits() -> Limits:
    """The limits of the run this code runs in (Limits() outside one): what a routine's own
    process started from there gets too."""
    return _ACTIVE or Limits()


def _collect(pid: int, fd: int, status_fd: int, out, limits: Limits, returns: object,
             plan: confine.Plan | None):
    deadline = time.monotonic() + limits.time
    chunks: list[bytes] = []
    size = 0
    status = None
    timed_out = False
    while status is None:
        if signals.requested():  # Ctrl-C or SIGTERM to the grader: the run ends with it
            _kill(pid, plan)
            signals.check()
        left = deadline - time.monotonic()
        if left <= 0:
            timed_out = True
            status = _end(pid, status_fd)
            break
        ready = select.select([fd, status_fd], [], [], min(left, 0.05))[0]
        if fd in ready:
            data = os.read(fd, 1 << 16)
            if data:
                size += len(data)
                if size <= wire.MAX_BYTES:
                    chunks.append(data)
                continue
        if status_fd in ready:
            status = _read_int(status_fd, timeout=10.0)
            if status is None:
                status = signal.SIGKILL
    while data := _read_rest(fd):
        size += len(data)
        if size <= wire.MAX_BYTES:
            chunks.append(data)
    _kill(pid, plan)  # whatever it left
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
    if size > wire.MAX_BYTES:
        raise SubmissionFailed(f"the run sent more than {wire.MAX_BYTES >> 20} MB", output)
    try:
        message = wire.loads(b"".join(chunks), dict[str, object])
        if set(message) == {"failed"}:
            raise SubmissionFailed(str(wire.read(message["failed"], str, "reason")), output)
        if set(message) != {"ok"}:
            raise wire.WireError("result: neither ok nor failed")
        value = wire.read(message["ok"], returns)
    except wire.WireError as exc:  # a truncated or forged message is the submission's doing
        raise SubmissionFailed(f"the run's result is not what the grader reads ({exc})",
                               output) from None
    if TRACEBACK in output:  # it caught its own error and printed it: a crash all the same
        last = [line for line in output.splitlines() if line.strip()][-1].strip()
        raise SubmissionFailed(f"the submission printed a traceback ({last[:200]})", output)
    return value


def _read_rest(fd: int) -> bytes:
    if select.select([fd], [], [], 0)[0]:
        with contextlib.suppress(OSError):
            return os.read(fd, 1 << 16)
    return b""


def _end(pid: int, status_fd: int) -> int:
    """Ask the run's relay to end its jail (SIGTERM), then kill it: its wait status."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.kill(pid, signal.SIGTERM)
    status = _read_int(status_fd, timeout=END_GRACE)
    if status is None:
        _signal_group(pid)
        status = _read_int(status_fd, timeout=10.0)
    return signal.SIGKILL if status is None else status


def _signal_group(pid: int) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pid, signal.SIGKILL)
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGKILL)


def _kill(pid: int, plan: confine.Plan | None) -> None:
    """End the run and whatever it left: its relay's jail, its process group, its uid."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.kill(pid, signal.SIGTERM)
    deadline = time.monotonic() + END_GRACE
    while time.monotonic() < deadline and processes.group(pid):
        select.select([], [], [], 0.01)
    _signal_group(pid)
    with contextlib.suppress(Exception):
        left = processes.group(pid)
        if left:
            processes.stop(left)
    if plan is not None and plan.mode == "uid":
        confine.sweep(plan)


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
