"""sandbox.spawn as a student's code attacks it, in every isolation the machine offers (the
namespaces, another uid, none) and, as root, also from a grader that is not root (a user
namespace): the teacher's secret in an ancestor's environment (a shell's `timeout`), writes
outside the scratch folder (another student's submission), programs left running in a session
of their own, the network, the processes it can see."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from helpers import sleeping, wait_until
from mexone.sandbox import Jail, spawn
from mexone.sandbox.spawn import MODE_ENV, isolation

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="the jail's layers are Linux's")

SECRET = "teacher-secret-5f3a"
MARK = "317.25"  # the sleeps' duration: how the test finds them in the process table

ATTACK = textwrap.dedent('''
    import json, os, socket, subprocess, sys
    other, port = sys.argv[1], int(sys.argv[2])
    found = {"secret": [], "wrote": [], "net": [], "pids": 0}
    for pid in os.listdir("/proc"):
        if pid.isdigit():
            found["pids"] += 1
            try:
                with open(f"/proc/{pid}/environ", "rb") as f:
                    if b"teacher-secret" in f.read():
                        found["secret"].append(pid)
            except OSError:
                pass
    if any("teacher-secret" in v for v in os.environ.values()):
        found["secret"].append("own environment")
    for path in (other, "/tmp/jail-test-outside.txt", os.path.expanduser("~/../x.txt")):
        try:
            with open(path, "w") as f:
                f.write("overwritten")
            found["wrote"].append(path)
        except OSError:
            pass
    with open("mine.txt", "w") as f:  # its scratch folder: allowed
        f.write("ok")
    for family, kind in ((socket.AF_INET, socket.SOCK_STREAM), (socket.AF_INET, socket.SOCK_DGRAM),
                         (socket.AF_INET6, socket.SOCK_STREAM)):
        try:
            s = socket.socket(family, kind)
            s.settimeout(2)
            s.connect(("127.0.0.1" if family == socket.AF_INET else "::1", port))
            s.send(b"x")
            found["net"].append(f"{family.name} {kind.name}")
        except OSError:
            pass
    for _ in range(40):
        subprocess.Popen(["sleep", "MARK"], start_new_session=True)
    print(json.dumps(found), flush=True)
''').replace("MARK", MARK)

SPAWNER = textwrap.dedent('''
    import json, subprocess, sys
    from mexone.sandbox import Jail, spawn
    python, other, port = sys.argv[1:4]
    jail = Jail(another_user=sys.argv[5:6] == ["grader"])
    with spawn([python, "-c", sys.argv[4], other, port], jail, stdout=subprocess.PIPE) as p:
        out, _ = p.popen.communicate(timeout=60)
        code = p.returncode
    print(json.dumps({"code": code, "out": out.decode()}))
''')


def _sleeps() -> list[int]:
    return sleeping(MARK)


def _outside(wrote: list[str], private_tmp: bool) -> list[str]:
    """The writes that reached the grader's file system (a jail in a mount namespace writes
    to a /tmp of its own, gone with it)."""
    return [w for w in wrote if not (private_tmp and w.startswith("/tmp/"))]


def _modes() -> list[str]:
    offered = isolation().mode
    order = ["none", "uid", "namespaces"]
    modes = order[:order.index(offered) + 1]
    return [m for m in modes if m != "uid" or isolation().root]


def _python(mode: str) -> str:
    """A Python the jail can run: another uid needs one others can read (/usr/bin's)."""
    if mode != "uid":
        return sys.executable
    for path in ("/usr/bin/python3", "/usr/local/bin/python3"):
        if os.access(path, os.X_OK):
            return path
    pytest.skip("no Python outside /root for a jail of another uid")


@pytest.fixture
def listener():
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(50)
    server.settimeout(0.1)
    yield server
    server.close()


def _shared_folder() -> Path:
    """A folder every user may enter (a grader that is not root works there)."""
    folder = Path("/tmp") / f"mexone-jail-test-{os.getpid()}"
    folder.mkdir(exist_ok=True)
    os.chmod(folder, 0o777)
    return folder


@pytest.mark.parametrize("who", ["grader", "lab"])
@pytest.mark.parametrize("mode", _modes())
def test_a_jail_reads_no_secret_writes_nothing_outside_leaves_nothing_and_has_no_network(
        mode, who, listener, monkeypatch):
    """The grader runs under `timeout` with the secret in its environment (as a course's
    run_autograder would): no process the jail can see holds it; another student's file is
    unchanged; the 40 sleeps in sessions of their own end with the jail; no socket reaches a
    server listening on the grader's loopback. A grader's jail (a uid of the pool, as root) and
    the lab's (the spawner's uid, no capabilities) alike."""
    folder = _shared_folder()
    other = folder / "zzz.py"
    other.write_text("zzz's submission\n")
    os.chmod(other, 0o666)  # even a file every user may write
    env = {**os.environ, MODE_ENV: mode, "MEXONE_EXERCISE_SECRET": SECRET,
           "PYTHONPATH": str(Path(__file__).resolve().parents[2] / "src")}
    try:
        python = _python(mode if who == "grader" else "none")
        out = subprocess.run(["timeout", "120", sys.executable, "-c", SPAWNER, python,
                              str(other), str(listener.getsockname()[1]), ATTACK, who], env=env,
                             capture_output=True, text=True, timeout=150, cwd=folder)
        assert out.returncode == 0, out.stderr
        report = json.loads(out.stdout)
        assert report["code"] == 0, report
        found = json.loads(report["out"])
        assert found["secret"] == [], found
        assert _outside(found["wrote"], mode == "namespaces") == [], found
        assert other.read_text() == "zzz's submission\n"
        assert found["net"] == [], found
        with pytest.raises(TimeoutError):
            listener.accept()
        if mode == "namespaces":
            assert found["pids"] <= 3, found  # its init, itself, the ls it ran: nothing else
        assert wait_until(lambda: not _sleeps(), timeout=10), _sleeps()
        assert not Path("/tmp/jail-test-outside.txt").exists()
    finally:
        shutil.rmtree(folder, ignore_errors=True)


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0 or not shutil.which("su"),
                    reason="a grader that is not root is tried from root (su nobody)")
@pytest.mark.parametrize("mode", ["namespaces", "none"])
def test_a_grader_that_is_not_root_gets_a_user_namespace(mode, listener):
    """The same attacks from a grader running as nobody: a user namespace of its own (where
    the machine allows unprivileged user namespaces), else ("none") Landlock alone keeps the
    secret of the `timeout` above it, which runs as the same user."""
    folder = _shared_folder()
    other = folder / "zzz.py"
    other.write_text("zzz's submission\n")
    os.chmod(other, 0o666)
    try:
        python = _python("uid")
        for name, text in (("spawner.py", SPAWNER), ("attack.py", ATTACK)):
            (folder / name).write_text(text)
        # mexone where nobody can read it: a checkout may sit in a folder only root enters
        # (CI's clone), and a grader's code is installed for the user who runs it
        src = folder / "src"
        shutil.copytree(Path(__file__).resolve().parents[2] / "src" / "mexone", src / "mexone",
                        ignore=shutil.ignore_patterns("__pycache__"))
        command = (f"cd {folder} && MEXONE_SANDBOX={mode} MEXONE_EXERCISE_SECRET={SECRET} "
                   f"PYTHONPATH={src} timeout 120 "
                   f"{python} spawner.py {python} {other} {listener.getsockname()[1]} "
                   f"\"$(cat attack.py)\" grader")
        out = subprocess.run(["su", "nobody", "-s", "/bin/sh", "-c", command],
                             capture_output=True, text=True, timeout=150)
        assert out.returncode == 0, out.stderr
        report = json.loads(out.stdout)
        found = json.loads(report["out"])
        assert report["code"] == 0 and found["secret"] == [], found
        assert _outside(found["wrote"], private_tmp=True) == [], found
        assert found["net"] == [] and other.read_text() == "zzz's submission\n"
        assert wait_until(lambda: not _sleeps(), timeout=10), _sleeps()
        assert not Path("/tmp/jail-test-outside.txt").exists()
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def test_kill_ends_what_the_jail_started_in_any_session(tmp_path):
    code = (f"import subprocess, time\nfor _ in range(5):\n"
            f"    subprocess.Popen(['sleep', '{MARK}'], start_new_session=True)\n"
            "print('up', flush=True)\ntime.sleep(300)\n")
    before = set(_sleeps())  # none, unless an earlier failed run left its own behind
    proc = spawn([sys.executable, "-c", code], Jail(), stdout=subprocess.PIPE)
    started: set[int] = set()
    try:
        assert proc.popen.stdout.readline() == b"up\n"
        started = set(_sleeps()) - before
        assert len(started) == 5, f"{len(started)} sleeps found of the 5 started"
        proc.kill()
        assert proc.returncode is not None
        assert wait_until(lambda: not started & set(_sleeps()), timeout=10), \
            f"alive 10 s after the kill: {sorted(started & set(_sleeps()))}"
        assert not proc.scratch.exists()  # its own scratch folder went with it
    finally:  # a failed run leaves nothing behind for the next one
        proc.kill()
        for pid in started & set(_sleeps()):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)


def test_the_program_exit_status_and_signal_come_through():
    """The handle's status is the jail's program's: an exit code, or the signal that ended it
    (SIGXCPU past the CPU limit, as a grader reports it)."""
    from mexone.sandbox import Limits

    with spawn([sys.executable, "-c", "import sys; sys.exit(7)"], Jail()) as proc:
        assert proc.wait(60) == 7
    with spawn([sys.executable, "-c", "while True: pass"], Jail(limits=Limits(cpu=1))) as proc:
        assert proc.wait(60) == -24  # SIGXCPU


@pytest.mark.parametrize("mode", _modes())
def test_what_a_jail_may_read(mode, monkeypatch):
    """Its readable folders, not what is hidden inside them (a teacher's pack installed in
    site-packages), nor anything else of the grader's."""
    folder = _shared_folder()
    try:
        pack = folder / "pack"
        (pack / "solutions").mkdir(parents=True)
        (pack / "visible.txt").write_text("seen\n")
        (pack / "solutions" / "answer.py").write_text("ANSWER = 42\n")
        (folder / "elsewhere.txt").write_text("not for the jail\n")
        for path in (pack, pack / "solutions"):
            os.chmod(path, 0o755)
        code = textwrap.dedent(f'''
            import json
            out = {{}}
            for path in ("{pack}/visible.txt", "{pack}/solutions/answer.py",
                         "{folder}/elsewhere.txt"):
                try:
                    out[path.rsplit("/", 1)[1]] = open(path).read().strip()
                except OSError as exc:
                    out[path.rsplit("/", 1)[1]] = exc.strerror
            print(json.dumps(out))
        ''')
        monkeypatch.setenv(MODE_ENV, mode)
        monkeypatch.setattr(sys.modules["mexone.sandbox.spawn"], "_isolation", None)
        jail = Jail(readable=(pack,), hidden=(pack / "solutions",), another_user=True)
        with spawn([_python(mode), "-c", code], jail, stdout=subprocess.PIPE) as proc:
            out = json.loads(proc.popen.stdout.read())
        assert out["visible.txt"] == "seen", out
        assert out["answer.py"] != "ANSWER = 42" and out["elsewhere.txt"] != "not for the jail", out
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def test_a_jail_of_the_spawners_own_uid_makes_no_set_uid_file():
    """A root lab's jail runs as root without capabilities: it may not mark a file of its own
    set-user-ID (it would be root's outside), by chmod or at creation."""
    code = textwrap.dedent('''
        import os
        out = []
        open("f", "w").close()
        for call in (lambda: os.chmod("f", 0o4755), lambda: os.chmod("f", 0o2755),
                     lambda: os.close(os.open("g", os.O_CREAT | os.O_WRONLY, 0o4755))):
            try:
                call()
                out.append("allowed")
            except PermissionError:
                out.append("refused")
        os.chmod("f", 0o755)
        print(" ".join(out), oct(os.stat("f").st_mode & 0o7777))
    ''')
    with spawn([sys.executable, "-c", code], Jail(), stdout=subprocess.PIPE) as proc:
        assert proc.popen.stdout.read().decode().split() == ["refused"] * 3 + ["0o755"]
