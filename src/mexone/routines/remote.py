"""A routine in a process of its own, in lockstep with the simulation in another: the routine's
side, and the wire both sides speak. The simulator's side is routines.isolated.

The routine's process is a fresh interpreter (``python -m mexone.routines.remote FD CPU MB PID``),
never a fork of the simulator: it has no lab, no model and nothing of a grader's in its memory,
only what the simulator sends it (the routine's path, its node name, the parameters, the time,
the messages of its subscriptions). Its ``mexone.rospy`` is the same module as in ``mexone run``,
over a RoutineContext whose lab and scheduler are stand-ins: publishes, subscriptions, parameters
and log lines are queued and go with the routine's next wait; a wait (Rate.sleep, rospy.sleep,
spin, wait_for_message) is one round trip, answered when the simulation reached the wake-up time
or delivered messages, which come back with the answer and run in the routine's thread as they
do in-process. Anything else of the lab (its model, mexone.motion's helpers that need it) is not
offered: it raises one clear error.

What crosses is JSON (mexone.sandbox.wire), read against the protocol's schema, never a pickle:
requests and answers are lists of plain data, a message is a mexone.msgs dataclass read as the
class its topic was advertised or subscribed with (a routine names a message type by its name,
which the simulator looks up among mexone.msgs' messages only). The routine's process is a jail
(mexone.sandbox.spawn): it reads the routine and Python, writes its scratch folder only.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import select
import socket
import struct
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from types import SimpleNamespace

__all__ = ["send", "receive", "receive_bytes", "plain", "ProtocolError", "NotOffered",
           "main", "MAX_FRAME", "message_type", "message", "type_name"]

MAX_FRAME = 64 << 20  # bytes one message may have (a routine's 10 GB message ends it)
_HEADER = struct.Struct("!I")


class ProtocolError(Exception):
    """The other side sent what the protocol does not allow (or hung up)."""


class NotOffered(Exception):  # noqa: N818 - what the routine asked for
    """The routine asked its process for something only the simulator has (the lab's model)."""


def send(sock: socket.socket, obj: object) -> None:
    """One message: its length, then its JSON (mexone.sandbox.wire)."""
    from mexone.sandbox import wire

    try:
        data = wire.dumps(obj)
    except wire.WireError as exc:
        raise ProtocolError(str(exc)) from None
    sock.sendall(_HEADER.pack(len(data)) + data)


def receive_bytes(sock: socket.socket, poll: Callable[[], None] | None = None) -> bytes:
    """One message's bytes; `poll()` runs every 50 ms while none arrives (so a thread waiting
    here can be interrupted). ProtocolError on a hang-up or an oversized message."""
    header = _read(sock, _HEADER.size, poll)
    (size,) = _HEADER.unpack(header)
    if size > MAX_FRAME:
        raise ProtocolError(f"a message of {size} bytes (at most {MAX_FRAME >> 20} MB)")
    return _read(sock, size, poll)


def receive(sock: socket.socket, poll: Callable[[], None] | None = None) -> list:
    """One message: a non-empty list of plain JSON (its parts are read against their own
    schemas by the receiver: `message`); ProtocolError for anything else."""
    from mexone.sandbox import wire

    try:
        value = wire.loads(receive_bytes(sock, poll), list, "message")
    except wire.WireError as exc:
        raise ProtocolError(str(exc)) from None
    if not value:
        raise ProtocolError("an empty message")
    return value


def _read(sock: socket.socket, size: int, poll: Callable[[], None] | None) -> bytes:
    buf = bytearray()
    while len(buf) < size:
        if poll is not None:
            while not select.select([sock], [], [], 0.05)[0]:
                poll()
        chunk = sock.recv(min(size - len(buf), 1 << 20))
        if not chunk:
            raise ProtocolError("the other side hung up")
        buf += chunk
    return bytes(buf)


def message_type(name: object) -> type:
    """The mexone.msgs message class of this name (ProtocolError for any other name)."""
    from mexone.bus import msgs

    found = getattr(msgs, name, None) if isinstance(name, str) and name in msgs.__all__ else None
    if not (isinstance(found, type) and dataclasses.is_dataclass(found)):
        raise ProtocolError(f"{str(name)[:60]!r} is not a message type of mexone.msgs: a routine "
                            "graded in its own process sends mexone.msgs messages and plain data")
    return found


def type_name(msg_type: type) -> str:
    """What names `msg_type` on the wire (its class's name, a message of mexone.msgs)."""
    return getattr(msg_type, "__name__", str(msg_type))


def message(raw: object, msg_type: type) -> object:
    """A message received, read as `msg_type` (ProtocolError if it is not one)."""
    from mexone.sandbox import wire

    try:
        return wire.read(raw, msg_type, "message")
    except wire.WireError as exc:
        raise ProtocolError(str(exc)) from None


def plain(value: object, depth: int = 0) -> bool:
    """Whether `value` is plain data (what a parameter server holds)."""
    if depth > 20:
        return False
    if value is None or isinstance(value, bool | int | float | str):
        return True
    if isinstance(value, list | tuple):
        return all(plain(v, depth + 1) for v in value)
    if isinstance(value, dict):
        return all(isinstance(k, str) and plain(v, depth + 1) for k, v in value.items())
    return False


# ----- the routine's process ------------------------------------------------------------------
class _Client:
    """The routine's end of the socket: queued one-way requests, and calls that wait for an
    answer (one at a time: a thread the routine started waits its turn)."""

    def __init__(self, sock: socket.socket):
        self.sock = sock
        self.pid = os.getpid()
        self.queue: list[tuple] = []
        self.queue_lock = threading.Lock()
        self.call_lock = threading.Lock()
        self.time = 0.0
        self.time_ns = 0
        self.callbacks: dict[int, Callable[[object], None]] = {}
        self.types: dict[int, type] = {}  # each subscription's message type
        self.next_id = 0
        self.stopped = False

    def post(self, *request: object) -> None:
        with self.queue_lock:
            self.queue.append(request)

    def call(self, *request: object) -> list:
        from mexone.routines.runtime import Forked

        if os.getpid() != self.pid:
            raise Forked  # a fork of the routine shares this socket: it must not talk on it
        with self.call_lock:
            with self.queue_lock:
                queued, self.queue = self.queue, []
            send(self.sock, (queued, request))
            return receive(self.sock)

    def log(self, level: str, text: str) -> None:
        self.post("log", level, text)


class _Everything(set):
    """warned_topics on the routine's side: every topic counts as warned about, as the simulator
    side (which knows the controllers) says when a command topic has no subscriber."""

    def __contains__(self, item: object) -> bool:
        return True


def _not_offered(what: str) -> NotOffered:
    return NotOffered(f"{what} is not offered to a routine graded in its own process: it has no "
                      "lab and no model, only mexone.rospy's topics, parameters, time and log "
                      "(docs/exercises.md)")


class _Sim:
    def __init__(self, client: _Client):
        self._client = client

    @property
    def time(self) -> float:
        return self._client.time

    @property
    def time_ns(self) -> int:
        return self._client.time_ns

    def __getattr__(self, name: str):
        raise _not_offered(f"the simulation's '{name}'")


class _Subscription:
    def __init__(self, client: _Client, sid: int):
        self._client, self._sid = client, sid

    def unregister(self) -> None:
        if self._client.callbacks.pop(self._sid, None) is not None:
            self._client.post("unsub", self._sid)


class _Bus:
    """The lab's bus as rospy uses it: advertise, publish, subscribe, subscriber counts."""

    def __init__(self, client: _Client):
        self._client = client

    def advertise(self, name: str, msg_type: type) -> None:
        self._client.post("adv", name, type_name(msg_type))

    def publish(self, name: str, msg: object) -> None:
        from mexone.sandbox import wire

        try:  # here, so a message that cannot cross fails at the routine's publish
            data = wire.plain(msg)
        except wire.WireError as exc:
            raise ProtocolError(f"{type_name(type(msg))} cannot be sent to the simulator: "
                                f"{exc} (a routine graded in its own process sends mexone.msgs "
                                "messages and plain data)") from None
        self._client.post("pub", name, data)

    def subscribe(self, name: str, msg_type: type, callback: Callable[[object], None],
                  latched: bool = False, node: str = "") -> _Subscription:
        client = self._client
        with client.queue_lock:
            sid = client.next_id = client.next_id + 1
        client.callbacks[sid] = callback
        client.types[sid] = msg_type
        client.post("sub", sid, name, type_name(msg_type), node)
        return _Subscription(client, sid)

    @property
    def topics(self) -> _Topics:
        return _Topics(self._client)

    def __getattr__(self, name: str):
        raise _not_offered(f"the bus's '{name}'")


class _Topics:
    def __init__(self, client: _Client):
        self._client = client

    def get(self, name: str):
        (_, count) = self._client.call("count", name)
        return SimpleNamespace(subscriptions=[None] * int(count))


class _Lab:
    def __init__(self, client: _Client):
        self.sim = _Sim(client)
        self.bus = _Bus(client)
        self.controllers = None

    def __getattr__(self, name: str):
        raise _not_offered(f"the lab's '{name}' (mexone.motion's helpers need it)")


class _Params(dict):
    """The parameter server as the routine sees it: a copy; what it sets goes to the simulator
    too (plain data only: a parameter server holds no objects)."""

    def __init__(self, client: _Client, values: dict):
        super().__init__(values)
        self._client = client

    def __setitem__(self, key: str, value: object) -> None:
        super().__setitem__(key, value)
        if plain(value):
            self._client.post("param", key, value)

    def __delitem__(self, key: str) -> None:
        super().__delitem__(key)
        self._client.post("unparam", key)


class _Scheduler:
    """runtime.Scheduler's routine side, over the socket."""

    def __init__(self, client: _Client):
        self.client = client
        self.pid = client.pid
        self.owner = threading.get_ident()
        self.context = None

    @property
    def stopped(self) -> bool:
        return self.client.stopped

    def wait(self, wake: float, ready: Callable[[], bool] | None = None) -> None:
        from mexone.routines.runtime import Forked, Shutdown

        if os.getpid() != self.pid:
            raise Forked
        if threading.get_ident() != self.owner:
            raise Shutdown  # only the routine's own thread waits on the clock, as in-process
        if math.isnan(wake):
            raise ValueError("cannot wait until a NaN time")
        client = self.client
        while True:
            if client.stopped:
                raise Shutdown
            self.context.run_callbacks()
            if (ready is not None and ready()) or client.time >= wake - 1e-9:
                return
            answer = client.call("wait", wake)
            if answer[0] != "time":
                client.stopped = True
                raise Shutdown
            _, client.time, client.time_ns, delivered = answer
            for sid, raw in delivered:
                callback = client.callbacks.get(sid)
                if callback is not None:
                    callback(message(raw, client.types[sid]))

    @contextmanager
    def busy(self, what: str) -> Iterator[None]:
        yield


def _context_class():
    from mexone.routines.runtime import RoutineContext

    class _Context(RoutineContext):
        """The routine's context; its node's name (init_node's) goes to the simulator too."""

        def __setattr__(self, name: str, value: object) -> None:
            super().__setattr__(name, value)
            if name == "node_name" and isinstance(self.params, _Params):
                self.params._client.post("node", value)

    return _Context


def _run(path: Path) -> tuple[str | None, int | None]:
    """The routine, as RoutineRunner._main runs it in a thread: (its error, its line)."""
    import traceback

    from mexone.routines import sandbox
    from mexone.routines.runtime import Shutdown

    try:
        sandbox.run_path(path)
    except Shutdown:
        pass
    except sandbox.RoutineExit as exc:
        return str(exc), None
    except SystemExit as exc:
        if exc.code not in (None, 0):
            return f"routine exited with status {exc.code}", None
    except BaseException as exc:  # noqa: BLE001 - the student's error, shown as their traceback
        if isinstance(exc, KeyboardInterrupt):
            exc = KeyboardInterrupt("the routine raised KeyboardInterrupt (only the simulation "
                                    "stops routines)")
        tb = sys.exc_info()[2]
        lines = [f.lineno for f in traceback.extract_tb(tb) if f.filename == str(path)]
        return sandbox.students_traceback(exc, path, tb), (lines[-1] if lines else None)
    return None, None


def main(argv: list[str] | None = None) -> None:
    """The routine's process (FD), in its jail (mexone.sandbox.spawn: its limits, its end with
    the simulator's): the routine, then one last message."""
    fd = (argv or sys.argv[1:])[0]
    sock = socket.socket(fileno=int(fd))
    code = 0
    try:
        from mexone.routines import processes, runtime, sandbox

        _Context = _context_class()  # noqa: N806 - a class
        client = _Client(sock)
        _, path, node, params, client.time, client.time_ns, private, remap = receive(sock)
        path = Path(path)
        for key, value in private.items():  # the same objects, as init_node tells them by identity
            if params.get(f"{node}/{key}") == value:
                params[f"{node}/{key}"] = value
        scheduler = _Scheduler(client)
        context = _Context(_Lab(client), scheduler, _Params(client, params), client.log,
                           node_name=node, source=str(path), warned_topics=_Everything(),
                           private=private, name_remap=remap)
        scheduler.context = context
        sandbox.install()
        before = processes.children()
        send(sock, ([], ("ready",)))  # no answer: the simulator serves the routine from here
        runtime.bind(context)
        error, line = _run(path)
        runtime.bind(None)
        errors = list(context.errors) + sandbox.stop_children(before)
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        with contextlib.suppress(ProtocolError, OSError):
            client.call("end", error, line, errors)
    except BaseException:  # noqa: BLE001 - the simulator reports a process that ends early
        code = 3
    finally:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        from mexone.routines import sandbox

        sandbox._real.get("_exit", os._exit)(code)


if __name__ == "__main__":
    main()
