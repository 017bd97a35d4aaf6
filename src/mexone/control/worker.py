"""A student's PythonController in a process of its own: mexone's side (the student's side is
control/worker_main.py).

A controller class resolved from a file or a module (the YAML's `type:`) never runs in the lab's
process: a segfault, `posix._exit`, a ctypes write into MuJoCo's memory or a frozen update
cannot be survived there, and a graded controller must not share a process with the simulator
that measures it. Its worker is started by `mexone.sandbox.spawn` (in the jail `set_jail` sets; in
a grader's simulator, by set_jail's starter: forked warm by the runs' fork server and jailed the
same way, exercises.isolate), imports the student's module, and runs the same lifecycle and
API in lockstep with the controller manager:

- each update, what the controller reads (MuJoCo's qpos, qvel and actuator forces, the time,
  the sensors it asked for, its chained inputs) goes into shared memory the worker maps
  read-only; its command (and exports) come back in shared memory it may write; a 5-byte frame
  each way wakes the other side (`sandbox.wire`);
- everything else is a JSON frame: calls (create, activate, deactivate, set_param, report,
  model, rebind, check_entry, quit) and their replies, log lines, faults, requests for a sensor,
  and before an update the bus messages that arrived for the class's `topics` (mexone.bus.msgs
  data, `message_data`: the worker rebuilds them, never an object of its choosing);
- `self.dynamics` computes on the worker's private copy of the compiled model (sent again when
  the model changes), so nothing the controller does changes the simulated physics.

A call or an update that does not answer in time, a process that ends or crashes, or a frame
the protocol does not allow ends the worker (with everything it started) and raises
`WorkerFailed`, whose `line` is the student's line (`sandbox.ended`: faulthandler's dump). A
fault in the student's code (an exception, a bad return value) is `StudentFault`: the worker
lives on, as the object does in-process.

Describing a class (its parameters, interface, lines) also takes a worker: `describe` starts
one, asks, and keeps it for the controller that is usually created next (`claim`); a worker
nobody claims ends by itself after POOL_IDLE s.
"""

from __future__ import annotations

import atexit
import contextlib
import dataclasses
import math
import os
import re
import sys
import threading
import time
import weakref
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

import numpy as np

from mexone.control import watchdog
from mexone.control.resolve import Found, locate
from mexone.control.student import COMMAND_INTERFACES, Param, PythonController
from mexone.errors import InputError
from mexone.ranges import number_text
from mexone.sandbox import Jail, Limits, StudentProcess, spawn
from mexone.sandbox.ended import WHERE_SIGNAL, read_dump, student_line, why_ended
from mexone.sandbox.wire import Channel, WireError, frame, pair

if TYPE_CHECKING:
    import mmap

    import mujoco

    from mexone.control.resolve import Plugin

__all__ = ["ClassInfo", "Layout", "Worker", "WorkerFailed", "StudentFault", "describe", "claim",
           "resolve", "prestart", "stand_in", "set_jail", "end_all", "message_data", "message_from",
           "STARTUP_TIMEOUT", "POOL_IDLE", "MAIN"]

MAIN = "mexone.control.worker_main"  # python -m MAIN FRAMES_FD DESCRIPTORS_FD DUMP_FD
STARTUP_TIMEOUT = 60.0  # s for a worker's interpreter to start and import mexone (mexone's time)
POOL_IDLE = 15.0  # s a described, unclaimed worker waits for its controller before it ends
WHERE_TIMEOUT = 0.5  # s a stuck worker gets to say where it is before it is ended
_TEXT_MAX = 400  # characters of a student's text (an exception's message) shown
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,99}$")
_KINDS = {"bool": bool, "int": int, "float": float, "str": str}
_LEVELS = range(0, 51)

# frames (sandbox.wire kinds): mexone -> worker
UPDATE, CALL, FILLED, MESSAGES = b"U", b"J", b"F", b"M"
# worker -> mexone
DONE, KEPT, UPDATE_FAULT, REPLY = b"D", b"N", b"Q", b"R"
LOG, THREAD_FAULT, SENSOR, PARAMS = b"L", b"X", b"S", b"P"
_ENDS_UPDATE = (DONE, KEPT, UPDATE_FAULT)
FILLED_FRAME = frame(FILLED)
_UPDATE_HEAD = frame(UPDATE, bytes(8))[:5]  # an update's frame: this, then its number (8 bytes)

_jail = Jail(limits=Limits(time=math.inf, cpu=1e9, memory_mb=4096))
_starter: Callable[..., StudentProcess] = spawn


def set_jail(jail: Jail, starter: Callable[..., StudentProcess] | None = None) -> None:
    """The jail every controller worker starts in from now on (a grader's: its limits, its
    scratch folder). Default: no CPU limit, 4 GB of address space, a scratch folder of its own.
    `starter`: what starts a worker in it, with `sandbox.spawn`'s signature (default: spawn; a
    grader's simulator forks it from its warm fork server, exercises.isolate)."""
    global _jail, _starter
    _jail = jail
    _starter = starter or spawn


class WorkerFailed(Exception):
    """The worker ended, stopped answering or broke the protocol; it is gone. `why`: words
    ("did not return within 2 s", "its process crashed (SIGSEGV)"); `line`: the student's line
    it was at, if known; `hung`: it did not answer (rather than ended)."""

    def __init__(self, why: str, line: int | None = None, hung: bool = False):
        super().__init__(why)
        self.why, self.line, self.hung = why, line, hung


class StudentFault(Exception):
    """The student's code failed in a call (its one line: file:line: Type: message); the worker
    lives on."""


# ----- what a class is, as the worker describes it --------------------------------------------
@dataclass(frozen=True)
class ClassInfo:
    """A student's PythonController class, described by the worker that imported it: all the lab
    knows of it (data, checked here: the worker is the student's)."""

    name: str
    file: str
    origin: str
    command_interface: str
    params: dict[str, dict[str, Any]]
    update_line: int | None
    report: bool
    check_entry: bool
    exports: dict[str, int] = field(default_factory=dict)
    inputs: dict[str, int] = field(default_factory=dict)
    topics: dict[str, str] = field(default_factory=dict)  # name -> a mexone.bus.msgs class's name
    stamp: str | None = None  # the file's digest when it was imported (set here, not by it)

    @classmethod
    def checked(cls, obj: object) -> ClassInfo:
        """From the worker's JSON; WireError for anything a description cannot hold."""
        if not isinstance(obj, dict):
            raise WireError("a class description that is not an object")
        try:
            name, file, origin = (_text(obj[k], 1000) for k in ("name", "file", "origin"))
            interface = obj["command_interface"]
            if interface not in COMMAND_INTERFACES or not _NAME.match(name):
                raise WireError("a class description with a bad name or interface")
            params = {}
            for key, value in dict(obj["params"]).items():
                if not _NAME.match(str(key)) or not isinstance(value, dict) or \
                        value.get("kind") not in _KINDS:
                    raise WireError("a class description with a malformed parameter")
                params[str(key)] = dict(value)
            line = obj.get("update_line")
            return cls(name, file, origin, interface, params,
                       line if isinstance(line, int) and line > 0 else None,
                       obj.get("report") is True, obj.get("check_entry") is True,
                       _sizes(obj.get("exports", {})), _sizes(obj.get("inputs", {})),
                       _topics(obj.get("topics", {})), _digest(file))
        except (KeyError, TypeError, ValueError) as exc:
            raise WireError(f"a malformed class description ({type(exc).__name__})") from None

    def declared(self) -> dict[str, Param]:
        """Its Params, built here from the description (TypeError: a description no Param of the
        student's could have)."""
        out = {}
        for key, p in self.params.items():
            choices = p.get("choices")
            param = Param(_KINDS[p["kind"]](p["default"]), p.get("low"), p.get("high"),
                          _text(p.get("doc", ""), 400), _text(p.get("unit", ""), 40),
                          tuple(str(c) for c in choices) if isinstance(choices, list) else None)
            param.__set_name__(None, key)
            out[key] = param
        return out

    def current(self) -> bool:
        """The file still holds what was imported (an edit since: describe again)."""
        return self.stamp is not None and self.stamp == _digest(self.file)


def _digest(path: str) -> str | None:
    import hashlib  # here: not in a worker's start (OpenSSL's load)

    try:
        with open(path, "rb") as file:
            return hashlib.sha256(file.read(1 << 24)).hexdigest()
    except OSError:
        return None


def _text(value: object, limit: int) -> str:
    if not isinstance(value, str):
        raise WireError("text expected")
    return value[:limit]


def _sizes(value: object) -> dict[str, int]:
    if not isinstance(value, dict) or not all(_NAME.match(str(k)) and isinstance(v, int)
                                              and 0 < v <= 10_000 for k, v in value.items()):
        raise WireError("malformed exports or inputs")
    return {str(k): int(v) for k, v in value.items()}


def _topics(value: object) -> dict[str, str]:
    from mexone.bus import msgs

    if not isinstance(value, dict) or not all(
            isinstance(k, str) and len(k) <= 200 and all(p.isidentifier() for p in k.split("/"))
            and v in msgs.__all__ and dataclasses.is_dataclass(getattr(msgs, v))
            for k, v in value.items()):
        raise WireError("malformed topics")
    return dict(value)


# ----- bus messages to a worker (PythonController.topics) -------------------------------------
def message_data(value: Any) -> Any:
    """A mexone.bus.msgs message as JSON-able data `message_from` rebuilds: a message is
    {"@": its class's name, field: value...}, a tuple {"@t": [...]}, bytes {"@b": hex}."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        out = {f.name: message_data(getattr(value, f.name)) for f in dataclasses.fields(value)}
        out["@"] = type(value).__name__
        return out
    if isinstance(value, tuple):
        return {"@t": [message_data(v) for v in value]}
    if isinstance(value, list):
        return [message_data(v) for v in value]
    if isinstance(value, (bytes, bytearray, memoryview)):
        return {"@b": bytes(value).hex()}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def message_from(data: Any) -> Any:
    """The message `message_data` wrote (classes only from mexone.bus.msgs)."""
    from mexone.bus import msgs

    if isinstance(data, list):
        return [message_from(v) for v in data]
    if not isinstance(data, dict):
        return data
    if "@t" in data:
        return tuple(message_from(v) for v in data["@t"])
    if "@b" in data:
        return bytes.fromhex(data["@b"])
    name = data.get("@")
    if name not in msgs.__all__:
        raise ValueError(f"not a mexone.bus.msgs message: {name!r:.40}")
    return getattr(msgs, name)(**{k: message_from(v) for k, v in data.items() if k != "@"})


def shown(text: object) -> str:
    """A student's text as one line of at most _TEXT_MAX characters: control characters (a
    newline, an escape sequence) shown as '?'."""
    text = str(text)
    text = "".join(c if c.isprintable() else "?" for c in text[:_TEXT_MAX + 1])
    return text if len(text) <= _TEXT_MAX else text[:_TEXT_MAX - 3] + "..."


class _StandIn:
    """What the lab holds for a worker's controller object: the framework's attributes (name,
    joints, dofs, params) and nothing of the student's, which live in the worker."""

    def __getattr__(self, name: str) -> NoReturn:
        if name.startswith("__"):
            raise AttributeError(name)
        raise AttributeError(f"'{name}' is an attribute of the controller's object, which runs in "
                             "a process of its own: define report() to bring numbers back "
                             "(docs/controllers.md)")


def stand_in(info: ClassInfo) -> type[PythonController]:
    """A PythonController class for the lab that stands for the student's class in its worker:
    the same name, command_interface and Params (`_mexone_worker`: the description)."""
    attrs: dict[str, Any] = {"command_interface": info.command_interface, "__module__": __name__,
                             "__doc__": f"{info.name} from {info.file}, run in its own process",
                             "_mexone_worker": info, "exports": dict(info.exports),
                             "inputs": dict(info.inputs), "topics": _message_classes(info)}
    try:
        attrs.update(info.declared())
    except (TypeError, ValueError, KeyError):
        raise WireError("a parameter no Param could declare") from None
    if info.check_entry:
        attrs["check_entry"] = classmethod(_check_entry_in_worker)
    return type(info.name, (_StandIn, PythonController), attrs)


def _message_classes(info: ClassInfo) -> dict[str, type]:
    from mexone.bus import msgs

    return {name: getattr(msgs, kind) for name, kind in info.topics.items()}


def _check_entry_in_worker(cls: type[PythonController], name: str, joints: tuple[str, ...],
                           plugin: Plugin, timestep: float) -> None:
    """`check_entry` of a class whose own runs in its worker (mexone check --controllers)."""
    info: ClassInfo = cls._mexone_worker  # type: ignore[attr-defined]  # stand_in's class carries it
    worker = claim(info, plugin.type, plugin.yaml_dir)
    try:
        worker.call({"call": "check_entry", "name": name, "joints": list(joints),
                     "timestep": timestep, "plugin": {
                         "type": plugin.type, "raw": {k: v for k, (v, _) in plugin.raw.items()},
                         "lines": dict(plugin.lines), "params": plugin.params,
                         "update_rate": plugin.update_rate, "source": str(plugin.source or ""),
                         "line": plugin.line}}, watchdog.STUDENT_SETUP_TIMEOUT)
    except StudentFault as exc:
        raise InputError(f"controller '{name}': {exc}") from None
    except WorkerFailed as exc:
        raise InputError(f"controller '{name}': check_entry: {exc.why}"
                         + (f" ({info.file}:{exc.line})" if exc.line else "")) from None
    finally:
        worker.kill()


# ----- shared memory --------------------------------------------------------------------------
@dataclass(frozen=True)
class Layout:
    """Where each number is in a worker's shared memory (float64 slots). The input block (the
    worker maps it read-only): t, dt, qpos, qvel, qfrc_actuator, mocap positions and
    quaternions, each sensor's fields, each chained input. The output block (page-aligned
    after it; the worker may write it): the line of the `return` that produced the command,
    the command, each export. Nothing the worker writes there times or excuses it: mexone
    measures its updates itself (IsolatedRunner)."""

    n: int
    nq: int
    nv: int
    nmocap: int
    sensors: tuple[tuple[str, str, tuple[tuple[str, int], ...]], ...] = ()  # name, class, fields
    inputs: tuple[tuple[str, int], ...] = ()
    exports: tuple[tuple[str, int], ...] = ()

    HEAD = 2  # t, dt
    OUT_HEAD = 1  # return line

    @property
    def inputs_size(self) -> int:
        return (self.HEAD + self.nq + 2 * self.nv + 7 * self.nmocap
                + sum(size for _, _, fields in self.sensors for _, size in fields)
                + sum(size for _, size in self.inputs))

    @property
    def outputs_size(self) -> int:
        return self.OUT_HEAD + self.n + sum(size for _, size in self.exports)

    @property
    def split(self) -> int:
        """Byte offset of the output block (a page boundary)."""
        page = os.sysconf("SC_PAGE_SIZE")
        return -(-self.inputs_size * 8 // page) * page

    @property
    def nbytes(self) -> int:
        page = os.sysconf("SC_PAGE_SIZE")
        return self.split + -(-max(1, self.outputs_size) * 8 // page) * page

    def views(self, inputs: np.ndarray, outputs: np.ndarray) -> dict[str, Any]:
        """Named views of the two blocks (both sides cut them the same way)."""
        at = self.HEAD
        out: dict[str, Any] = {}
        for key, size in (("qpos", self.nq), ("qvel", self.nv), ("frc", self.nv),
                          ("mocap_pos", 3 * self.nmocap), ("mocap_quat", 4 * self.nmocap)):
            out[key] = inputs[at:at + size]
            at += size
        sensors = []
        for _, _, fields in self.sensors:
            views = []
            for name, size in fields:
                views.append((name, inputs[at:at + size]))
                at += size
            sensors.append(views)
        out["sensors"] = sensors
        out["inputs"] = {}
        for name, size in self.inputs:
            out["inputs"][name] = inputs[at:at + size]
            at += size
        at = self.OUT_HEAD
        out["command"] = outputs[at:at + self.n]
        at += self.n
        out["exports"] = {}
        for name, size in self.exports:
            out["exports"][name] = outputs[at:at + size]
            at += size
        return out

    def to_json(self) -> dict[str, Any]:
        return {"n": self.n, "nq": self.nq, "nv": self.nv, "nmocap": self.nmocap,
                "sensors": [[n, c, [list(f) for f in fields]] for n, c, fields in self.sensors],
                "inputs": [list(i) for i in self.inputs], "exports": [list(e) for e in self.exports]}

    @classmethod
    def from_json(cls, obj: dict[str, Any]) -> Layout:
        return cls(int(obj["n"]), int(obj["nq"]), int(obj["nv"]), int(obj["nmocap"]),
                   tuple((str(n), str(c), tuple((str(f), int(s)) for f, s in fields))
                         for n, c, fields in obj["sensors"]),
                   tuple((str(n), int(s)) for n, s in obj["inputs"]),
                   tuple((str(n), int(s)) for n, s in obj["exports"]))


def shared_block(nbytes: int) -> int:
    """A sealed shared-memory file of `nbytes` (memfd): the worker can neither shrink it (which
    would make mexone's reads fault) nor grow it."""
    import fcntl

    fd = os.memfd_create("mexone-controller", os.MFD_CLOEXEC | os.MFD_ALLOW_SEALING)
    os.ftruncate(fd, nbytes)
    _seal(fd, fcntl.F_SEAL_SHRINK | fcntl.F_SEAL_GROW | fcntl.F_SEAL_SEAL)
    return fd


SEAL_TRIES = 6


def _seal(fd: int, seals: int) -> None:
    """`fcntl(fd, F_ADD_SEALS, seals)`, tried again on EBUSY: Linux refuses F_SEAL_WRITE while
    it still holds a page of the file pinned (one just written, not yet out of a CPU's LRU
    batch), a passing state; "OSError: [Errno 16]" ended a graded run once (issue 36)."""
    import errno
    import fcntl

    for attempt in range(SEAL_TRIES):
        try:
            fcntl.fcntl(fd, fcntl.F_ADD_SEALS, seals)
            return
        except OSError as exc:
            if exc.errno != errno.EBUSY or attempt == SEAL_TRIES - 1:
                raise
            time.sleep(0.01 * 2 ** attempt)  # the kernel waited ~75 ms itself


def model_block(model: mujoco.MjModel) -> tuple[int, int]:
    """The compiled model as MuJoCo's binary (MJB) in a sealed memfd: (fd, size)."""
    import fcntl

    import mujoco

    size = mujoco.mj_sizeModel(model)
    buf = np.empty(size, np.uint8)
    mujoco.mj_saveModel(model, None, buf)
    fd = os.memfd_create("mexone-model", os.MFD_CLOEXEC | os.MFD_ALLOW_SEALING)
    view = memoryview(buf)  # type: ignore[arg-type]  # numpy's stubs: no __buffer__ on 3.11
    while view:
        view = view[os.write(fd, view):]
    _seal(fd, fcntl.F_SEAL_SHRINK | fcntl.F_SEAL_GROW | fcntl.F_SEAL_WRITE | fcntl.F_SEAL_SEAL)
    return fd, size


# ----- the process ----------------------------------------------------------------------------
_live: weakref.WeakSet[Worker] = weakref.WeakSet()


class Worker:
    """One controller worker: its process, the frame channel, its dump pipe and shared memory.
    Serves the worker's requests while it waits (`handler`: the runner, with on_log,
    on_thread_fault, on_sensor, on_params)."""

    def __init__(self, jail: Jail | None = None, readable: tuple[Path, ...] = ()):
        jail = jail or _jail
        self.jail = dataclasses.replace(jail, limits=_within_ours(jail.limits),
                                        readable=tuple(dict.fromkeys((*jail.readable,
                                                                      *readable))))
        self.file = ""  # the student's file, once known (for its line in a dump)
        self.handler: Any = None
        self.thread: int | None = None
        self.pid: int | None = None
        self.seq = 0  # the last request's number: every answer names the one it answers
        self.inputs: np.ndarray | None = None
        self.outputs: np.ndarray | None = None
        self._mapped: mmap.mmap | None = None
        chan, theirs = pair()
        dump_r, dump_w = os.pipe()
        fds = (theirs[0].fileno(), theirs[1].fileno(), dump_w)
        try:
            os.set_blocking(dump_r, False)
            self.process: StudentProcess = _starter(
                [sys.executable, "-m", MAIN, *map(str, fds)], self.jail, pass_fds=fds,
                env=_environment(), stdout=2)
        except BaseException:
            chan.close()
            os.close(dump_r)
            raise
        finally:
            for sock in theirs:
                sock.close()
            os.close(dump_w)
        self.chan, self.dump = chan, dump_r
        self.started = time.monotonic()
        _live.add(self)
        self._finalizer = weakref.finalize(self, _end, self.process, chan, dump_r, os.getpid())

    # ----- calls ----------------------------------------------------------------------------------
    def ready(self) -> None:
        """Wait for the interpreter to start (mexone's time, not the student's)."""
        reply = self._answer(STARTUP_TIMEOUT)
        if not isinstance(reply, dict) or not isinstance(reply.get("thread"), int):
            self._failed("sent a malformed greeting")
        self.thread = reply["thread"]
        # the process itself (a jail's relay may stand between): whom WHERE_SIGNAL goes to
        self.pid = self.chan.peer(1.0) or self.process.pid

    def call(self, request: dict[str, Any], timeout: float, fds: Sequence[int] = ()) -> Any:
        """Ask; the answer's value, StudentFault for the student's error, WorkerFailed else."""
        self.seq += 1
        try:
            if fds:
                self.chan.hand_over(tuple(fds))
            self.chan.send_json(CALL, dict(request, fds=len(fds), seq=self.seq))
        except WireError:
            self._ended()
        return self._answer(timeout)

    def _answer(self, timeout: float) -> Any:
        """The answer to the last call: an answer to an earlier one (a wait a Ctrl-C cut short in
        a notebook) is passed over."""
        deadline = time.monotonic() + timeout
        while True:
            _, payload = self.wait(deadline, (REPLY,), timeout)
            message = self._json(payload)
            if not isinstance(message, dict):
                self._failed("sent a malformed answer")
            if message.get("seq") == self.seq:
                break
        if "fault" in message:
            raise StudentFault(shown(message["fault"]))
        if "input_error" in message:
            error = message["input_error"]
            if not isinstance(error, dict):
                self._failed("sent a malformed answer")
            hint, line = error.get("hint"), error.get("line")
            raise InputError(shown(error.get("what", "")), hint=shown(hint) if hint else None,
                             line=line if isinstance(line, int) and line > 0 else None)
        return message.get("ok")

    def update(self, timeout: float) -> tuple[bytes, bytes]:
        """One update's round trip (its state already in shared memory): DONE, KEPT or
        UPDATE_FAULT with what follows the update's number in its payload, the worker's
        requests served meanwhile. An answer to an earlier update (a wait a Ctrl-C cut short
        in a notebook) is passed over. What a Python controller in its own process costs per
        update is mostly this: kept to two syscalls and a comparison when nothing else comes."""
        self.seq += 1
        number = self.seq.to_bytes(8, "little")
        chan = self.chan
        try:
            chan.send_frame(_UPDATE_HEAD + number)
            frame = chan.receive(timeout)
        except WireError as exc:
            self._broke(exc)
        if frame is None:
            self._hung(timeout)
        if frame[0] in _ENDS_UPDATE and frame[1][:8] == number:
            return frame[0], frame[1][8:]
        deadline = time.monotonic() + timeout
        while True:
            if frame[0] not in _ENDS_UPDATE:
                self.serve(*frame)
            elif frame[1][:8] == number:
                return frame[0], frame[1][8:]
            frame = self.wait(deadline, (*_ENDS_UPDATE, LOG, THREAD_FAULT, SENSOR, PARAMS),
                              timeout)

    def wait(self, deadline: float, ends: tuple[bytes, ...], timeout: float) -> tuple[bytes, bytes]:
        """Frames until one of kind `ends`, serving the worker's other requests meanwhile (an
        update's answer that is not awaited is passed over)."""
        chan = self.chan
        while True:
            try:
                frame = chan.receive(max(0.0, deadline - time.monotonic()))
            except WireError as exc:
                self._broke(exc)
            if frame is None:
                self._hung(timeout)
            kind, payload = frame
            if kind in ends:
                return kind, payload
            if kind not in _ENDS_UPDATE:
                self.serve(kind, payload)

    def _broke(self, exc: WireError) -> NoReturn:
        """The channel failed: the process ended (why), or it sent what the protocol forbids."""
        if "hung up" in str(exc):
            self._ended()
        self._failed(f"sent what mexone cannot read ({exc})")

    def serve(self, kind: bytes, payload: bytes) -> None:
        """One of the worker's frames that is not an answer: a log line, a thread's fault, a
        sensor wanted, parameters it changed."""
        handler = self.handler
        message = self._json(payload)
        if not isinstance(message, dict):
            self._failed("sent a malformed message")
        if kind == LOG:
            level = message.get("level")
            if handler is not None and isinstance(level, int) and level in _LEVELS:
                handler.on_log(level, shown(message.get("text", "")))
        elif kind == THREAD_FAULT:
            if handler is not None:
                handler.on_thread_fault(shown(message.get("fault", "")))
        elif kind == SENSOR:
            index = message.get("sensor")
            if handler is None or not isinstance(index, int) or not handler.on_sensor(index):
                self._failed("asked for a sensor it has not got")
            try:
                self.chan.send_frame(FILLED_FRAME)
            except WireError:
                self._ended()
        elif kind == PARAMS:
            if handler is not None and isinstance(message.get("params"), dict):
                handler.on_params(message["params"])
        else:
            self._failed(f"sent a frame of unknown kind {kind!r}")

    def _json(self, payload: bytes) -> Any:
        try:
            return Channel.json(payload)
        except WireError as exc:
            self._failed(str(exc))

    # ----- its shared memory ------------------------------------------------------------------------
    def map(self, layout: Layout) -> int:
        """A new shared block for `layout`, mapped here; its fd (the caller hands it over, then
        closes it)."""
        import mmap

        fd = shared_block(layout.nbytes)
        mapped = mmap.mmap(fd, layout.nbytes)
        whole = np.frombuffer(mapped, np.float64)
        self.inputs = whole[:layout.inputs_size]
        self.outputs = whole[layout.split // 8:layout.split // 8 + max(1, layout.outputs_size)]
        self._mapped = mapped  # kept alive with the views
        return fd

    # ----- ending -------------------------------------------------------------------------------
    def _hung(self, timeout: float) -> NoReturn:
        line = self.where()
        self.kill()
        raise WorkerFailed(f"did not return within {number_text(timeout)} s", line, hung=True)

    def where(self) -> int | None:
        """The student's line the worker is at now (faulthandler's answer to WHERE_SIGNAL)."""
        if not self.file or self.process.poll() is not None:
            return None
        def found(text: str) -> bool:
            return student_line(text, self.file, self.thread) is not None

        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(self.pid or self.process.pid, WHERE_SIGNAL)
            return student_line(read_dump(self.dump, WHERE_TIMEOUT, found), self.file,
                                self.thread)
        return None

    def _ended(self) -> NoReturn:
        status = self.process.wait(2.0)
        self.process.kill()  # what it started goes too (and with it the dump pipe's writers)
        dump = read_dump(self.dump, WHERE_TIMEOUT)
        line = student_line(dump, self.file, self.thread) if self.file else None
        self.kill()
        raise WorkerFailed(why_ended(status, self.jail.limits.cpu if self.jail.limits.cpu < 1e8
                                     else None), line)

    def _failed(self, why: str) -> NoReturn:
        self.kill()
        raise WorkerFailed(f"its process {why}")

    @property
    def alive(self) -> bool:
        return self.process.poll() is None and self._finalizer.alive

    def quit(self, timeout: float = 1.0) -> list[str]:
        """End the worker politely: the lines it says about what its student left running
        (threads), then the process ends (killed if it does not within `timeout` s)."""
        lines: list[str] = []
        if self.alive:
            with contextlib.suppress(WorkerFailed, StudentFault, InputError):
                said = self.call({"call": "quit"}, timeout)
                if isinstance(said, list):
                    lines = [shown(s) for s in said[:10]]
        self.kill()
        return lines

    def kill(self) -> None:
        """End the process and everything it started (idempotent)."""
        self._finalizer()
        _live.discard(self)


def _within_ours(limits: Limits) -> Limits:
    """`limits` no higher than this process's own hard limits (a lab in a grader's limited
    process: a child may not raise them)."""
    import resource

    cpu, memory = limits.cpu, limits.memory_mb
    hard = resource.getrlimit(resource.RLIMIT_CPU)[1]
    if hard != resource.RLIM_INFINITY:
        cpu = max(1, min(cpu, hard - 1))
    hard = resource.getrlimit(resource.RLIMIT_AS)[1]
    if hard != resource.RLIM_INFINITY:
        memory = max(1, min(memory, hard >> 20))
    return dataclasses.replace(limits, cpu=cpu, memory_mb=memory)


def _end(process: StudentProcess, chan: Channel, dump: int, owner: int) -> None:
    if os.getpid() != owner:  # a fork of the lab's process: the workers are the lab's to end
        return
    process.kill()
    chan.close()
    with contextlib.suppress(OSError):
        os.close(dump)


@atexit.register
def end_all() -> None:
    """End every controller worker of this process (at its exit; a caller that leaves by
    os._exit, which skips atexit, calls it first)."""
    for worker in list(_live):
        worker.kill()
    _pool.clear()
    _spares.clear()


def _environment() -> dict[str, str]:
    """The worker's environment: the lab's, mexone importable as here, one BLAS thread (a
    controller's numpy must not spread over the cores the simulation uses)."""
    env = dict(os.environ)
    package = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = os.pathsep.join([package, *filter(None, [env.get("PYTHONPATH")])])
    for key in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env[key] = "1"
    env["MUJOCO_GL"] = "disable"  # a controller renders nothing: no OpenGL library loaded
    env.pop("PYTHONSTARTUP", None)
    return env


# ----- describing a class, and the workers kept for their controllers -----------------------------
@dataclass
class _Pooled:
    info: ClassInfo
    key: tuple[object, ...]
    worker: Worker


_pool: list[_Pooled] = []
_described: dict[tuple[object, ...], ClassInfo] = {}
_lock = threading.Lock()
_POOL_MAX = 32


def describe(ctype: str, yaml_dir: Path | None, shipped: list[str], fresh: bool = False,
             found: Found | None = None) -> ClassInfo:
    """The class `ctype` names, imported and described in a worker (kept for `claim`), or the
    InputError its import or lookup raised (no location: the caller adds the YAML's)."""
    found = found or locate(ctype, yaml_dir, shipped)
    key = (ctype, str(yaml_dir), tuple(sys.path))
    with _lock:
        known = _described.get(key)
    if known is not None and not fresh and known.current():
        return known
    worker = _start(_readable(found, yaml_dir))
    try:
        info = _describe_in(worker, ctype, yaml_dir, shipped, found)
    except BaseException:
        worker.kill()
        raise
    with _lock:
        _described[key] = info
        _pool.append(_Pooled(info, key, worker))
        while len(_pool) > _POOL_MAX:
            _pool.pop(0).worker.kill()
    return info


_spares: list[Worker] = []  # started ahead (prestart), not yet greeted
_SPARES_MAX = 8


@contextlib.contextmanager
def reading() -> Iterator[None]:
    """Around reading a controller YAML: if it is refused, the workers started for it (spares,
    described classes kept for their controllers) end at once rather than idle."""
    with _lock:
        before = {id(w) for w in _spares} | {id(e.worker) for e in _pool}
    try:
        yield
    except BaseException:
        with _lock:
            new = [w for w in _spares if id(w) not in before] + \
                  [e.worker for e in _pool if id(e.worker) not in before]
            _spares[:] = [w for w in _spares if id(w) in before]
            _pool[:] = [e for e in _pool if id(e.worker) in before]
        for worker in new:
            worker.kill()
        raise


def prestart(count: int, readable: tuple[Path, ...] = ()) -> None:
    """Start `count` workers now, without waiting for them (a YAML of several Python controllers:
    their interpreters start side by side, while this process reads on); `readable`: the
    folders their code is in (the YAML's)."""
    with _lock:
        _prune()
        while len(_spares) < min(count, _SPARES_MAX):
            _spares.append(Worker(readable=readable))


def _readable(found: Found, yaml_dir: Path | None) -> tuple[Path, ...]:
    """The folders a worker for `found` must read (besides Python's and mexone's): the YAML's,
    the student's file's, the module's."""
    folders = [yaml_dir] if yaml_dir is not None else []
    if found.kind == "file":
        folders.append(Path(found.name).parent)
    elif found.kind in ("module", "entry"):  # an entry point's value: "package.module:Class"
        with contextlib.suppress(ImportError, ValueError, AttributeError):
            import importlib.util

            spec = importlib.util.find_spec(found.name.partition(":")[0].split(".")[0])
            origin = Path(spec.origin) if spec and spec.origin else None
            if origin is not None:
                folders.append(origin.parent.parent if origin.name == "__init__.py"
                               else origin.parent)
    return tuple(dict.fromkeys(f for f in folders if f is not None))


def _prune() -> None:
    """Forget the kept workers that ended by themselves (idle for POOL_IDLE), reading their exit
    status: no zombie is left behind. Called with _lock held."""
    for entry in [e for e in _pool if not e.worker.alive]:
        _pool.remove(entry)
        entry.worker.kill()
    for worker in [w for w in _spares if not w.alive]:
        _spares.remove(worker)
        worker.kill()


def _start(readable: tuple[Path, ...] = ()) -> Worker:
    with _lock:
        _prune()
        index = next((i for i, w in enumerate(_spares)
                      if set(readable) <= set(w.jail.readable)), None)
        worker = _spares.pop(index) if index is not None else None
    worker = worker if worker is not None and worker.alive else Worker(readable=readable)
    try:
        worker.ready()
    except WorkerFailed as exc:
        raise InputError(f"a controller's process did not start: {exc.why}",
                         hint="is mexone importable by this Python?") from None
    return worker


def _describe_in(worker: Worker, ctype: str, yaml_dir: Path | None, shipped: list[str],
                 found: Found | None = None) -> ClassInfo:
    timeout = watchdog.STUDENT_SETUP_TIMEOUT
    found = found or locate(ctype, yaml_dir, shipped)
    what = {"file": Path(found.name).name, "module": f"module {found.name}"}.get(
        found.kind, f"entry point {found.name}")
    if found.kind == "file":
        worker.file = found.name
    try:
        obj = worker.call({"call": "describe", "type": ctype, "yaml_dir": str(yaml_dir or ""),
                           "path": list(sys.path), "found": [found.kind, found.name,
                                                             found.cls_name]}, timeout)
    except StudentFault as exc:
        raise InputError(f"importing {what} failed: {exc}") from None
    except WorkerFailed as exc:
        where = f" ({'interrupted' if exc.hung else 'at'} {worker.file}:{exc.line})" \
            if exc.line and worker.file else ""
        said = f"did not finish within {number_text(timeout)} s" if exc.hung else \
            f"failed: {exc.why}"
        raise InputError(f"importing {what} {said}{where}",
                         hint="fix the file; Reload imports it again") from None
    try:
        info = ClassInfo.checked(obj)
        stand_in(info)
    except WireError as exc:
        worker.kill()
        raise InputError(f"importing {ctype}: the controller's process sent what mexone cannot "
                         f"read ({exc})") from None
    worker.file = info.file
    return info


def claim(info: ClassInfo, ctype: str, yaml_dir: Path | None) -> Worker:
    """A worker that imported `info`'s class: the one `describe` kept, else a new one (which
    must find the same class: a file edited since the YAML was read is refused in one line)."""
    with _lock:
        for entry in _pool:
            if entry.info is info:
                _pool.remove(entry)
                if entry.worker.alive and info.current():
                    return entry.worker
                entry.worker.kill()
                break
    found = locate(ctype, yaml_dir, [])
    worker = _start(_readable(found, yaml_dir))
    try:
        now = _describe_in(worker, ctype, yaml_dir, [], found)
    except BaseException:
        worker.kill()
        raise
    if (now.command_interface, now.params, now.exports, now.inputs) != \
            (info.command_interface, info.params, info.exports, info.inputs):
        worker.kill()
        raise InputError(f"{Path(info.file).name} changed since the controllers were read",
                         hint="load them again (Reload)")
    return worker


def resolve(ctype: str, yaml_dir: Path | None, shipped: list[str], fresh: bool = False,
            classes: dict[str, type] | None = None) -> tuple[type[PythonController], str]:
    """The class for `type:` `ctype`: one handed over in `classes` (the caller's own, in its
    process), mexone's own (imported here), else the student's, described by its worker (a
    stand-in class here)."""
    if classes and ctype in classes:
        cls = classes[ctype]
        if not (isinstance(cls, type) and issubclass(cls, PythonController)):
            raise InputError(f"classes['{ctype}'] is not a mexone.control.PythonController")
        return cls, f"class {cls.__qualname__} handed over in Python"
    found = locate(ctype, yaml_dir, shipped)
    if found.own:
        from mexone.control.resolve import resolve_class

        return resolve_class(ctype, yaml_dir, shipped, fresh)
    info = describe(ctype, yaml_dir, shipped, fresh, found)
    return stand_in(info), info.origin
