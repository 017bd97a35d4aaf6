"""The wire between mexone and a student's process: frames of one kind byte, a length and a
payload (bytes, or JSON text for structured messages), with file descriptors beside them where a
frame hands one over (a shared-memory block). Never a pickle: what a student's process sends is
data, read with a size limit and `json.loads`, so no object of its making reaches mexone.

`Channel` is one end of a socketpair. mexone's end never blocks past a deadline: `receive`
takes a timeout, and `send` gives up when the other side stops reading; a process that hangs
or floods is the caller's to end (its `StudentProcess.kill`).
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import socket
import struct
import time

__all__ = ["Channel", "WireError", "MAX_FRAME", "pair"]

MAX_FRAME = 1 << 20  # bytes one frame may carry (a report, a class's description, a fault)
_HEADER = struct.Struct("<cI")  # kind (one byte), payload length
_CHUNK = 1 << 16


class WireError(Exception):
    """The other side hung up, sent what the protocol does not allow, or stopped reading."""


def pair() -> tuple[Channel, socket.socket]:
    """A Channel for mexone's end, and the other end's socket to hand to the student's process
    (`pass_fds`; close it here once the process started)."""
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    return Channel(ours), theirs


class Channel:
    """One end of a frame socket. `max_frame`: the largest payload accepted from the other side;
    `with_fds`: receive descriptors the other side hands over (the student's end, which gets its
    shared memory this way)."""

    def __init__(self, sock: socket.socket, max_frame: int = MAX_FRAME, with_fds: bool = False):
        self.sock = sock
        self.fd = sock.fileno()
        self.max_frame = max_frame
        self.with_fds = with_fds
        self.fds: list[int] = []  # descriptors received, oldest first (the receiver takes them)
        self._buf = bytearray()
        self._poll = select.poll()
        self._poll.register(self.fd, select.POLLIN)
        if not with_fds:  # mexone's end: writes never block (see send)
            os.set_blocking(self.fd, False)

    # ----- sending ------------------------------------------------------------------------------
    def send(self, kind: bytes, payload: bytes = b"", fds: tuple[int, ...] = (),
             timeout: float = 10.0) -> None:
        """One frame (and `fds` with it). mexone's end gives up after `timeout` s of the other
        side not reading (WireError); the student's end blocks as a pipe does."""
        data = _HEADER.pack(kind, len(payload)) + payload
        if fds:
            sent = socket.send_fds(self.sock, [data[:1]], list(fds))
            data = data[sent:]
        if not data:
            return
        try:
            written = os.write(self.fd, data)  # the usual case: all of it at once
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
                data = data[os.write(self.fd, data):]
            except BlockingIOError:
                continue
            except OSError as exc:
                raise WireError(f"the other side hung up ({exc.strerror})") from None

    def send_json(self, kind: bytes, obj: object, fds: tuple[int, ...] = (),
                  timeout: float = 10.0) -> None:
        self.send(kind, json.dumps(obj, separators=(",", ":")).encode(), fds, timeout)

    # ----- receiving ----------------------------------------------------------------------------
    def receive(self, timeout: float | None = None) -> tuple[bytes, bytes] | None:
        """The next frame (kind, payload), or None if none came within `timeout` s (None: wait
        as long as it takes). WireError on a hang-up or an oversized frame."""
        frame = self._frame()
        if frame is not None:
            return frame
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            if deadline is not None:
                left = deadline - time.monotonic()
                if left <= 0 or not self._poll.poll(max(0.0, left) * 1e3):
                    return None
            elif not self.with_fds:
                self._poll.poll()
            self._fill()
            frame = self._frame()
            if frame is not None:
                return frame

    def _fill(self) -> None:
        try:
            if self.with_fds:
                data, fds, _, _ = socket.recv_fds(self.sock, _CHUNK, 8)
                self.fds.extend(fds)
            else:
                data = os.read(self.fd, _CHUNK)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            raise WireError(f"the other side hung up ({exc.strerror})") from None
        if not data:
            raise WireError("the other side hung up")
        self._buf += data

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
        with contextlib.suppress(OSError):
            self.sock.close()
        for fd in self.fds:
            with contextlib.suppress(OSError):
                os.close(fd)
        self.fds.clear()
