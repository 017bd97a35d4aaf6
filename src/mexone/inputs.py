"""read_input(path): the one way mexone reads a file a user named (model, world, controller YAML).

A FIFO or ``/dev/zero`` named ``robot.urdf`` would block or never end, and a 50 MB YAML keeps
PyYAML busy for a minute, so a user's file must be a regular file below a size cap. The file is
opened without blocking and vetted on the open descriptor, so nothing is read before the check.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from mexone.errors import InputError

__all__ = ["read_input", "read_input_text", "vet_regular_file", "input_limit_mb", "set_input_limit_mb",
           "DEFAULT_LIMIT_MB", "LIMIT_ENV"]

DEFAULT_LIMIT_MB = 4.0  # Mex-One's URDF is 36 kB, its YAML 2 kB, a 1000-link URDF 0.4 MB; PyYAML
# needs about 1 s per MB
LIMIT_ENV = "MEXONE_MAX_INPUT_MB"
_limit_override: float | None = None

_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISSOCK, "a socket"))


def set_input_limit_mb(megabytes: float | None) -> None:
    """The --max-input-mb flag: lift (or lower) the cap for this process."""
    global _limit_override
    if megabytes is not None and not megabytes > 0:
        raise InputError(f"--max-input-mb {megabytes:g}: must be a number > 0")
    _limit_override = megabytes


def input_limit_mb() -> float:
    if _limit_override is not None:
        return _limit_override
    text = os.environ.get(LIMIT_ENV)
    if text:
        try:
            value = float(text)
        except ValueError:
            value = 0.0
        if not value > 0 or value == float("inf"):
            raise InputError(f"{LIMIT_ENV}={text}: must be a number of megabytes > 0")
        return value
    return DEFAULT_LIMIT_MB


def _kind(mode: int) -> str | None:
    """None for a regular file, else what it is."""
    if stat.S_ISREG(mode):
        return None
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def _refuse_kind(kind: str, label: str) -> InputError:
    return InputError(f"is {kind}, not a regular file", file=label,
                      hint="name the model or config file itself")


def vet_regular_file(path: Path | str, label: str | None = None) -> None:
    """Refuse what is not a regular file (used for files others read for us: meshes, xacro)."""
    label = label or str(path)
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise InputError("no such file", file=label, hint="check the path") from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", file=label) from None
    if (kind := _kind(mode)) is not None:
        raise _refuse_kind(kind, label)


def read_input(path: Path | str, label: str | None = None, follow: bool = True) -> bytes:
    """The bytes of a user's file, refused (InputError, one line) unless a regular file within
    the size cap; with `follow` False, a symbolic link is refused at the open itself (no check
    and swap between a look and the read)."""
    label = label or str(path)
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags if follow else flags | os.O_NOFOLLOW)
    except FileNotFoundError:
        raise InputError("no such file", file=label, hint="check the path") from None
    except IsADirectoryError:
        raise _refuse_kind("a directory", label) from None
    except OSError as exc:
        if not follow and exc.errno == errno.ELOOP:
            raise InputError("is a symbolic link: refused, not read", file=label,
                             hint="name the file itself") from None
        raise InputError(f"cannot read: {exc.strerror}", file=label) from None
    info = os.fstat(fd)
    if (kind := _kind(info.st_mode)) is not None:
        os.close(fd)
        raise _refuse_kind(kind, label)
    with os.fdopen(fd, "rb") as handle:
        limit_mb = input_limit_mb()
        limit = int(limit_mb * 1e6)
        if info.st_size > limit:
            raise _too_big(info.st_size, limit_mb, label)
        data = handle.read(limit + 1)
        if len(data) > limit:  # grew while we looked
            raise _too_big(len(data), limit_mb, label)
    return data


def _too_big(size: int, limit_mb: float, label: str) -> InputError:
    needed = max(int(size / 1e6) + 1, 1)
    return InputError(f"is {size / 1e6:.1f} MB, over the {limit_mb:g} MB limit for input files",
                      file=label, hint=f"if it is meant to be this big, pass --max-input-mb {needed} "
                                       f"or set {LIMIT_ENV}={needed}")


def read_input_text(path: Path | str, label: str | None = None) -> str:
    """read_input, decoded as UTF-8 (YAML and friends)."""
    label = label or str(path)
    data = read_input(path, label)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise InputError("is not UTF-8 text", file=label, line=line,
                         hint="save it as UTF-8; is it the right file?") from None
