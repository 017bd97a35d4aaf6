"""A graded controller's worker is forked warm from the runs' fork server (the zygote), not a
fresh interpreter: the boundary that fork must keep. The student's module, imported in the
worker, tries the zygote (signal it, read its environment and memory), looks for the teacher's
secret and for any descriptor of the zygote's (its door for workers among them), and says what
it found in its import's error, which the simulator reads back."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pytest

from mexone.exercises import isolate
from mexone.sandbox import isolation

pytestmark = pytest.mark.skipif(sys.platform != "linux" or isolation().mode == "none",
                                reason="the jail's layers are Linux's namespaces or uids")

SECRET = "teacher-secret-zygote-41"

ATTACK = '''
import ctypes, errno, json, os

SERVER, RUN, ZYGOTE = {server}, {run}, {zygote}
libc = ctypes.CDLL(None, use_errno=True)


def kill(pid):  # the system call itself, past the guard's os.kill
    if libc.kill(pid, 0) != 0:
        number = ctypes.get_errno()
        raise OSError(number, os.strerror(number))


found = {{}}
for name, what in (("kill", lambda: kill(SERVER)),
                   ("env", lambda: open(f"/proc/{{SERVER}}/environ", "rb").read()),
                   ("mem", lambda: open(f"/proc/{{SERVER}}/mem", "rb").read(1)),
                   ("run", lambda: kill(RUN))):
    try:
        what()
        found[name] = "reached"
    except OSError as exc:
        found[name] = errno.errorcode.get(exc.errno, "?")
found["secret"] = sum(k == "MEXONE_EXERCISE_SECRET" or "{secret}" in v
                      for k, v in os.environ.items())
links = [os.readlink(f"/proc/self/fd/{{fd}}") for fd in os.listdir("/proc/self/fd")
         if int(fd) > 2 and os.path.exists(f"/proc/self/fd/{{fd}}")]
found["fds"], found["shared"] = len(links), len(set(links) & set(ZYGOTE))
import mexone.exercises.isolate as iso
found["door"] = iso._door is not None and iso._door.fileno() != -1
found["uid"] = os.getuid()
raise RuntimeError("FOUND" + json.dumps(found, separators=(",", ":")))  # its scratch is its own
'''


def _attack_from_a_worker(folder: str, server: int, zygote: list[str]) -> str:
    """In the simulator (a trusted run): a worker for the attack's class, as a graded lab starts
    one; what its module found."""
    from mexone.control import worker
    from mexone.errors import InputError

    path = Path(folder) / "attack.py"
    path.write_text(ATTACK.format(server=server, run=os.getpid(), zygote=zygote,
                                   secret=SECRET))
    started = worker._start(readable=(Path(folder),))
    assert isinstance(started.process.popen, isolate.Forked), "not forked by the zygote"
    try:
        worker._describe_in(started, "attack/Attack", Path(folder), [])
    except InputError as exc:
        return str(exc).partition("FOUND")[2].partition(" (fix")[0]
    finally:
        started.kill()


def _links(pid: int) -> set[str]:
    """The pipes and sockets process `pid` holds."""
    found = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            link = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:
            continue
        if link.startswith(("socket:", "pipe:")):
            found.add(link)
    return found


def test_a_worker_forked_by_the_zygote_reaches_neither_it_nor_the_secret(tmp_path, monkeypatch):
    monkeypatch.setenv("MEXONE_EXERCISE_SECRET", SECRET)
    server = isolate._server(restart=True)  # started with the secret in the grader's environment
    try:
        folder = tmp_path / "class"
        folder.mkdir()
        os.chmod(tmp_path, 0o755)
        os.chmod(folder, 0o777)  # the simulator writes the attack; a jail of another uid reads
        assert isolate.run_isolated(sum, [1, 2]) == 3  # the server is up: its door made
        zygote = _links(server.process.pid)
        found = json.loads(isolate.run_trusted(_attack_from_a_worker, str(folder),
                                               server.process.pid, sorted(zygote)))
    finally:
        isolate._server(restart=True)
    assert {found[k] for k in ("kill", "env", "mem", "run")} <= {"ESRCH", "EPERM", "ENOENT",
                                                                 "EACCES"}, found
    assert found["secret"] == 0 and found["door"] is False, found
    assert found["shared"] == 0 and found["fds"] <= 4, found  # frames, descriptors, dump (+ ls)
    if os.geteuid() == 0:
        assert found["uid"] != 0, found


def _probed() -> list[object]:
    import importlib

    spawn = importlib.import_module("mexone.sandbox.spawn")  # the module, not its function
    return [spawn._hidden is not None, spawn.isolation().mode]


def test_the_simulator_inherits_the_probe_and_a_jail_probes_its_own():
    """The fork server probes the machine once for its simulators; a jailed run forgets that
    answer (inside, seccomp refuses new namespaces: a jail it starts, exercise 14's observer's,
    set up with the outside's answer ended with exit status 3 in every run)."""
    assert isolate.run_trusted(_probed) == [True, isolation().mode]
    hidden, mode = isolate.run_jailed(_probed)
    assert not hidden and mode != "namespaces"
