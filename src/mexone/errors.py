"""Exception hierarchy: every error a user can cause is a MexoneError with a one-line message.

The CLI prints ``mexone: <str(error)>`` and exits 2; nothing else of the error reaches the user.
"""

from __future__ import annotations

import warnings
from pathlib import Path

PRINTABLE_LIMIT = 300  # characters of outside text a one-line message shows

__all__ = [
    "warn_renamed",
    "MexoneError",
    "InputError",
    "ModelError",
    "UnsupportedError",
    "OutputExistsError",
    "ArgumentTypeError",
    "RoutineError",
    "install_extra",
    "printable",
]


def install_extra(extras: str) -> str:
    """How to add an optional extra (`ros2`, `foxglove`, ...), for a hint: the form that works
    from a clone of mexone, which is on no package index (naming the package `mexone` with the
    extra asks one for it)."""
    return f'pip install ".[{extras}]" in a clone of mexone'


class MexoneError(Exception):
    """Base class: something the user can fix, located in a file and line where known."""

    def __init__(
        self,
        what: str,
        *,
        file: str | Path | None = None,
        line: int | None = None,
        hint: str | None = None,
    ) -> None:
        self.what = what
        self.file = str(file) if file is not None else None
        self.line = line
        self.hint = hint
        super().__init__(self.one_line())

    def one_line(self) -> str:
        """The error as one line: file:line: what (hint)."""
        where = ""
        if self.file is not None:
            where = f"{self.file}:{self.line}: " if self.line else f"{self.file}: "
        hint = f" ({self.hint})" if self.hint else ""
        return f"{where}{self.what}{hint}"

    def located(self, file: str | Path, line: int | None = None) -> MexoneError:
        """Fill in the location if the raiser did not know it."""
        if self.file is None:
            self.file = str(file)
        if self.line is None:
            self.line = line
        self.args = (self.one_line(),)
        return self


class InputError(MexoneError):
    """A file that cannot be read: missing, malformed XML, wrong types, refused entities."""


class ModelError(MexoneError):
    """A readable file that does not describe a robot we can build (unknown link, bad tree)."""


class UnsupportedError(MexoneError):
    """Valid input that the target format or simulator cannot represent faithfully."""


class OutputExistsError(MexoneError):
    """Refusing to overwrite a file the user made."""


class ArgumentTypeError(MexoneError, TypeError):
    """A Python API called with a value of a type its signature does not accept: a TypeError for
    Python callers, a one-line MexoneError for the front ends that print them."""


class RoutineError(MexoneError):
    """A routine failed (raised, exited with an error status, stopped yielding, left a program
    running): `RoutineRunner.run` raises it so a Python caller cannot miss it. The one line
    names the routine's file and line; `details` holds every routine's whole report (the
    student's traceback)."""

    def __init__(self, what: str, *, file: str | Path | None = None, line: int | None = None,
                 hint: str | None = None, details: str = "") -> None:
        self.details = details or what
        super().__init__(what, file=file, line=line, hint=hint)


def warn_renamed(old: str, new: str) -> None:
    """A renamed name was used: it still works for one release, and says what to write instead
    (a DeprecationWarning at the caller's line)."""
    warnings.warn(f"{old} is renamed {new}; the old name goes in the next release",
                  DeprecationWarning, stacklevel=3)


def printable(text: object, limit: int = PRINTABLE_LIMIT) -> str:
    """Text from outside (a file or folder name, a student's error, a ROS request's field) as one
    line that shows what it is: every character Python does not print (a newline, a carriage
    return, NUL, ESC, a bidi override, a line separator) escaped as Python writes it (`\\n`,
    `\\x00`, `\\u202e`), and at most `limit` characters, the rest counted. The one rule for
    echoing a value we did not write: it can neither fake a line of ours nor flood one."""
    text = str(text)
    head = text[:limit]
    shown = head if head.isprintable() else "".join(
        c if c.isprintable() else repr(c)[1:-1] for c in head)
    if len(text) > limit:
        shown += f"... ({len(text)} characters)"
    return shown
