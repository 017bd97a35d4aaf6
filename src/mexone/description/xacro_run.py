"""expand_xacro(path): run xacro in a child process with a time and memory limit.

xacro evaluates Python expressions: ``${9**9**9}`` holds the interpreter (and its GIL) in one
C call that no thread or signal can interrupt, so the expansion runs in a child we can kill.
The child resolves ``$(find pkg)`` with mexone's package finder (ROS_PACKAGE_PATH, the folders
above the file, mexone's robots) instead of ROS 2's ament index, and reports a failure as one
JSON line that the parent turns into the usual one-line error.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from mexone.errors import InputError, MexoneError

__all__ = ["expand_xacro", "TIMEOUT_ENV", "DEFAULT_TIMEOUT"]

TIMEOUT_ENV = "MEXONE_XACRO_TIMEOUT"
DEFAULT_TIMEOUT = 6.0  # s: a full PR2 expands in about 3 s; a runaway expression ends within 10 s
_MEMORY_LIMIT = 2 << 30  # bytes of address space for the child
_ERROR_TAG = "mexone-xacro-error:"
_SOURCE_HINT = "fix the xacro source"


def _timeout() -> float:
    text = os.environ.get(TIMEOUT_ENV)
    if not text:
        return DEFAULT_TIMEOUT
    try:
        value = float(text)
    except ValueError:
        value = 0.0
    if not value > 0 or value == float("inf"):
        raise InputError(f"{TIMEOUT_ENV}={text}: must be a number of seconds > 0")
    return value


def expand_xacro(path: Path) -> bytes:
    """The expanded XML, or an InputError (one line) naming the file. A grader's simulator
    runs no student's xacro (its expressions are Python): sandbox.trust.UntrustedCode."""
    from mexone.sandbox import trust

    trust.check(path, "a xacro file: its expressions are Python")
    timeout = _timeout()
    package_root = str(Path(__file__).resolve().parents[2])  # the child imports this mexone
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        p for p in (package_root, os.environ.get("PYTHONPATH")) if p))
    try:
        done = subprocess.run([sys.executable, "-m", "mexone.description.xacro_run", str(path)],
                              stdin=subprocess.DEVNULL, capture_output=True, timeout=timeout, env=env)
    except subprocess.TimeoutExpired:
        raise InputError(f"xacro did not finish within {timeout:g} s", file=path,
                         hint=f"a runaway expression such as ${{9**9**9}} or a recursive macro? "
                              f"if it is only slow, set {TIMEOUT_ENV}=<seconds>") from None
    if done.returncode == 0:
        return done.stdout
    stderr = done.stderr.decode("utf-8", "replace")
    for line in reversed(stderr.splitlines()):
        if line.startswith(_ERROR_TAG):
            report = json.loads(line[len(_ERROR_TAG):])
            raise InputError(report["what"], file=path, hint=report["hint"])
    last = next((x for x in reversed(stderr.splitlines()) if x.strip()), f"exit {done.returncode}")
    raise InputError(f"xacro failed: {last.strip()}", file=path, hint=_SOURCE_HINT)


# ----- the child ---------------------------------------------------------------------------------
class _PackageNotFound(Exception):
    def __init__(self, error: MexoneError) -> None:
        super().__init__(error.one_line())
        self.error = error


def _root_cause(exc: BaseException) -> BaseException:
    """The first of our, memory or recursion errors that xacro wrapped (else exc itself)."""
    cause: BaseException | None = exc
    seen = 0
    while cause is not None and seen < 20:
        if isinstance(cause, _PackageNotFound | MemoryError | RecursionError):
            return cause
        cause, seen = getattr(cause, "exc", None) or cause.__cause__ or cause.__context__, seen + 1
    return exc


def _child(path: str) -> int:
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (_MEMORY_LIMIT, _MEMORY_LIMIT))
    import xacro
    from xacro import substitution_args

    from mexone.description.packages import require_package
    from mexone.errors import MexoneError

    def find(name: str) -> str:
        try:
            return str(require_package(name, Path(path).parent, f"$(find {name})"))
        except MexoneError as exc:
            raise _PackageNotFound(exc) from None

    substitution_args._eval_find = find  # $(find pkg) in attributes and includes
    substitution_args._eval_dict["find"] = find  # find('pkg') inside ${...}

    def report(what: str, hint: str | None) -> int:
        sys.stderr.write(_ERROR_TAG + json.dumps({"what": what, "hint": hint}) + "\n")
        return 3

    try:
        doc = xacro.process_file(path)
    except Exception as exc:  # xacro surfaces its users' mistakes as assorted Python errors
        cause = _root_cause(exc)
        if isinstance(cause, _PackageNotFound):  # the source is fine: the package is not found
            return report(f"xacro: {cause.error.what}", cause.error.hint)
        if isinstance(cause, MemoryError):
            return report(f"xacro: ran out of memory ({_MEMORY_LIMIT >> 30} GB)",
                          "a runaway expression or macro? fix the xacro source")
        if isinstance(cause, RecursionError):
            return report("xacro: macros nest too deeply (Python's recursion limit)",
                          "a macro that calls itself without end? fix the xacro source")
        if isinstance(exc, xacro.XacroException):
            return report(f"xacro: {' '.join(str(exc).split())}", _SOURCE_HINT)
        return report(f"xacro: {type(exc).__name__}: {' '.join(str(exc).split())}", _SOURCE_HINT)
    sys.stdout.buffer.write(doc.toxml(encoding="utf-8"))
    return 0


if __name__ == "__main__":
    sys.exit(_child(sys.argv[1]))
