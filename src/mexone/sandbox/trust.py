"""Which files a process may run as code. Everywhere but in a grader's simulator: any (the lab on
a student's own machine runs the student's files, each in a jail of its own). In the simulator
(`trust_only`): only the grader's own -- Python's installation, mexone and the exercise's
folders -- so a student's file is never code there: an audit hook refuses to execute it (an
import, a file run), and mexone's own runners of code in a child process (xacro's Python
expressions) refuse it with `check`.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["UntrustedCode", "trust_only", "trusted", "check"]


class UntrustedCode(RuntimeError):
    """A process that runs only the grader's code was about to run a student's file."""


_roots: tuple[str, ...] | None = None  # None: every file is trusted
_seen: dict[str, bool] = {}


def trust_only(roots: list[str]) -> None:
    """From now on, this process runs code only from files under `roots`, and an audit hook
    makes sure (it cannot be removed: for the process's life)."""
    global _roots
    first = _roots is None
    _roots = tuple(sorted({os.path.realpath(r).rstrip("/") + "/" for r in roots if r}))
    _seen.clear()
    if first:
        sys.addaudithook(_hook)


def trusted(path: str) -> bool:
    """Whether code from `path` may run in this process."""
    if _roots is None or not path or path.startswith("<"):
        return True
    known = _seen.get(path)
    if known is None:
        known = _seen[path] = os.path.realpath(path).startswith(_roots)
    return known


def check(path: str | Path, what: str = "code") -> None:
    """UntrustedCode if this process may not run `path` (`what` it is, for the message)."""
    if not trusted(str(path)):
        raise UntrustedCode(f"the grader's simulator runs no student code, and {Path(path).name} "
                            f"({what}) is not the grader's: a grader runs a student's file with "
                            "ctx.run, in a jail")


def _hook(event: str, args: tuple[object, ...]) -> None:
    if event == "exec":
        name = getattr(args[0], "co_filename", "") if args else ""
    elif event == "ctypes.dlopen":
        name = str(args[0]) if args and args[0] else ""
    else:
        return
    check(name, "Python code" if event == "exec" else "a shared library")
