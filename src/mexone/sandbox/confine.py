"""The confinement itself: what turns a process into a student's jail. Standard library only: it
runs by path before any package is imported (enter.py, for `spawn`) and in a fork of the
grader's fork server (a graded function), so it imports nothing of mexone's.

`jail(plan)` returns in the confined process; on the way, the process it was called in becomes
the jail's *relay*: it waits for the jail and ends with its exit status (or the signal that
ended it), and when it ends, everything the jail started ends too. The layers, each where the
machine offers it (`probe`):

- namespaces (Linux user namespaces, or root): a PID namespace whose first process is the
  jail's init (when it ends, the kernel ends every process of the namespace), a mount namespace
  whose root is a fresh tmpfs holding read-only binds of what Python needs (the system's
  libraries, Python's installation, mexone) and the plan's readable folders, the scratch folder
  read-write (a tmpfs of `scratch_mb` holding a copy of what was put there: a jail fills no
  disk of the machine's), a private /tmp and /dev/shm, its own /proc and a minimal /dev; no network (a
  network namespace with a loopback that is down), its own IPC and host name;
- another user: as root, the jail's processes run as an unprivileged uid of the pool
  (`Plan.uid`), so they cannot read, signal or trace the grader's; without namespaces the relay
  ends every process of that uid when the jail ends;
- Landlock (Linux 5.13+): the same file-system view as rules (read-only, the scratch folder
  writable), no TCP, no signals or abstract sockets outside the jail, no ptrace of what is
  outside (so not /proc/<ancestor>/environ either);
- seccomp: no new namespaces, mounts, ptrace, BPF, io_uring, kernel keys or modules, and no
  socket but a Unix one unless the plan allows the network;
- resource limits (CPU seconds, address space, file size, processes, no core files) and
  no_new_privs (no setuid program gives privileges back).
"""

from __future__ import annotations

import ctypes
import os
import resource
import select
import struct
import sys
import time

TYPE_CHECKING = False  # typing's flag without typing's import (the relay's start); mypy: True
if TYPE_CHECKING:
    from collections.abc import Callable, Sequence
    from types import FrameType, TracebackType
    from typing import Any

try:  # the C module: `signal` imports enum, a third of this module's start in the jail's relay
    import _signal as signal  # type: ignore[import-not-found]  # typeshed has no stub for the C module
except ImportError:  # pragma: no cover - every CPython has it
    import signal

__all__ = ["Plan", "jail", "probe", "sweep", "JailError", "SYSTEM_ETC"]

# the few files of /etc a Python process reads (the dynamic loader's cache first)
SYSTEM_ETC = ("ld.so.cache", "ld.so.conf", "ld.so.conf.d", "localtime", "timezone", "passwd",
              "group", "nsswitch.conf", "hosts", "host.conf", "mime.types", "alternatives",
              "fonts", "os-release", "debian_version", "protocols", "services", "gai.conf")
SYSTEM_DIRS = ("/usr", "/bin", "/sbin", "/lib", "/lib64", "/lib32", "/libx32", "/opt")
DEVICES = ("null", "zero", "full", "random", "urandom")
JAIL_UID = 1000  # the jail's uid inside its own user namespace (never 0: no capabilities)

CLONE_NEWNS, CLONE_NEWCGROUP, CLONE_NEWUTS = 0x00020000, 0x02000000, 0x04000000
CLONE_NEWIPC, CLONE_NEWUSER, CLONE_NEWPID = 0x08000000, 0x10000000, 0x20000000
CLONE_NEWNET, CLONE_NEWTIME = 0x40000000, 0x00000080
NAMESPACES = (CLONE_NEWNS | CLONE_NEWCGROUP | CLONE_NEWUTS | CLONE_NEWIPC | CLONE_NEWUSER
              | CLONE_NEWPID | CLONE_NEWNET | CLONE_NEWTIME)
MS_RDONLY, MS_NOSUID, MS_NODEV, MS_NOEXEC = 1, 2, 4, 8
MS_REMOUNT, MS_BIND, MS_REC, MS_PRIVATE = 32, 4096, 16384, 1 << 18
MS_NOATIME, MS_NODIRATIME, MS_RELATIME = 1024, 2048, 1 << 21
MNT_DETACH = 2
PR_SET_PDEATHSIG, PR_SET_DUMPABLE, PR_SET_SECCOMP = 1, 4, 22
PR_CAPBSET_DROP, PR_SET_CHILD_SUBREAPER, PR_SET_NO_NEW_PRIVS = 24, 36, 38

# syscall numbers: x86_64, and the generic table of aarch64
_SYSCALLS = {
    "x86_64": {"socket": 41, "clone": 56, "clone3": 435, "unshare": 272, "setns": 308,
               "mount": 165, "umount2": 166, "pivot_root": 155, "chroot": 161, "ptrace": 101,
               "process_vm_readv": 310, "process_vm_writev": 311, "bpf": 321,
               "perf_event_open": 298, "keyctl": 250, "add_key": 248, "request_key": 249,
               "userfaultfd": 323, "io_uring_setup": 425, "io_uring_enter": 426,
               "io_uring_register": 427, "kexec_load": 246, "kexec_file_load": 320,
               "init_module": 175, "finit_module": 313, "delete_module": 176,
               "mount_setattr": 442, "move_mount": 429, "open_tree": 428, "fsopen": 430,
               "fsconfig": 431, "fsmount": 432, "fspick": 433, "open_by_handle_at": 304,
               "reboot": 169, "swapon": 167, "swapoff": 168, "acct": 163, "quotactl": 179,
               "syslog": 103, "sethostname": 170, "setdomainname": 171, "settimeofday": 164,
               "clock_settime": 227, "kcmp": 312, "iopl": 172, "ioperm": 173, "vhangup": 153,
               "uselib": 134, "landlock_create_ruleset": 444, "landlock_add_rule": 445,
               "landlock_restrict_self": 446, "chmod": 90, "fchmod": 91, "fchmodat": 268,
               "fchmodat2": 452, "open": 2, "openat": 257, "creat": 85, "mknod": 133,
               "mknodat": 259, "openat2": 437},
    "aarch64": {"socket": 198, "clone": 220, "clone3": 435, "unshare": 97, "setns": 268,
                "mount": 40, "umount2": 39, "pivot_root": 41, "chroot": 51, "ptrace": 117,
                "process_vm_readv": 270, "process_vm_writev": 271, "bpf": 280,
                "perf_event_open": 241, "keyctl": 219, "add_key": 217, "request_key": 218,
                "userfaultfd": 282, "io_uring_setup": 425, "io_uring_enter": 426,
                "io_uring_register": 427, "kexec_load": 104, "kexec_file_load": 294,
                "init_module": 105, "finit_module": 273, "delete_module": 106,
                "mount_setattr": 442, "move_mount": 429, "open_tree": 428, "fsopen": 430,
                "fsconfig": 431, "fsmount": 432, "fspick": 433, "open_by_handle_at": 265,
                "reboot": 142, "swapon": 224, "swapoff": 225, "acct": 89, "quotactl": 60,
                "syslog": 116, "sethostname": 161, "setdomainname": 162, "settimeofday": 170,
                "clock_settime": 112, "kcmp": 272, "vhangup": 58,
                "landlock_create_ruleset": 444, "landlock_add_rule": 445,
                "landlock_restrict_self": 446, "fchmod": 52, "fchmodat": 53, "fchmodat2": 452,
                "openat": 56, "mknodat": 33, "openat2": 437},
}
_AUDIT_ARCH = {"x86_64": 0xC000003E, "aarch64": 0xC00000B7}
# what seccomp refuses in a jail (EPERM): changing what the jail is, or reaching past it
DENIED = ("unshare", "setns", "mount", "umount2", "pivot_root", "chroot", "ptrace",
          "process_vm_readv", "process_vm_writev", "bpf", "perf_event_open", "keyctl", "add_key",
          "request_key", "userfaultfd", "io_uring_setup", "io_uring_enter", "io_uring_register",
          "kexec_load", "kexec_file_load", "init_module", "finit_module", "delete_module",
          "mount_setattr", "move_mount", "open_tree", "fsopen", "fsconfig", "fsmount", "fspick",
          "open_by_handle_at", "reboot", "swapon", "swapoff", "acct", "quotactl", "syslog",
          "sethostname", "setdomainname", "settimeofday", "clock_settime", "kcmp", "iopl",
          "ioperm", "vhangup", "uselib")


class JailError(OSError):
    """The jail could not be set up as planned (the relay reports it, exit status 3)."""


class Plan:
    """What one jail is: how (`mode`: "namespaces", "uid" or "none"), where it writes
    (`scratch`), what it reads, as whom, with which limits. Paths are absolute and resolved.
    (A plain class, not a dataclass: dataclasses imports inspect, which the relay's start
    would pay for.)"""

    FIELDS: dict[str, tuple[Any, Any]] = {  # name: (kind, default); a kind may be `int | None`
        "mode": (str, "none"),
        "scratch": (str, ""),
        "root": (str, ""),  # an empty folder the new root is mounted on (namespaces)
        "readable": (list, ()),
        "hidden": (list, ()),  # inside readable ones: not shown
        "uid": (int | None, None),  # run as this uid (the grader is root)
        "gid": (int | None, None),
        "user_namespace": (bool, False),  # the grader is not root: a user namespace of its own
        "network": (bool, False),
        "cpu": (float, 60.0),
        "memory_mb": (int, 2048),
        "file_mb": (int, 1024),
        "scratch_mb": (int, 256),  # the scratch folder's size, where it is a tmpfs (namespaces)
        "processes": (int, 64),
        "landlock": (int, 0),  # the ABI to use, 0: none
        "seccomp": (bool, False),
        "parent": (int, 0),  # the jail ends when this process ends (0: not watched)
    }

    mode: str
    scratch: str
    root: str
    readable: list[str]
    hidden: list[str]
    uid: int | None
    gid: int | None
    user_namespace: bool
    network: bool
    cpu: float
    memory_mb: int
    file_mb: int
    scratch_mb: int
    processes: int
    landlock: int
    seccomp: bool
    parent: int

    def __init__(self, **values: Any):
        unknown = set(values) - set(self.FIELDS)
        if unknown:
            raise TypeError(f"Plan has no field {sorted(unknown)[0]!r}")
        for name, (kind, default) in self.FIELDS.items():
            value = values.get(name, default)
            setattr(self, name, list(value) if kind is list else value)

    def __repr__(self) -> str:
        return "Plan(" + ", ".join(f"{n}={getattr(self, n)!r}" for n in self.FIELDS) + ")"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Plan) and all(getattr(self, n) == getattr(other, n)
                                               for n in self.FIELDS)

    def dumps(self) -> str:
        """One line of text: `name=value` fields, a list's items apart by \\x1f (json's import
        would cost the jail's relay more than the rest of its start)."""
        out = []
        for name in self.FIELDS:
            value = getattr(self, name)
            shown = "\x1f".join(value) if isinstance(value, list) else \
                "" if value is None else str(int(value)) if isinstance(value, bool) else str(value)
            out.append(f"{name}={shown}")
        return "\x1e".join(out)

    @classmethod
    def loads(cls, text: str) -> Plan:
        values: dict[str, Any] = {}
        for item in text.split("\x1e"):
            name, _, shown = item.partition("=")
            kind, default = cls.FIELDS[name]
            if kind is list:
                values[name] = shown.split("\x1f") if shown else []
            elif shown == "" and default is None:
                values[name] = None
            elif kind is bool:
                values[name] = shown == "1"
            elif kind in (int, float):
                values[name] = kind(shown)
            elif kind == int | None:
                values[name] = int(shown)
            else:
                values[name] = shown
        return cls(**values)


class _suppress:  # contextlib.suppress without contextlib's imports (the relay's start)
    def __init__(self, *kinds: type[BaseException]):
        self.kinds = kinds

    def __enter__(self) -> None:
        return None

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 tb: TracebackType | None) -> bool:
        return kind is not None and issubclass(kind, self.kinds)


# ----- the C library ------------------------------------------------------------------------
_libc: ctypes.CDLL | None = None


def _lib() -> ctypes.CDLL:
    global _libc
    if _libc is None:
        _libc = ctypes.CDLL(None, use_errno=True)
        _libc.syscall.restype = ctypes.c_long
        if sys.platform == "linux":
            _libc.mount.argtypes = (ctypes.c_char_p, ctypes.c_char_p, ctypes.c_char_p,
                                    ctypes.c_ulong, ctypes.c_char_p)
            _libc.prctl.argtypes = (ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong,
                                    ctypes.c_ulong, ctypes.c_ulong)
    return _libc


def _ok(result: int, what: str) -> int:
    if result < 0:
        err = ctypes.get_errno()
        raise JailError(err, f"{what}: {os.strerror(err)}")
    return result


def _nr(name: str) -> int | None:
    return _SYSCALLS.get(os.uname().machine, {}).get(name)


def _syscall(name: str, *args: object) -> int:
    number = _nr(name)
    if number is None:
        raise JailError(38, f"{name}: no such system call here")
    return _lib().syscall(number, *args)


def _prctl(option: int, arg: int = 0) -> int:
    """Linux's prctl; elsewhere 0 (nothing to set: the jail there is its limits)."""
    if sys.platform != "linux":
        return 0
    return _lib().prctl(option, arg, 0, 0, 0)


def _mount(source: str | None, target: str, fstype: str | None, flags: int,
           data: str | None = None) -> None:
    enc: Callable[[str | None], bytes | None] = (lambda s: None if s is None else s.encode())  # noqa: E731
    _ok(_lib().mount(enc(source), enc(target), enc(fstype), flags, enc(data)),
        f"mount {source or fstype} on {target}")


def _write(path: str, text: str) -> None:
    fd = os.open(path, os.O_WRONLY)
    try:
        os.write(fd, text.encode())
    finally:
        os.close(fd)


# ----- what the machine offers ----------------------------------------------------------------
def landlock_abi() -> int:
    """The Landlock ABI the kernel offers (0: none)."""
    number = _nr("landlock_create_ruleset")
    if number is None or sys.platform != "linux":
        return 0
    result = _lib().syscall(number, None, 0, 1)  # LANDLOCK_CREATE_RULESET_VERSION
    return max(0, int(result))


def probe() -> dict[str, bool | int]:
    """What this machine offers, tried in this process (call it in a throwaway child: it
    unshares): {"namespaces": bool, "landlock": ABI, "seccomp": bool, "root": bool}."""
    root = os.geteuid() == 0
    found = {"namespaces": False, "landlock": landlock_abi(), "seccomp": False, "root": root}
    if sys.platform != "linux":
        return found
    try:
        flags = CLONE_NEWPID | CLONE_NEWNS | CLONE_NEWNET | CLONE_NEWIPC | CLONE_NEWUTS
        if not root:
            flags |= CLONE_NEWUSER
        _ok(_lib().unshare(flags), "unshare")
        if not root:
            _map_user()
        _mount(None, "/", None, MS_REC | MS_PRIVATE)
        found["namespaces"] = True
    except OSError:
        pass
    try:
        _ok(_prctl(PR_SET_NO_NEW_PRIVS, 1), "no_new_privs")
        _seccomp(network=True, allow_all=True)
        found["seccomp"] = True
    except OSError:
        pass
    return found


# ----- the jail -------------------------------------------------------------------------------
class _Stop(Exception):  # noqa: N818 - the relay was asked to end the jail
    pass


def _stop(signum: int, frame: FrameType | None) -> None:
    raise _Stop


def jail(plan: Plan, keep_fds: tuple[int, ...] = ()) -> None:
    """Confine this process as `plan` says; returns in the confined process (the jail's first
    program), while this process becomes its relay and never returns. `keep_fds`: the
    descriptors the jail keeps (besides 0, 1, 2); its working folder is the scratch folder.
    A process that cannot be set up ends with exit status 3 and one line on stderr."""
    if plan.parent and os.getppid() != plan.parent:
        os._exit(3)
    if plan.mode == "namespaces":
        flags = CLONE_NEWPID | CLONE_NEWNS | CLONE_NEWIPC | CLONE_NEWUTS
        flags |= 0 if plan.network else CLONE_NEWNET
        flags |= CLONE_NEWUSER if plan.user_namespace else 0
        _guard(lambda: _ok(_lib().unshare(flags), "unshare"))
        if plan.user_namespace:
            _guard(_map_user)
    else:
        _guard(lambda: _ok(_prctl(PR_SET_CHILD_SUBREAPER, 1), "subreaper"))
    report_r, report_w = os.pipe()
    relay = os.getpid()
    pid = os.fork()
    if pid:
        os.close(report_w)
        _relay(plan, pid, report_r)
    os.close(report_r)
    _die_with(relay)
    if plan.mode == "namespaces":  # this process is the namespace's init (PID 1)
        _guard(lambda: _build_root(plan))
        init = os.getpid()
        pid = os.fork()
        if pid:
            _init(pid, report_w)
        _die_with(init)
    os.close(report_w)
    _guard(lambda: _confine(plan, keep_fds))


def _guard(step: Callable[[], object]) -> None:
    """Run a set-up step; if it fails, the jail ends here with exit status 3 and why."""
    try:
        step()
    except Exception as exc:  # noqa: BLE001 - any failure of the set-up: one line, status 3
        with _suppress(OSError):
            os.write(2, f"mexone sandbox: cannot set up the jail: {exc}\n".encode())
        os._exit(3)


def _die_with(parent: int) -> None:
    """SIGKILL when the parent ends; if it has ended already, end now (a parent outside this
    PID namespace shows as 0)."""
    if parent and sys.platform == "linux":
        _prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
        if os.getppid() not in (parent, 0):
            os._exit(3)


def _map_user() -> None:
    """In a fresh user namespace: the jail's uid and gid are JAIL_UID, standing for this
    process's own outside (the only mapping an unprivileged process may write)."""
    uid, gid = os.geteuid(), os.getegid()
    with _suppress(FileNotFoundError):
        _write("/proc/self/setgroups", "deny")
    _write("/proc/self/uid_map", f"{JAIL_UID} {uid} 1")
    _write("/proc/self/gid_map", f"{JAIL_UID} {gid} 1")


def _relay(plan: Plan, pid: int, report: int) -> None:
    """The jail's relay: waits for it, ends what it left, ends as the jail's program ended.
    SIGTERM, SIGINT or SIGHUP here end the jail at once (SIGKILL: its PID namespace, or the
    parent-death signal, ends it)."""
    for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
        signal.signal(sig, _stop)
    status = None
    try:
        raw = _wait(pid, plan.parent)
        if plan.mode == "namespaces":  # init's report: how the program ended
            data = b""
            while len(data) < 4 and (chunk := os.read(report, 4 - len(data))):
                data += chunk
            status = struct.unpack("i", data)[0] if len(data) == 4 else raw
        else:
            status = raw
    except _Stop:
        with _suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
        with _suppress(ChildProcessError, _Stop):
            os.waitpid(pid, 0)
        status = signal.SIGKILL
    for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
        signal.signal(sig, signal.SIG_IGN)
    sweep(plan)
    _end_as(status)


def _wait(pid: int, parent: int) -> int:
    """The wait status of child `pid`; _Stop if `parent` (the spawner) ended meanwhile (a
    process, not the thread that spawned the jail, as the parent-death signal would be)."""
    try:
        ready = os.pidfd_open(pid)
    except (AttributeError, OSError):
        ready = None
    try:
        while True:
            done, raw = os.waitpid(pid, os.WNOHANG)
            if done:
                return raw
            if parent and os.getppid() != parent:
                raise _Stop
            if ready is not None:
                select.select([ready], [], [], 0.5)
            else:
                time.sleep(0.05)
    finally:
        if ready is not None:
            os.close(ready)


def _end_as(status: int) -> None:
    """End this process as the wait status `status` says the jail's program ended."""
    for stream in (sys.stdout, sys.stderr):
        with _suppress(Exception):
            stream.flush()
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        with _suppress(ValueError, OSError):
            resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        with _suppress(OSError, ValueError):
            signal.signal(sig, signal.SIG_DFL)
            signal.pthread_sigmask(signal.SIG_UNBLOCK, [sig])
            os.kill(os.getpid(), sig)
        os._exit(128 + sig)
    os._exit(os.WEXITSTATUS(status) if os.WIFEXITED(status) else 3)


def _init(program: int, report: int) -> None:
    """The namespace's init: reaps every process; when the program ends, reports how and ends
    (the kernel then ends every other process of the namespace)."""
    while True:
        try:
            pid, status = os.waitpid(-1, 0)
        except ChildProcessError:
            os._exit(0)
        if pid == program:
            with _suppress(OSError):
                os.write(report, struct.pack("i", status))
            os._exit(0)


def sweep(plan: Plan) -> None:
    """End every process the jail left (without namespaces: this process's adopted orphans,
    and as root every process of the jail's uid)."""
    if plan.mode == "namespaces":
        return
    for _ in range(200):
        left = _orphans()
        if plan.uid is not None and os.geteuid() == 0:
            left |= _of_uid(plan.uid)
        left.discard(os.getpid())
        if not left:
            return
        for pid in left:
            with _suppress(ProcessLookupError, PermissionError):
                os.kill(pid, signal.SIGKILL)
        _reap()


def _reap() -> None:
    with _suppress(ChildProcessError):
        while os.waitpid(-1, os.WNOHANG)[0] > 0:
            pass


def _running(pid: str) -> bool:
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            stat = f.read()
    except OSError:
        return False
    return stat[stat.rindex(b")") + 2:][:1] not in (b"Z", b"X")


def _orphans() -> set[int]:
    """This process's children (a subreaper adopts the jail's orphans), running."""
    found = set()
    with _suppress(OSError):
        for task in os.listdir("/proc/self/task"):
            with open(f"/proc/self/task/{task}/children") as f:
                found |= {int(p) for p in f.read().split() if _running(p)}
    return found


def _of_uid(uid: int) -> set[int]:
    found = set()
    with _suppress(OSError):
        for entry in os.listdir("/proc"):
            if entry.isdigit():
                try:
                    with open(f"/proc/{entry}/status") as f:
                        line = next((x for x in f if x.startswith("Uid:")), "")
                except OSError:
                    continue
                if str(uid) in line.split()[1:] and _running(entry):
                    found.add(int(entry))
    return found


# ----- the mount namespace --------------------------------------------------------------------
def _ro_flags(path: str) -> int:
    """The flags a read-only remount of a bind of `path` needs: read-only, no setuid programs,
    no devices, and the flags the source has locked (a user namespace may not clear them)."""
    flags = MS_REMOUNT | MS_BIND | MS_RDONLY | MS_NOSUID | MS_NODEV
    f = os.statvfs(path).f_flag
    for st, ms in ((os.ST_NOEXEC, MS_NOEXEC), (os.ST_NOATIME, MS_NOATIME),
                   (os.ST_NODIRATIME, MS_NODIRATIME), (4096, MS_RELATIME)):
        if f & st:
            flags |= ms
    return flags


class _MountAttr(ctypes.Structure):
    _fields_ = [("attr_set", ctypes.c_uint64), ("attr_clr", ctypes.c_uint64),
                ("propagation", ctypes.c_uint64), ("userns_fd", ctypes.c_uint64)]


def _read_only(target: str) -> None:
    """Make the bind at `target` read-only with everything mounted below it (mount_setattr,
    Linux 5.12+), else the bind itself."""
    attr = _MountAttr(1 | 2 | 4, 0, 0, 0)  # MOUNT_ATTR_RDONLY | NOSUID | NODEV
    done = _nr("mount_setattr") is not None and _lib().syscall(
        _nr("mount_setattr"), -100, target.encode(), 0x8000, ctypes.byref(attr),
        ctypes.sizeof(attr)) == 0
    if not done:
        _mount(None, target, None, _ro_flags(target))


def _bind(source: str, target: str, writable: bool) -> None:
    if os.path.isdir(source):
        os.makedirs(target, exist_ok=True)
    else:
        os.makedirs(os.path.dirname(target), exist_ok=True)
        if not os.path.exists(target):
            os.close(os.open(target, os.O_CREAT | os.O_WRONLY, 0o644))
    _mount(source, target, None, MS_BIND | MS_REC)
    if writable:
        _mount(None, target, None, MS_REMOUNT | MS_BIND | MS_NOSUID | MS_NODEV
               | (_ro_flags(target) & (MS_NOEXEC | MS_NOATIME | MS_NODIRATIME | MS_RELATIME)))
    else:
        _read_only(target)


def _system_paths() -> list[tuple[str, str]]:
    """(kind, path) of the system's part of the view: its program and library folders (or the
    symlinks that stand for them) and the few files of /etc."""
    out: list[tuple[str, str]] = []
    for path in SYSTEM_DIRS:
        if os.path.islink(path):
            out.append(("link", path))
        elif os.path.isdir(path):
            out.append(("ro", path))
    for name in SYSTEM_ETC:
        path = os.path.join("/etc", name)
        if os.path.exists(path):
            out.append(("ro", os.path.realpath(path) if not os.path.isdir(path) else path))
    return out


def _build_root(plan: Plan) -> None:
    """The jail's file system: a tmpfs root with read-only binds, the scratch folder writable,
    then pivot_root into it and the old root detached."""
    _mount(None, "/", None, MS_REC | MS_PRIVATE)
    root = plan.root
    _mount("tmpfs", root, "tmpfs", MS_NOSUID | MS_NODEV, "mode=0755,size=16m")
    entries = _system_paths() + [("ro", p) for p in plan.readable]
    entries += [("tmpfs", "/tmp"), ("rw", plan.scratch)]
    entries += [("hide", p) for p in plan.hidden]
    seen = set()
    order = {"tmpfs": 0, "link": 0, "ro": 1, "rw": 2, "hide": 3}
    for kind, path in sorted(entries, key=lambda e: (e[1].count("/"), order[e[0]], e[1])):
        if (kind, path) in seen or not os.path.isabs(path):
            continue
        seen.add((kind, path))
        target = root + path
        if kind == "link":
            if not os.path.lexists(target):
                os.symlink(os.readlink(path), target)
        elif kind == "tmpfs":
            os.makedirs(target, exist_ok=True)
            _mount("tmpfs", target, "tmpfs", MS_NOSUID | MS_NODEV, "mode=1777,size=128m")
        elif kind == "rw" and path == plan.scratch:
            _scratch(plan, target)
        elif kind == "hide":
            if os.path.isdir(target):
                _mount("tmpfs", target, "tmpfs", MS_NOSUID | MS_NODEV | MS_RDONLY,
                       "mode=0755,size=4k")
            elif os.path.exists(target):
                _mount("/dev/null", target, None, MS_BIND)
        elif os.path.exists(path):
            _bind(path, target, writable=(kind == "rw"))
    _dev(root)
    os.makedirs(root + "/proc", exist_ok=True)
    with _suppress(OSError):  # refused where /proc is masked (a container): no /proc
        _mount("proc", root + "/proc", "proc", MS_NOSUID | MS_NODEV | MS_NOEXEC)
    with _suppress(OSError):
        _ok(_syscall("sethostname", b"mexone-jail", 11), "sethostname")
    os.chdir(root)
    if _syscall("pivot_root", b".", b".") == 0:  # the old root is stacked on ".": detach it
        _ok(_lib().umount2(b".", MNT_DETACH), "umount2 old root")
    else:
        _ok(_syscall("chroot", b"."), "chroot")
    os.chdir("/")
    _mount(None, "/", None, MS_REMOUNT | MS_BIND | MS_RDONLY | MS_NOSUID | MS_NODEV)


def _scratch(plan: Plan, target: str) -> None:
    """The scratch folder in the jail: a tmpfs of `plan.scratch_mb` (the jail's uid's) holding
    a copy of the folder as the grader left it (a run's inputs, a home's caches). Writes past
    its size fail (ENOSPC) inside the jail, not on the machine's disk, which the grader and the
    other runs need. Nothing is read back from a scratch folder: the copy is the jail's."""
    os.makedirs(target, exist_ok=True)
    owner = "" if plan.uid is None else f",uid={plan.uid},gid={plan.gid}"
    _mount("tmpfs", target, "tmpfs", MS_NOSUID | MS_NODEV, f"mode=0700,size={plan.scratch_mb}m"
           + owner)
    source = plan.scratch
    for folder, dirs, files in os.walk(source):
        into = target + folder[len(source):]
        for name in dirs:
            os.makedirs(os.path.join(into, name), mode=0o755, exist_ok=True)
        for name in files:
            src, dst = os.path.join(folder, name), os.path.join(into, name)
            if os.path.islink(src):
                os.symlink(os.readlink(src), dst)
                continue
            with open(src, "rb") as fin, open(dst, "wb") as fout:
                while chunk := fin.read(1 << 20):
                    fout.write(chunk)
            os.chmod(dst, os.stat(src).st_mode & 0o777)
        if plan.uid is not None:
            assert plan.gid is not None  # a plan with a uid has its gid (spawn: gid=uid)
            for name in (into, *(os.path.join(into, n) for n in dirs + files)):
                os.chown(name, plan.uid, plan.gid, follow_symlinks=False)


def _dev(root: str) -> None:
    dev = root + "/dev"
    os.makedirs(dev, exist_ok=True)
    _mount("tmpfs", dev, "tmpfs", MS_NOSUID, "mode=0755,size=64k")
    for name in DEVICES:
        if os.path.exists("/dev/" + name):
            os.close(os.open(f"{dev}/{name}", os.O_CREAT | os.O_WRONLY, 0o666))
            _mount("/dev/" + name, f"{dev}/{name}", None, MS_BIND)
    for name, to in (("fd", "/proc/self/fd"), ("stdin", "/proc/self/fd/0"),
                     ("stdout", "/proc/self/fd/1"), ("stderr", "/proc/self/fd/2")):
        os.symlink(to, f"{dev}/{name}")
    os.makedirs(dev + "/shm")
    _mount("tmpfs", dev + "/shm", "tmpfs", MS_NOSUID | MS_NODEV, "mode=1777,size=64m")


# ----- the program's own limits ---------------------------------------------------------------
def _confine(plan: Plan, keep_fds: tuple[int, ...]) -> None:
    """The jail's program, before it runs: its own session, another user, limits, Landlock,
    seccomp; only the descriptors it keeps; its working folder the scratch folder."""
    os.setsid()
    for cap in range(64):  # the bounding set, while this process may still change it
        if _prctl(PR_CAPBSET_DROP, cap) < 0:
            break  # EINVAL: past the last capability; EPERM: it had none to drop
    if plan.uid is not None and os.geteuid() == 0:
        assert plan.gid is not None  # a plan with a uid has its gid (spawn: gid=uid)
        os.setgroups([])
        os.setresgid(plan.gid, plan.gid, plan.gid)
        os.setresuid(plan.uid, plan.uid, plan.uid)
    _drop_capabilities()
    cpu = max(1, int(plan.cpu))
    resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 1))
    for limit, value in ((resource.RLIMIT_AS, plan.memory_mb << 20), (resource.RLIMIT_CORE, 0),
                         (resource.RLIMIT_FSIZE, plan.file_mb << 20)):
        with _suppress(ValueError, OSError):
            resource.setrlimit(limit, (value, value))
    if plan.mode != "none" or plan.uid is not None:  # counted per user: the jail's own
        with _suppress(ValueError, OSError):
            resource.setrlimit(resource.RLIMIT_NPROC, (plan.processes, plan.processes))
    os.chdir(plan.scratch)
    _ok(_prctl(PR_SET_NO_NEW_PRIVS, 1), "no_new_privs")
    if plan.landlock:
        _landlock(plan)
    if plan.seccomp:
        _seccomp(plan.network)
    keep = {0, 1, 2, *keep_fds}
    with _suppress(OSError):
        for fd in [int(x) for x in os.listdir("/proc/self/fd")]:
            if fd not in keep:
                with _suppress(OSError):
                    os.close(fd)


class _CapHeader(ctypes.Structure):
    _fields_ = [("version", ctypes.c_uint32), ("pid", ctypes.c_int)]


class _CapData(ctypes.Structure):
    _fields_ = [("effective", ctypes.c_uint32), ("permitted", ctypes.c_uint32),
                ("inheritable", ctypes.c_uint32)]


def _drop_capabilities() -> None:
    """No capability left, none to regain (the bounding set is emptied before): the ambient set
    cleared, effective, permitted and inheritable sets zero (a jail in a user namespace is root of it
    until here; a root grader's jail without another uid keeps uid 0 but no privilege)."""
    if sys.platform != "linux":
        return
    _prctl(47, 4)  # PR_CAP_AMBIENT, PR_CAP_AMBIENT_CLEAR_ALL
    header = _CapHeader(0x20080522, 0)  # _LINUX_CAPABILITY_VERSION_3
    data = (_CapData * 2)()
    _ok(_lib().capset(ctypes.byref(header), data), "capset")


# ----- Landlock -------------------------------------------------------------------------------
_FS_RIGHTS = {1: (1 << 13) - 1, 2: (1 << 14) - 1, 3: (1 << 15) - 1, 4: (1 << 15) - 1,
              5: (1 << 16) - 1}
_READ = 1 | 4 | 8  # EXECUTE, READ_FILE, READ_DIR
_FILE_RIGHTS = 1 | 2 | 4 | (1 << 14) | (1 << 15)  # what a rule on a file may grant


class _RulesetAttr(ctypes.Structure):
    _fields_ = [("handled_access_fs", ctypes.c_uint64), ("handled_access_net", ctypes.c_uint64),
                ("scoped", ctypes.c_uint64)]


class _PathBeneath(ctypes.Structure):
    _pack_ = 1
    _fields_ = [("allowed_access", ctypes.c_uint64), ("parent_fd", ctypes.c_int32)]


def _landlock(plan: Plan) -> None:
    """Landlock rules: read (and run) the view, write the scratch folder (and /tmp, /dev/shm
    in a namespace); no TCP unless the plan allows the network; no signal or abstract socket
    beyond the jail (ABI 6)."""
    abi = min(plan.landlock, 7)
    fs = _FS_RIGHTS[min(abi, 5)]
    attr = _RulesetAttr(fs, 0 if plan.network or abi < 4 else 3, 3 if abi >= 6 else 0)
    size = 8 if abi < 4 else (16 if abi < 6 else 24)
    ruleset = _ok(_syscall("landlock_create_ruleset", ctypes.byref(attr), size, 0),
                  "landlock_create_ruleset")
    try:
        if plan.mode == "namespaces":
            reads = ["/"]
            writes = [plan.scratch, "/tmp", "/dev/shm"]
        else:
            reads = [p for kind, p in _system_paths() if kind == "ro"] + list(plan.readable)
            reads += ["/proc"]
            writes = [plan.scratch]
        devices = [f"/dev/{d}" for d in DEVICES]
        for path in reads:
            _allow(ruleset, path, _READ, plan.hidden)
        for path in writes:
            _allow(ruleset, path, fs, ())
        for path in devices:
            _allow(ruleset, path, (1 | 2 | 4 | (1 << 14) | (1 << 15)) & fs, ())
        _ok(_syscall("landlock_restrict_self", ruleset, 0), "landlock_restrict_self")
    finally:
        os.close(ruleset)


def _allow(ruleset: int, path: str, access: int, hidden: Sequence[str]) -> None:
    """A rule granting `access` beneath `path`; where one of `hidden` lies beneath it, the
    rule goes to each of its entries but the hidden one instead (Landlock only allows)."""
    inside = [h for h in hidden if h.startswith(path.rstrip("/") + "/")]
    if inside and os.path.isdir(path):
        with _suppress(OSError):
            for name in os.listdir(path):
                child = os.path.join(path, name)
                if child in hidden:
                    continue
                _allow(ruleset, child, access, inside)
        _add_rule(ruleset, path, access & 8)  # its listing (READ_DIR), not its files
        return
    _add_rule(ruleset, path, access)


def _add_rule(ruleset: int, path: str, access: int) -> None:
    try:
        fd = os.open(path, os.O_PATH | os.O_CLOEXEC)
    except OSError:
        return
    try:
        if not os.path.isdir(path):
            access &= _FILE_RIGHTS
        if access:
            rule = _PathBeneath(access, fd)
            _ok(_syscall("landlock_add_rule", ruleset, 1, ctypes.byref(rule), 0),
                f"landlock rule for {path}")
    finally:
        os.close(fd)


# ----- seccomp --------------------------------------------------------------------------------
_LD, _JEQ, _JGE, _JSET, _RET = 0x20, 0x15, 0x35, 0x45, 0x06
_MODE_ARGS = (("chmod", 1), ("fchmod", 1), ("fchmodat", 2), ("fchmodat2", 2), ("open", 2),
              ("openat", 3), ("creat", 1), ("mknod", 1), ("mknodat", 2))  # (call, its mode)
_ALLOW, _ERRNO, _KILL = 0x7FFF0000, 0x00050000, 0x80000000


class _SockFilter(ctypes.Structure):
    _fields_ = [("code", ctypes.c_uint16), ("jt", ctypes.c_uint8), ("jf", ctypes.c_uint8),
                ("k", ctypes.c_uint32)]


class _SockFprog(ctypes.Structure):
    _fields_ = [("len", ctypes.c_ushort), ("filter", ctypes.POINTER(_SockFilter))]


def _program(network: bool, allow_all: bool = False) -> list[tuple[Any, ...]]:
    """The filter as (code, jump-if-true, jump-if-false, k); jumps name labels."""
    machine = os.uname().machine
    table = _SYSCALLS[machine]
    if allow_all:
        return [(_RET, 0, 0, _ALLOW)]
    prog: list[tuple[Any, ...]] = [(_LD, 0, 0, 4), (_JEQ, 0, "kill", _AUDIT_ARCH[machine]), (_LD, 0, 0, 0)]
    if machine == "x86_64":
        prog.append((_JGE, "eperm", 0, 0x40000000))  # the x32 ABI's numbers
    for name in DENIED:
        if name in table:
            prog.append((_JEQ, "eperm", 0, table[name]))
    prog.append((_JEQ, "enosys", 0, table["clone3"]))  # its flags are out of reach: use clone
    prog.append((_JEQ, "enosys", 0, table["openat2"]))  # its mode too: glibc's open is openat
    for name, arg in _MODE_ARGS:  # no set-user/group-ID bit on a file it makes (a root's jail)
        if name in table:
            prog.append((_JEQ, f"mode{arg}", 0, table[name]))
    prog.append((_JEQ, "clone", 0, table["clone"]))
    if not network:
        prog.append((_JEQ, "socket", 0, table["socket"]))
    prog.append((_RET, 0, 0, _ALLOW))
    namespaces = NAMESPACES
    for arg in sorted({a for _, a in _MODE_ARGS}):
        prog += [(f"mode{arg}", None), (_LD, 0, 0, 16 + 8 * arg), (_JSET, "eperm", 0, 0o6000),
                 (_RET, 0, 0, _ALLOW)]
    prog += [("clone", None), (_LD, 0, 0, 16), (_JSET, "eperm", 0, namespaces), (_RET, 0, 0, _ALLOW),
             ("socket", None), (_LD, 0, 0, 16), (_JEQ, 0, "noaf", 1), (_RET, 0, 0, _ALLOW),
             ("noaf", None), (_RET, 0, 0, _ERRNO | 97),  # EAFNOSUPPORT
             ("eperm", None), (_RET, 0, 0, _ERRNO | 1),
             ("enosys", None), (_RET, 0, 0, _ERRNO | 38),
             ("kill", None), (_RET, 0, 0, _KILL)]
    return prog


def _assemble(prog: list[tuple[Any, ...]]) -> list[tuple[int, int, int, int]]:
    labels: dict[str, int]
    out: list[tuple[Any, ...]]
    labels, out = {}, []
    for item in prog:
        if len(item) == 2:
            labels[item[0]] = len(out)
        else:
            out.append(item)
    code: list[tuple[int, int, int, int]] = []
    for i, (op, jt, jf, k) in enumerate(out):
        def jump(to: int | str, i: int = i) -> int:
            return to if isinstance(to, int) else labels[to] - i - 1
        code.append((op, jump(jt), jump(jf), k))
        if not (0 <= code[-1][1] <= 255 and 0 <= code[-1][2] <= 255):
            raise JailError(22, "the seccomp filter's jumps are too long")
    return code


def _seccomp(network: bool, allow_all: bool = False) -> None:
    code = _assemble(_program(network, allow_all))
    array = (_SockFilter * len(code))(*[_SockFilter(*c) for c in code])
    prog = _SockFprog(len(code), array)
    _ok(_lib().prctl(PR_SET_SECCOMP, 2, ctypes.addressof(prog), 0, 0), "seccomp")
