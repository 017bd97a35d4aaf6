"""The wire between mexone and a student's process: frames of one kind byte, a length and a
payload (bytes, or JSON text for structured messages), and descriptors (a shared-memory block)
handed over on a socket of their own. Never a pickle: what a student's process sends is data,
read with a size limit and `json.loads`, so no object of its making reaches mexone.

`Channel` is one end. mexone's end never blocks past a deadline: `receive` takes a timeout, and
`send` gives up when the other side stops reading; a process that hangs or floods is the
caller's to end (its `StudentProcess.kill`). A frame with no payload is five bytes: what a
lockstep loop sends each way per cycle (`frame`).
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import socket
import struct
import time

__all__ = ["Channel", "WireError", "MAX_FRAME", "pair", "frame"]

MAX_FRAME = 1 << 20  # bytes one frame may carry (a report, a class's description, a fault)
_HEADER = struct.Struct("<cI")  # kind (one byte), payload length
_CHUNK = 1 << 16


class WireError(Exception):
    """The other side hung up, sent what the protocol does not allow, or stopped reading."""


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

    def hand_over(self, descriptors: tuple[int, ...]) -> None:
        """Descriptors for the other side (which `take`s them), on the descriptor socket."""
        try:
            socket.send_fds(self.fds, [b"d"], list(descriptors))
        except OSError as exc:
            raise WireError(f"the other side hung up ({exc.strerror})") from None

    def take(self, count: int) -> list[int]:
        """The student's end: the `count` descriptors mexone handed over with its last call."""
        _, fds, _, _ = socket.recv_fds(self.fds, 1, count)
        if len(fds) != count:
            for fd in fds:
                os.close(fd)
            raise WireError(f"{len(fds)} descriptors, not {count}")
        return fds

    def introduce(self) -> None:
        """The student's end, once: one byte on the descriptor socket, whose credentials the
        kernel attaches (`peer`)."""
        self.fds.sendall(b"c")

    def peer(self, timeout: float) -> int | None:
        """mexone's end: the pid (as this process sees it: a PID namespace translated) of the
        process that `introduce`d itself, as the kernel says, not as it might claim; None where
        the kernel does not say (not Linux) or nothing came within `timeout` s."""
        cred = getattr(socket, "SCM_CREDENTIALS", None)
        if cred is None or not select.select([self.fds], [], [], timeout)[0]:
            return None
        try:
            _, ancillary, _, _ = self.fds.recvmsg(1, socket.CMSG_SPACE(struct.calcsize("3i")))
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
    def json(payload: bytes) -> object:
        """A JSON payload as data (WireError if it is not JSON)."""
        try:
            return json.loads(payload)
        except (ValueError, RecursionError) as exc:
            raise WireError(f"a message that is not JSON ({type(exc).__name__})") from None

    def close(self) -> None:
        for sock in (self.sock, self.fds):
            if sock is not None:
                with contextlib.suppress(OSError):
                    sock.close()
