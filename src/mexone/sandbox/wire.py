"""The wire between mexone and a student's process, and what may cross it: data, never a pickle.

Framing: frames of one kind byte, a length and a payload (bytes, or JSON text for structured
messages), and descriptors (a shared-memory block) handed over on a socket of their own.
`Channel` is one end. mexone's end never blocks past a deadline: `receive` takes a timeout, and
`send` gives up when the other side stops reading; a process that hangs or floods is the
caller's to end (its `StudentProcess.kill`). A frame with no payload is five bytes: what a
lockstep loop sends each way per cycle (`frame`).

Payloads: `dumps(value)` writes plain data, dataclasses (their fields and their class's name
under "$"), numpy arrays (dtype, shape and the raw bytes in base64, under "$a") and bytes (base64
under "$b"). `loads(data, schema)` (and `Channel.json(payload, schema)`) reads it back only as
`schema` says: `float`, `int`, `bool`, `str`, `bytes`, `None`, `Path`, `numpy.ndarray`,
`list[X]`, `tuple[X, ...]`, `tuple[X, Y]`, `dict[str, X]`, `X | Y`, a dataclass (its fields'
annotations, recursively) or `object` (plain JSON only). A class is never looked up by a name
the sender chose: a dataclass is read only where the schema names it, the "$" tag only picks
among the schema's own alternatives. Whatever does not fit, is not JSON, is too large or too
deep is a WireError naming where (`result[2].position: expected float, got str`).
"""

from __future__ import annotations

import base64
import contextlib
import dataclasses
import json
import math
import os
import select
import socket
import struct
import time
import types
import typing
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["Channel", "WireError", "MAX_FRAME", "pair", "frame", "dumps", "loads", "plain", "read",
           "MAX_BYTES", "PLAIN"]

MAX_FRAME = 1 << 20  # bytes one frame may carry (a report, a class's description, a fault)
MAX_BYTES = 64 << 20  # the largest message `loads` reads (a graded run's samples are under 1 MB)
MAX_DEPTH = 64
PLAIN = object  # the schema of plain JSON: dicts, lists, strings, numbers, booleans, None
_DTYPES = ("float64", "float32", "int64", "int32", "int8", "uint8", "bool")
_HEADER = struct.Struct("<cI")  # kind (one byte), payload length
_CHUNK = 1 << 16


class WireError(Exception):
    """The other side hung up, stopped reading, or sent what the protocol or the schema does
    not allow (or what is not JSON); also what cannot be sent."""


def frame(kind: bytes, payload: bytes = b"") -> bytes:
    """A frame's bytes (build a payload-less one once, send it every cycle)."""
    return _HEADER.pack(kind, len(payload)) + payload


def pair() -> tuple[Channel, tuple[socket.socket, socket.socket]]:
    """A Channel for mexone's end, and the other end's two sockets (frames, descriptors) to hand
    to the student's process (`pass_fds`; close them here once it started)."""
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    our_fds, their_fds = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    with contextlib.suppress(AttributeError, OSError):  # the kernel tells us who writes (Linux)
        our_fds.setsockopt(socket.SOL_SOCKET, socket.SO_PASSCRED, 1)
    return Channel(ours, our_fds), (theirs, their_fds)


class Channel:
    """One end of a frame socket (and of its descriptor socket, `fds`). `student`: the student's
    end, which blocks as a pipe does; mexone's end never does. `max_frame`: the largest payload
    accepted from the other side."""

    def __init__(self, sock: socket.socket, fds: socket.socket | None = None,
                 max_frame: int = MAX_FRAME, student: bool = False):
        self.sock, self.fds = sock, fds
        self.fd = sock.fileno()
        self.max_frame = max_frame
        self.student = student
        self._buf = bytearray()
        self._timeout: float | None = None  # the kernel's receive timeout now (None: none)

    # ----- sending ------------------------------------------------------------------------------
    def send(self, kind: bytes, payload: bytes = b"", timeout: float = 10.0) -> None:
        """One frame. mexone's end gives up after `timeout` s of the other side not reading
        (WireError); the student's end blocks."""
        self.send_frame(_HEADER.pack(kind, len(payload)) + payload, timeout)

    def send_frame(self, data: bytes, timeout: float = 10.0) -> None:
        """A frame's bytes (`frame`)."""
        if self.student:
            try:
                self.sock.sendall(data)
            except OSError as exc:
                raise WireError(f"the other side hung up ({exc.strerror})") from None
            return
        try:
            written = self.sock.send(data, socket.MSG_DONTWAIT)  # usually all of it at once
        except BlockingIOError:
            written = 0
        except OSError as exc:
            raise WireError(f"the other side hung up ({exc.strerror})") from None
        if written < len(data):
            self._send_rest(memoryview(data)[written:], timeout)

    def _send_rest(self, data: memoryview, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        out = select.poll()
        out.register(self.fd, select.POLLOUT)
        while data:
            left = deadline - time.monotonic()
            if left <= 0 or not out.poll(left * 1e3):
                raise WireError("the other side stopped reading")
            try:
                data = data[self.sock.send(data, socket.MSG_DONTWAIT):]
            except BlockingIOError:
                continue
            except OSError as exc:
                raise WireError(f"the other side hung up ({exc.strerror})") from None

    def send_json(self, kind: bytes, obj: object, timeout: float = 10.0) -> None:
        self.send(kind, json.dumps(obj, separators=(",", ":")).encode(), timeout)

    def _fds(self) -> socket.socket:
        assert self.fds is not None, "a channel without its descriptor socket"  # pair() makes one
        return self.fds

    def hand_over(self, descriptors: tuple[int, ...]) -> None:
        """Descriptors for the other side (which `take`s them), on the descriptor socket."""
        try:
            socket.send_fds(self._fds(), [b"d"], list(descriptors))
        except OSError as exc:
            raise WireError(f"the other side hung up ({exc.strerror})") from None

    def take(self, count: int) -> list[int]:
        """The student's end: the `count` descriptors mexone handed over with its last call."""
        _, fds, _, _ = socket.recv_fds(self._fds(), 1, count)
        if len(fds) != count:
            for fd in fds:
                os.close(fd)
            raise WireError(f"{len(fds)} descriptors, not {count}")
        return fds

    def introduce(self) -> None:
        """The student's end, once: one byte on the descriptor socket, whose credentials the
        kernel attaches (`peer`)."""
        self._fds().sendall(b"c")

    def peer(self, timeout: float) -> int | None:
        """mexone's end: the pid (as this process sees it: a PID namespace translated) of the
        process that `introduce`d itself, as the kernel says, not as it might claim; None where
        the kernel does not say (not Linux) or nothing came within `timeout` s."""
        cred = getattr(socket, "SCM_CREDENTIALS", None)
        if cred is None:
            return None
        fds = self._fds()
        if not select.select([fds], [], [], timeout)[0]:
            return None
        try:
            _, ancillary, _, _ = fds.recvmsg(1, socket.CMSG_SPACE(struct.calcsize("3i")))
        except OSError:
            return None
        for level, kind, data in ancillary:
            if level == socket.SOL_SOCKET and kind == cred and len(data) >= 12:
                return struct.unpack("3i", data[:12])[0]
        return None

    # ----- receiving ----------------------------------------------------------------------------
    def receive(self, timeout: float | None = None) -> tuple[bytes, bytes] | None:
        """The next frame (kind, payload), or None if none came within `timeout` s (None: wait
        as long as it takes). WireError on a hang-up or an oversized frame. One read when a
        frame is there or comes (the kernel keeps the timeout: no poll before it)."""
        if self._buf:
            found = self._frame()
            if found is not None:
                return found
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            if deadline is None:
                self._expire(None)
            else:
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._expire(left)
            try:
                data = os.read(self.fd, _CHUNK)
            except (BlockingIOError, InterruptedError):  # the timeout passed (or a signal)
                continue
            except OSError as exc:
                raise WireError(f"the other side hung up ({exc.strerror})") from None
            if not data:
                raise WireError("the other side hung up")
            if not self._buf and len(data) >= _HEADER.size:  # the lockstep's usual: one frame
                kind, size = _HEADER.unpack_from(data)
                if len(data) == _HEADER.size + size:
                    return kind, data[_HEADER.size:]
            self._buf += data
            found = self._frame()
            if found is not None:
                return found

    def _expire(self, seconds: float | None) -> None:
        """The kernel's receive timeout (SO_RCVTIMEO: up to 2 ms above `seconds`), set only when
        that is not already so: the same timeout every cycle costs no syscall."""
        current = self._timeout
        if seconds is None:
            if current is None:
                return
            whole, micro = 0, 0
        else:
            if current is not None and 0.0 <= current - seconds < 2e-3:
                return
            whole, micro = divmod(max(1000, int(seconds * 1e6) + 1000), 1_000_000)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, struct.pack("ll", whole, micro))
        self._timeout = None if seconds is None else (whole + micro / 1e6)

    def _frame(self) -> tuple[bytes, bytes] | None:
        buf = self._buf
        if len(buf) < _HEADER.size:
            return None
        kind, size = _HEADER.unpack_from(buf)
        if size > self.max_frame:
            raise WireError(f"a frame of {size} bytes (at most {self.max_frame})")
        end = _HEADER.size + size
        if len(buf) < end:
            return None
        payload = bytes(buf[_HEADER.size:end])
        del buf[:end]
        return kind, payload

    @staticmethod
    def json(payload: bytes, schema: object = PLAIN, where: str = "message") -> typing.Any:
        """A JSON payload read as `schema` says (`loads`; WireError if it is not JSON or does
        not fit)."""
        return loads(payload, schema, where)

    def close(self) -> None:
        for sock in (self.sock, self.fds):
            if sock is not None:
                with contextlib.suppress(OSError):
                    sock.close()


# ----- payloads: JSON against a schema ---------------------------------------------------------------
def _plain(value: object, depth: int = 0) -> object:
    if depth > MAX_DEPTH:
        raise WireError("nested too deeply")
    if value is None or isinstance(value, bool | int | str):
        return value
    if isinstance(value, float):
        return value
    if isinstance(value, bytes | bytearray | memoryview):
        return {"$b": base64.b64encode(bytes(value)).decode()}
    if isinstance(value, Path):
        return str(value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        out: dict[str, object] = {"$": type(value).__name__}
        for f in dataclasses.fields(value):
            out[f.name] = _plain(getattr(value, f.name), depth + 1)
        return out
    if isinstance(value, dict):
        return {str(k): _plain(v, depth + 1) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [_plain(v, depth + 1) for v in value]
    numpy = _numpy()
    if numpy is not None:
        if isinstance(value, numpy.ndarray):
            dtype = value.dtype.name if value.dtype.name in _DTYPES else "float64"
            data = numpy.asarray(value, dtype=dtype).tobytes()  # C order, any layout, 0-d too
            return {"$a": [dtype, list(value.shape), base64.b64encode(data).decode()]}
        if isinstance(value, numpy.generic):
            return _plain(value.item(), depth)
    raise WireError(f"cannot send a {type(value).__name__}")


def plain(value: object) -> object:
    """`value` as the plain data `dumps` writes (WireError for what cannot be sent)."""
    return _plain(value)


def dumps(value: object) -> bytes:
    """`value` as JSON bytes (NaN and infinities as JSON's common extension)."""
    try:
        return json.dumps(_plain(value), separators=(",", ":")).encode()
    except WireError:
        raise
    except (TypeError, ValueError, RecursionError) as exc:
        raise WireError(f"cannot send it: {exc}") from None


def loads(data: bytes | str, schema: object = PLAIN, where: str = "result") -> object:
    """`data` read as `schema` says (WireError if it does not fit)."""
    if len(data) > MAX_BYTES:
        raise WireError(f"{where}: {len(data)} bytes, more than {MAX_BYTES >> 20} MB")
    try:
        raw = json.loads(data)
    except (ValueError, RecursionError) as exc:
        raise WireError(f"{where}: not JSON ({type(exc).__name__})") from None
    return read(raw, schema, where)


def read(raw: object, schema: object, where: str = "result", depth: int = 0) -> object:
    """Decoded JSON `raw` checked and built as `schema` says."""
    if depth > MAX_DEPTH:
        raise WireError(f"{where}: nested too deeply")
    origin = typing.get_origin(schema)
    args = typing.get_args(schema)
    if schema is typing.Any or schema is object:
        return _check_plain(raw, where, depth)
    if schema is None or schema is type(None):
        if raw is not None:
            raise _expected("None", raw, where)
        return None
    if origin in (typing.Union, types.UnionType):
        tag = raw.get("$") if isinstance(raw, dict) else None
        errors = []
        for option in args:
            if tag is not None and isinstance(option, type) and dataclasses.is_dataclass(option) \
                    and option.__name__ != tag:
                continue
            try:
                return read(raw, option, where, depth)
            except WireError as exc:
                errors.append(exc)
        if errors and len(errors) == 1:
            raise errors[0]
        raise WireError(f"{where}: {_shown(raw)} is none of {_names(args)}")
    if schema is float:
        if isinstance(raw, bool) or not isinstance(raw, int | float):
            raise _expected("float", raw, where)
        return float(raw)
    if schema is int:
        if isinstance(raw, bool) or not isinstance(raw, int):
            raise _expected("int", raw, where)
        return raw
    if schema is bool:
        if not isinstance(raw, bool):
            raise _expected("bool", raw, where)
        return raw
    if schema is str:
        if not isinstance(raw, str):
            raise _expected("str", raw, where)
        return raw
    if schema is bytes:
        return _bytes(raw, where)
    if schema is Path:
        if not isinstance(raw, str):
            raise _expected("a path", raw, where)
        return Path(raw)
    if origin in (list, Sequence) or schema is list:
        if not isinstance(raw, list):
            raise _expected("list", raw, where)
        item = args[0] if args else object
        if item is float and all(type(x) is float for x in raw):  # the common case, quickly
            return raw
        return [read(x, item, f"{where}[{i}]", depth + 1) for i, x in enumerate(raw)]
    if origin is tuple or schema is tuple:
        if not isinstance(raw, list):
            raise _expected("tuple", raw, where)
        if not args or (len(args) == 2 and args[1] is Ellipsis):
            item = args[0] if args else object
            return tuple(read(x, item, f"{where}[{i}]", depth + 1) for i, x in enumerate(raw))
        if len(raw) != len(args):
            raise WireError(f"{where}: {len(raw)} items, expected {len(args)}")
        return tuple(read(x, t, f"{where}[{i}]", depth + 1)
                     for i, (x, t) in enumerate(zip(raw, args, strict=True)))
    if origin is dict or schema is dict:
        if not isinstance(raw, dict):
            raise _expected("dict", raw, where)
        key, value = args if args else (str, object)
        if key not in (str, typing.Any, object):
            raise WireError(f"{where}: a schema's dict keys are str")
        return {k: read(v, value, f"{where}[{k!r}]", depth + 1) for k, v in raw.items()}
    numpy = _numpy()
    if numpy is not None and schema is numpy.ndarray:
        return _array(raw, where, numpy)
    if dataclasses.is_dataclass(schema) and isinstance(schema, type):
        return _dataclass(raw, schema, where, depth)
    raise WireError(f"{where}: the schema {schema!r} is not one this module reads")


def _dataclass(raw: object, cls: type, where: str, depth: int) -> object:
    if not isinstance(raw, dict):
        raise _expected(cls.__name__, raw, where)
    if raw.get("$", cls.__name__) != cls.__name__:
        raise WireError(f"{where}: a {_shown(raw.get('$'))}, expected {cls.__name__}")
    hints = _hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(raw) - set(fields) - {"$"})
    if unknown:
        raise WireError(f"{where}: {cls.__name__} has no field {unknown[0]!r}")
    values = {}
    for name, f in fields.items():
        if name in raw:
            values[name] = read(raw[name], hints.get(name, object), f"{where}.{name}", depth + 1)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise WireError(f"{where}: {cls.__name__}'s field {name!r} is missing")
    try:
        return cls(**values)
    except Exception as exc:  # noqa: BLE001 - a class's own checks refusing the values
        raise WireError(f"{where}: {cls.__name__}: {exc}") from None


_HINTS: dict[type, dict[str, Any]] = {}


def _hints(cls: type) -> dict[str, Any]:
    hints = _HINTS.get(cls)
    if hints is None:
        hints = _HINTS[cls] = typing.get_type_hints(cls)
    return hints


def _bytes(raw: object, where: str) -> bytes:
    if not (isinstance(raw, dict) and set(raw) == {"$b"} and isinstance(raw["$b"], str)):
        raise _expected("bytes", raw, where)
    try:
        return base64.b64decode(raw["$b"], validate=True)
    except ValueError:
        raise WireError(f"{where}: bytes that are not base64") from None


def _array(raw: object, where: str, numpy: types.ModuleType) -> Any:  # a numpy array
    if isinstance(raw, list):  # a list of numbers is an array too
        try:
            array = numpy.asarray(raw, dtype=float)
        except (TypeError, ValueError):
            raise _expected("an array of numbers", raw, where) from None
        return array
    if not (isinstance(raw, dict) and set(raw) == {"$a"} and isinstance(raw["$a"], list)
            and len(raw["$a"]) == 3):
        raise _expected("an array", raw, where)
    dtype, shape, data = raw["$a"]
    if dtype not in _DTYPES or not isinstance(shape, list) or len(shape) > 8 \
            or not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in shape):
        raise WireError(f"{where}: an array of dtype {_shown(dtype)}, shape {_shown(shape)}")
    buffer = _bytes({"$b": data}, where)
    size = math.prod(shape) * numpy.dtype(dtype).itemsize
    if size != len(buffer):
        raise WireError(f"{where}: an array of shape {shape} with {len(buffer)} bytes")
    return numpy.frombuffer(buffer, dtype=dtype).reshape(shape).copy()


def _check_plain(raw: object, where: str, depth: int) -> object:
    if depth > MAX_DEPTH:
        raise WireError(f"{where}: nested too deeply")
    if isinstance(raw, list):
        for i, x in enumerate(raw):
            _check_plain(x, f"{where}[{i}]", depth + 1)
    elif isinstance(raw, dict):
        for k, v in raw.items():
            _check_plain(v, f"{where}[{k!r}]", depth + 1)
    return raw


def _numpy() -> typing.Any:
    import sys

    return sys.modules.get("numpy")


def _expected(what: str, raw: object, where: str) -> WireError:
    return WireError(f"{where}: expected {what}, got {_shown(raw)}")


def _shown(raw: object) -> str:
    if isinstance(raw, dict):
        return "an object"
    if isinstance(raw, list):
        return "a list"
    text = repr(raw)
    return f"{type(raw).__name__} {text[:40]}"


def _names(options: tuple[object, ...]) -> str:
    return ", ".join(getattr(o, "__name__", repr(o)) for o in options)
