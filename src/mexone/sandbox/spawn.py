"""`spawn(argv, jail)`: a process for a student's code in a jail, and the handle that ends all
of it. What a jail is made of lives in confine.py; this module decides it for this machine
(`isolation()`, probed once per process) and for one jail (a `Plan`): the view of the file
system (the system's libraries, Python's installation, mexone, the jail's readable folders),
the scratch folder, the uid of the pool a root grader gives each jail, the limits.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import select
import shutil
import signal
import socket
import stat
import struct
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from mexone.sandbox.confine import Plan, sweep

__all__ = ["Limits", "Jail", "StudentProcess", "spawn", "Isolation", "isolation", "jail_plan",
           "UidSlot", "keep_private", "SECRET_ENV", "MODE_ENV", "UIDS_ENV", "Forked"]

SECRET_ENV = "MEXONE_EXERCISE_SECRET"  # a teacher's own secret: never in a student's process
MODE_ENV = "MEXONE_SANDBOX"  # namespaces | uid | none: the isolation to use (default: the best)
UIDS_ENV = "MEXONE_SANDBOX_UIDS"  # FIRST-LAST: the uids a root grader gives its jails
UIDS = (64000, 64999)
ENTER = str(Path(__file__).with_name("enter.py"))  # run by path: no package import before exec
PACKAGE_PARENT = str(Path(__file__).resolve().parents[2])  # the folder holding mexone/
log = logging.getLogger("mexone.sandbox")


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
    the system's libraries, Python's installation and mexone (as root, they must be readable
    by others: the jail runs as another user), `hidden` folders inside those it must not see
    (what a teacher installed beside mexone is hidden anyway: HIDDEN_GROUPS), its `limits`,
    and whether it may use the network. `another_user`: a root spawner's jail runs as a uid of
    the pool (a grader's: its readable folders must then be readable by others); else as the
    spawner's uid, with no capabilities (the lab: a student's own files, wherever they are)."""

    scratch: Path | None = None
    readable: tuple[Path, ...] = ()
    limits: Limits = field(default_factory=Limits)
    network: bool = False
    hidden: tuple[Path, ...] = ()
    another_user: bool = False


@dataclass(frozen=True)
class Isolation:
    """What this machine offers a jail: `mode` "namespaces" (PID, mount, network, IPC, UTS and,
    for a grader that is not root, user namespaces), "uid" (root without namespaces: another
    user) or "none" (limits only); the Landlock ABI (0: none); seccomp; whether the grader is
    root (its jails then run as uids of the pool, UIDS_ENV)."""

    mode: str
    landlock: int
    seccomp: bool
    root: bool

    def describe(self) -> str:
        layers = {"namespaces": "PID, mount, network, IPC and UTS namespaces"
                  + ("" if self.root else " in a user namespace"),
                  "uid": "no namespace, another uid for a grader's",
                  "none": "no namespace, the grader's own uid"}[self.mode]
        if self.mode == "namespaces" and self.root:
            layers += ", another uid for a grader's"
        layers += f", Landlock ABI {self.landlock}" if self.landlock else ", no Landlock"
        layers += ", seccomp" if self.seccomp else ", no seccomp"
        return f"{layers}, resource limits"


_isolation: Isolation | None = None
_isolation_lock = threading.Lock()


def isolation() -> Isolation:
    """What this machine offers (probed once per process in a throwaway child; $MEXONE_SANDBOX
    may ask for less: namespaces, uid or none). Said once in a debug line of mexone.sandbox."""
    global _isolation
    with _isolation_lock:
        if _isolation is None:
            _isolation = _probe()
            log.debug("mexone sandbox: a student's process runs with %s", _isolation.describe())
        return _isolation


def _probe() -> Isolation:
    root = hasattr(os, "geteuid") and os.geteuid() == 0
    found = {"namespaces": False, "landlock": 0, "seccomp": False}
    if sys.platform == "linux":
        with contextlib.suppress(OSError, ValueError, subprocess.SubprocessError):
            out = subprocess.run([sys.executable, "-I", "-S", ENTER, "--probe"], check=True,
                                 capture_output=True, timeout=30, stdin=subprocess.DEVNULL)
            found.update(json.loads(out.stdout))
    if found["namespaces"]:
        mode = "namespaces"
    elif root and _reachable_by_others():
        mode = "uid"
    else:
        mode = "none"
    wanted = os.environ.get(MODE_ENV, "").strip()
    order = ("none", "uid", "namespaces")
    if wanted in order and order.index(wanted) < order.index(mode):
        mode = wanted if (wanted != "uid" or (root and _reachable_by_others())) else "none"
    return Isolation(mode, int(found["landlock"]), bool(found["seccomp"]), root)


def _reachable_by_others() -> bool:
    """Whether another user can run this Python and import mexone (without a mount namespace,
    a jail of another uid sees the files as they are)."""
    for path in (os.path.realpath(sys.executable), PACKAGE_PARENT):
        folder = os.path.dirname(path) if os.path.isfile(path) else path
        while True:
            try:
                mode = os.stat(folder).st_mode
            except OSError:
                return False
            if not mode & stat.S_IXOTH:
                return False
            if folder == os.path.dirname(folder):
                break
            folder = os.path.dirname(folder)
    return True


HIDDEN_GROUPS = ("mexone.solutions", "mexone.exercises")  # a teacher's answers and graders
_hidden: list[str] | None = None


def _hidden_defaults() -> list[str]:
    """What no jail sees even where it lies inside Python's site-packages: the folders of the
    entry points of HIDDEN_GROUPS (a teacher's pack of reference solutions, a teacher's
    exercises with their graders), found once per process without importing them."""
    global _hidden
    if _hidden is None:
        import importlib.util
        from importlib.metadata import entry_points

        found = set()
        for group in HIDDEN_GROUPS:
            try:
                points = list(entry_points(group=group))
            except Exception:  # noqa: BLE001 - a broken distribution hides nothing of its own
                points = []
            for ep in points:
                module, _, sub = ep.value.partition(":")
                try:
                    spec = importlib.util.find_spec(module.split(".")[0])
                except (ImportError, ValueError):
                    continue
                if spec is None:
                    continue
                if spec.submodule_search_locations:  # a package: its folders, all of them
                    found |= {os.path.realpath(p) for p in spec.submodule_search_locations}
                elif spec.origin and os.path.isfile(spec.origin):  # a module: its file
                    found.add(os.path.realpath(spec.origin))
        _hidden = sorted(found - {os.path.realpath(PACKAGE_PARENT + "/mexone")})
    return _hidden


def probe_now() -> None:
    """Probe the machine (`isolation`), find the hidden folders and matplotlib's font list now,
    once for this process and the forks it makes (a grader's fork server: its simulators then
    start their controllers' jails without a probe's interpreter and a scan of the installed
    distributions each). A fork that confines itself calls `forget_probe`."""
    isolation()
    _hidden_defaults()
    _matplotlib_fonts()


def forget_probe() -> None:
    """In a jail forked from a process that probed: what the machine offered outside is not
    what it offers in here (seccomp refuses new namespaces), so a jail started from in here
    probes again."""
    global _isolation, _hidden
    _isolation = _hidden = None
    _font_list.clear()


def _python_paths() -> list[str]:
    """Python's installation, its site-packages and the folder holding mexone: what a jail
    reads besides the system's libraries (nothing else of the grader's sys.path: its working
    folder or $PYTHONPATH may be the teacher's)."""
    paths = {sys.base_prefix, sys.prefix, sys.exec_prefix, sys.base_exec_prefix, PACKAGE_PARENT,
             os.path.dirname(os.path.realpath(sys.executable))}
    paths |= {p for p in sys.path if p and os.path.basename(p) in ("site-packages",
                                                                    "dist-packages")}
    # each as the process names it too: a venv reached through a symlink keeps that path in
    # sys.path and in mexone.__path__, which a jail's later imports go through
    return sorted({q for p in paths if p and os.path.exists(p)
                   for q in (os.path.abspath(p), os.path.realpath(p))})


class UidSlot:
    """A uid of the pool held for one jail (a root grader's): an abstract Unix socket bound in
    its name is the lock, so concurrent graders, threads or processes never share one."""

    def __init__(self) -> None:
        first, last = UIDS
        text = os.environ.get(UIDS_ENV, "")
        with contextlib.suppress(ValueError):
            first, last = (int(x) for x in text.split("-"))
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        for uid in range(first, last + 1):
            try:
                self.sock.bind(f"\0mexone-sandbox-uid-{uid}")
            except OSError:
                continue
            self.uid = uid
            return
        self.sock.close()
        raise OSError(f"every uid of {first}-{last} is in use by a jail ({UIDS_ENV} sets the "
                      "pool)")

    def release(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.close()


def _closed_to_others(paths: list[str]) -> str | None:
    """The first of `paths` (folders a jail binds) another user cannot enter, if any: its
    bind keeps its mode, so a jail of a uid of its own could not import from it."""
    for path in paths:
        with contextlib.suppress(OSError):
            if os.path.isdir(path) and not os.stat(path).st_mode & stat.S_IXOTH:
                return path
    return None


def jail_plan(jail: Jail, scratch: Path, root: Path | None, slot: UidSlot | None) -> Plan:
    """The Plan confine.jail carries out for `jail` on this machine."""
    iso = isolation()
    uid = slot.uid if slot is not None else None
    readable = _python_paths() + [os.path.realpath(p) for p in jail.readable]
    if uid is not None:
        closed = _closed_to_others(readable)
        if closed is not None:
            raise OSError(f"a jail runs as a user of its own, who cannot enter {closed} (mode "
                          f"{stat.S_IMODE(os.stat(closed).st_mode):o}): let others read it "
                          f"(chmod o+rx {closed}), or grade as a user who is not root")
    return Plan(mode=iso.mode, scratch=str(scratch), root=str(root) if root else "",
                readable=readable,
                hidden=_hidden_defaults() + [os.path.realpath(p) for p in jail.hidden],
                uid=uid, gid=uid,
                user_namespace=iso.mode == "namespaces" and not iso.root,
                network=jail.network, cpu=jail.limits.cpu, memory_mb=jail.limits.memory_mb,
                landlock=iso.landlock, seccomp=iso.seccomp, parent=os.getpid())


def prepare(jail: Jail) -> tuple[Path, Path, Path, bool, UidSlot | None]:
    """A jail's folders on the grader's side: (its work folder, its scratch, the mount point of
    its root, whether the scratch is its own, its uid slot). The scratch belongs to the jail's
    uid (as root); the work folder is traversable, not listable, by others."""
    iso = isolation()
    work = Path(tempfile.mkdtemp(prefix="mexone-jail-"))
    os.chmod(work, 0o711)
    own = jail.scratch is None
    scratch = work / "scratch" if jail.scratch is None else Path(jail.scratch).resolve()
    scratch.mkdir(parents=True, exist_ok=True)
    root = work / "root"
    root.mkdir()
    _seed_home(scratch)
    slot = None
    if iso.root and iso.mode != "none" and jail.another_user:
        slot = UidSlot()
        if iso.mode == "uid":  # what a jail of this uid left when its grader was killed
            sweep(Plan(mode="uid", scratch="", uid=slot.uid))
        for folder, _, files in os.walk(scratch):
            for name in (folder, *(os.path.join(folder, f) for f in files)):
                with contextlib.suppress(OSError):
                    os.chown(name, slot.uid, slot.uid, follow_symlinks=False)
        os.chmod(scratch, 0o700)
    return work, scratch, root, own, slot


_font_list: list[Path | None] = []


def _matplotlib_fonts() -> Path | None:
    """This user's matplotlib font list, built once (in a throwaway process) where matplotlib is
    installed and has none yet; None without matplotlib."""
    if not _font_list:
        import importlib.util

        found = None
        if importlib.util.find_spec("matplotlib") is not None:
            cache = Path(os.environ.get("MPLCONFIGDIR") or Path(
                os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "matplotlib")
            for attempt in range(2):
                found = max(cache.glob("fontlist-v*.json"), default=None)
                if found is not None or attempt:
                    break
                with contextlib.suppress(OSError, subprocess.SubprocessError):
                    subprocess.run([sys.executable, "-c", "import matplotlib.font_manager"],
                                   capture_output=True, timeout=300, stdin=subprocess.DEVNULL)
        _font_list.append(found)
    return _font_list[0]


def _seed_home(scratch: Path) -> None:
    """A jail's home (its scratch folder) starts with a copy of matplotlib's font list:
    python-control imports matplotlib, which would otherwise build the list by running fc-list,
    and a controller's worker may start no process."""
    fonts = _matplotlib_fonts()
    if fonts is None:
        return
    folder = scratch / ".cache" / "matplotlib"
    with contextlib.suppress(OSError):
        folder.mkdir(parents=True, exist_ok=True)
        if not (folder / fonts.name).exists():
            shutil.copyfile(fonts, folder / fonts.name)


def environment(env: Mapping[str, str] | None, scratch: Path) -> dict[str, str]:
    """A jail's environment: `env` (default: this process's) without the teacher's secret, its
    home and temporary folder its own."""
    environ = {k: v for k, v in (os.environ if env is None else env).items()
               if k not in (SECRET_ENV, "MPLCONFIGDIR")}
    environ["HOME"] = str(scratch)
    environ["XDG_CACHE_HOME"] = str(scratch / ".cache")
    environ["TMPDIR"] = "/tmp" if isolation().mode == "namespaces" else str(scratch)
    return environ


class Forked:
    """A jail's relay that a warm fork server forked (not this process's child): Popen's face
    over its pid and the pipe on which the server's monitor, its parent, writes its wait status
    (4 bytes, then the pipe closes). Signals go to it only until that status came: before, the
    monitor has not reaped it, so the pid is still its own."""

    def __init__(self, pid: int, status_fd: int):
        self.pid = pid
        self.returncode: int | None = None
        self._fd: int | None = status_fd
        self._data = b""
        self._lock = threading.Lock()

    def _read(self, timeout: float | None) -> int | None:
        with self._lock:
            deadline = None if timeout is None else time.monotonic() + timeout
            while self.returncode is None and self._fd is not None:
                left = None if deadline is None else max(0.0, deadline - time.monotonic())
                if not select.select([self._fd], [], [], left)[0]:
                    break
                chunk = os.read(self._fd, 4 - len(self._data))
                self._data += chunk
                if len(self._data) == 4 or not chunk:  # a monitor that died: killed, say
                    status = struct.unpack("!i", self._data)[0] if chunk else signal.SIGKILL
                    self.returncode = os.waitstatus_to_exitcode(status) if chunk else -status
                    os.close(self._fd)
                    self._fd = None
            return self.returncode

    def poll(self) -> int | None:
        return self._read(0.0)

    def wait(self, timeout: float | None = None) -> int:
        code = self._read(timeout)
        if code is None:
            raise subprocess.TimeoutExpired(f"pid {self.pid}", timeout or 0.0)
        return code

    def send_signal(self, sig: int) -> None:
        if self.poll() is None:
            os.kill(self.pid, sig)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)

    def __del__(self) -> None:
        if self._fd is not None:
            with contextlib.suppress(OSError):
                os.close(self._fd)


class StudentProcess:
    """A running student process. `kill()` ends it and everything it started; it is a context
    manager that does so on exit."""

    def __init__(self, popen: subprocess.Popen[bytes] | Forked, jail: Jail, scratch: Path, work: Path,
                 own_scratch: bool, plan: Plan, slot: UidSlot | None):
        self.popen = popen
        self.jail = jail
        self.scratch = scratch
        self.plan = plan
        self._work: Path | None = work
        self._own_scratch = own_scratch
        self._slot = slot
        self._lock = threading.Lock()

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
        """End the process and everything it started (idempotent): its relay is told to end
        the jail (its PID namespace, or every process of its uid or that it adopted), then
        killed if it does not."""
        with self._lock:
            if self.popen.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    self.popen.send_signal(signal.SIGTERM)
                with contextlib.suppress(subprocess.TimeoutExpired):
                    self.popen.wait(5.0)
            if self.popen.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    self.popen.kill()
                with contextlib.suppress(subprocess.TimeoutExpired):
                    self.popen.wait(5.0)
            if self.plan.mode == "uid":
                sweep(self.plan)  # the relay was killed before it swept: every process of the uid
            if self._slot is not None:
                self._slot.release()
                self._slot = None
            if self._work is not None:
                shutil.rmtree(self._work, ignore_errors=True)
                self._work = None

    def __enter__(self) -> StudentProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.kill()


def spawn(argv: Sequence[str], jail: Jail, *, pass_fds: Sequence[int] = (),
          env: Mapping[str, str] | None = None, stdin: Any = subprocess.DEVNULL,
          stdout: IO[Any] | int | None = None, stderr: IO[Any] | int | None = None) -> StudentProcess:
    """Start `argv` (a program and its arguments, e.g. [sys.executable, "-m", module, ...]) in
    `jail`, its working folder the scratch folder. `env` is its environment (default: this
    process's), never with the teacher's secret; `pass_fds` the descriptors it inherits. The
    returned handle's pid is the jail's relay (outside the jail): its exit status is the
    program's."""
    work, scratch, root, own, slot = prepare(jail)
    plan = jail_plan(jail, scratch, root, slot)
    try:
        popen = subprocess.Popen([sys.executable, "-I", "-S", ENTER, plan.dumps(),
                                  ",".join(str(int(fd)) for fd in pass_fds), *argv],
                                 pass_fds=tuple(pass_fds), env=environment(env, scratch),
                                 cwd=scratch, stdin=stdin, stdout=stdout, stderr=stderr,
                                 process_group=0)
    except BaseException:
        if slot is not None:
            slot.release()
        shutil.rmtree(work, ignore_errors=True)
        raise
    return StudentProcess(popen, jail, scratch, work, own, plan, slot)


def keep_private() -> None:
    """Make this process (a grader holding the teacher's secret) non-dumpable: no process of
    its uid may read its /proc/PID/environ or memory, or trace it (Linux; elsewhere nothing)."""
    if sys.platform == "linux":
        import ctypes

        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(4, 0, 0, 0, 0)  # PR_SET_DUMPABLE 0
