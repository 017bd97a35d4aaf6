"""Output files: a user's file is replaced only with --force, and never left half-written.

Every verb that writes goes through here. The checks run before any work (a sweep or a render
should not run for minutes and then find it may not write), and the bytes go to a temporary file
in the same folder that is renamed onto the name only when complete: a crash, Ctrl-C or a full
disk leaves either the old file or the new one, never a mix.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from mexone.errors import InputError, OutputExistsError

__all__ = ["usable", "check_output", "replacing", "move_into_place", "write_text", "temporary_path",
           "cache_dir"]


def usable(path: Path) -> Path:
    """A name the OS can look up (missing is fine): too long a name or a loop of links is one
    line, not an OSError from the first `exists()`."""
    path = Path(path)
    try:
        os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):
        pass
    except OSError as exc:
        raise InputError(f"cannot use this name: {exc.strerror}", file=path) from None
    return path


def check_output(path: Path, force: bool) -> Path:
    """Refuse, before any work, an output that is a folder, in a missing or read-only folder, or
    that exists (without force)."""
    path = usable(path)
    if path.is_dir():
        raise InputError("is a folder, not a file", file=path, hint="name a file inside it")
    folder = path.parent
    if not folder.is_dir():
        raise InputError("output folder does not exist", file=path,
                         hint=f"create it first: mkdir -p {folder}")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError("cannot write in this folder (permission denied)", file=path,
                         hint="pick a folder you can write to")
    if (path.exists() or path.is_symlink()) and not force:
        raise OutputExistsError("already exists; nothing was written", file=path,
                                hint="pass --force to overwrite it, or pick another name")
    return path


def temporary_path(path: Path) -> Path:
    """A hidden name next to path that keeps its extension (writers pick the format by it)."""
    return path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")


def move_into_place(temporary: Path, path: Path, force: bool) -> None:
    """Rename a finished temporary file onto path: atomically, and without force never over a
    file that appeared meanwhile (then OutputExistsError, and the temporary file stays)."""
    if force:
        os.replace(temporary, path)
        return
    try:
        os.link(temporary, path)  # fails if path exists: no window where another file is lost
    except FileExistsError:
        raise OutputExistsError("appeared while the output was written; it was left alone",
                                file=path, hint="pass --force to overwrite it") from None
    except OSError:  # a filesystem without hard links
        if path.exists():
            raise OutputExistsError("appeared while the output was written; it was left alone",
                                    file=path, hint="pass --force to overwrite it") from None
        os.replace(temporary, path)
        return
    temporary.unlink()


@contextmanager
def replacing(path: Path, force: bool) -> Iterator[Path]:
    """Yield a temporary path to write; rename it onto path when the block ends normally, delete
    it otherwise. An OSError while writing (disk full, permissions) is a one-line error."""
    path = check_output(Path(path), force)
    temporary = temporary_path(path)
    try:
        yield temporary
        move_into_place(temporary, path, force)
    except OSError as exc:
        raise InputError(f"cannot write: {exc.strerror or exc}", file=path) from None
    finally:
        temporary.unlink(missing_ok=True)


def write_text(path: Path, text: str, force: bool) -> None:
    with replacing(path, force) as temporary:
        temporary.write_text(text)


def cache_dir(kind: str) -> Path:
    """Where mexone keeps what it derives and can derive again (simplified meshes, generated
    message classes): $MEXONE_CACHE, else $XDG_CACHE_HOME/mexone, else ~/.cache/mexone, with
    `kind` below it. Not created here."""
    base = os.environ.get("MEXONE_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "mexone")
    return Path(base) / kind
