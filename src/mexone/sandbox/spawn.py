"""`spawn(argv, jail)`: a process for a student's code, and the handle that ends all of it.

This first version isolates with what every Linux has without privileges: a process group of its
own, resource limits (CPU seconds, address space, no core files) applied before the program
runs, and an environment without the teacher's secret. Namespaces (PID, mount, network, user),
a read-only view of the file system but the scratch folder and ending every descendant are the
next step; callers do not change when they land.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

__all__ = ["Limits", "Jail", "StudentProcess", "spawn"]

SECRET_ENV = "MEXONE_EXERCISE_SECRET"  # a teacher's own secret: never in a student's process
ENTER = str(Path(__file__).with_name("enter.py"))  # run by path: no package import before exec


@dataclass(frozen=True)
class Limits:
    """What one student process may use: wall seconds, CPU seconds, address space in MB."""

    time: float = 30.0
    cpu: float = 60.0
    memory_mb: int = 2048


@dataclass(frozen=True)
class Jail:
    """Where a student's process runs: `scratch` the only folder it may write (None: a fresh
    temporary folder, removed with the process), `readable` the folders it may read besides
    Python's and mexone's installation, its `limits`, and whether it may use the network."""

    scratch: Path | None = None
    readable: tuple[Path, ...] = ()
    limits: Limits = field(default_factory=Limits)
    network: bool = False


class StudentProcess:
    """A running student process. `kill()` ends it and everything it started; it is a context
    manager that does so on exit."""

    def __init__(self, popen: subprocess.Popen[bytes], jail: Jail, scratch: Path,
                 own_scratch: tempfile.TemporaryDirectory[str] | None):
        self.popen = popen
        self.jail = jail
        self.scratch = scratch
        self._own_scratch = own_scratch

    @property
    def pid(self) -> int:
        return self.popen.pid

    @property
    def returncode(self) -> int | None:
        """Its exit status once it ended (negative: the signal that ended it), else None."""
        return self.popen.returncode

    def poll(self) -> int | None:
        return self.popen.poll()

    def wait(self, timeout: float | None = None) -> int | None:
        """Its exit status, or None if it is still running after `timeout` s."""
        try:
            return self.popen.wait(timeout)
        except subprocess.TimeoutExpired:
            return None

    def kill(self) -> None:
        """End the process and everything it started (idempotent)."""
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self.popen.pid, signal.SIGKILL)
        with contextlib.suppress(ProcessLookupError):
            self.popen.kill()
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.popen.wait(5.0)
        if self._own_scratch is not None:
            self._own_scratch.cleanup()
            self._own_scratch = None

    def __enter__(self) -> StudentProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.kill()


def spawn(argv: Sequence[str], jail: Jail, *, pass_fds: Sequence[int] = (),
          env: Mapping[str, str] | None = None, stdin: Any = subprocess.DEVNULL,
          stdout: IO[Any] | int | None = None, stderr: IO[Any] | int | None = None) -> StudentProcess:
    """Start `argv` (a program and its arguments, e.g. [sys.executable, "-m", module, ...]) in
    `jail`, its working folder the scratch folder. `env` is its environment (default: this
    process's), never with the teacher's secret; `pass_fds` the descriptors it inherits."""
    own = None
    if jail.scratch is None:
        own = tempfile.TemporaryDirectory(prefix="mexone-scratch-")
        scratch = Path(own.name)
    else:
        scratch = Path(jail.scratch)
        scratch.mkdir(parents=True, exist_ok=True)
    environ = {k: v for k, v in (os.environ if env is None else env).items() if k != SECRET_ENV}
    limits = json.dumps([jail.limits.cpu, jail.limits.memory_mb])
    popen = subprocess.Popen([sys.executable, "-I", "-S", ENTER, limits, *argv],
                             pass_fds=tuple(pass_fds), env=environ, cwd=scratch, stdin=stdin,
                             stdout=stdout, stderr=stderr, process_group=0)
    return StudentProcess(popen, jail, scratch, own)
