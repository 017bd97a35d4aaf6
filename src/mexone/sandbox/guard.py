"""Guards inside a student's own process: a call that would end it, replace it, start a process
beside it or signal another process raises `Refused` at the student's own line, so the one line
mexone prints names it (a BaseException: `except Exception` in the student's code does not
swallow it). What bypasses Python (ctypes, a C extension) is not caught here: the process is
still the student's alone, and `StudentProcess.kill` ends it with everything it started.
"""

from __future__ import annotations

import os
import subprocess
from collections.abc import Callable
from typing import Any

__all__ = ["Refused", "install", "real_exit"]

_real: dict[tuple[str, str], Callable[..., Any]] = {}


class Refused(BaseException):
    """The student's code called something its process may not do."""


def real_exit(status: int) -> None:
    """End this process now (the guarded os._exit is the student's; this is mexone's)."""
    _real.get(("os", "_exit"), os._exit)(status)


def install(whose: str) -> None:
    """Guard this process, the process of `whose` ("a controller"): os._exit and posix._exit,
    fork, exec, posix_spawn, system and subprocess's fork_exec raise Refused, as does kill of
    any process but this one."""
    if _real:
        return
    import _posixsubprocess
    import posix

    exits = f"would end {whose}'s process (return from the method instead)"
    starts = f"{whose} may not start processes (its process computes, and only that)"
    table = {
        "_exit": exits, "fork": starts, "forkpty": starts, "execv": starts, "execve": starts,
        "posix_spawn": starts, "posix_spawnp": starts, "system": starts,
    }
    for name, why in table.items():
        for module in (os, posix):
            original = getattr(module, name, None)
            if original is not None:
                _real[(module.__name__, name)] = original
                setattr(module, name, _refuse(name, why))
    spawn = _refuse("subprocess.Popen", starts)
    _real[("_posixsubprocess", "fork_exec")] = _posixsubprocess.fork_exec
    _posixsubprocess.fork_exec = spawn
    if getattr(subprocess, "_fork_exec", None) is not None:  # Python 3.12's private alias
        setattr(subprocess, "_fork_exec", spawn)  # noqa: B010 - not in the stubs
    for name in ("kill", "killpg"):
        _real[("os", name)] = original = getattr(os, name)
        guarded = _own_only(name, original, whose)
        setattr(os, name, guarded)
        setattr(posix, name, guarded)


def _refuse(name: str, why: str) -> Callable[..., Any]:
    def refused(*args: object, **kwargs: object) -> Any:
        if name == "_exit":
            raise Refused(f"_exit({repr(args[0])[:40] if args else ''}) {why}")
        raise Refused(f"{name}(): {why}")

    refused.__name__ = refused.__qualname__ = name.rpartition(".")[2]
    return refused


def _own_only(name: str, original: Callable[..., Any], whose: str) -> Callable[[int, int], Any]:
    def guarded(pid: int, sig: int) -> Any:
        own = os.getpid() if name == "kill" else os.getpgrp()
        if pid not in (own, 0):
            raise Refused(f"os.{name}({pid}, {sig}): {whose} may signal only its own process")
        return original(pid, sig)

    guarded.__name__ = guarded.__qualname__ = name
    return guarded
