"""A real class on this machine: JupyterHub from PyPI, its proxy (configurable-http-proxy from
npm), LocalProcessSpawner and one Unix user per student, each student's Jupyter server running
mexone's launcher entry (jupyter-server-proxy).

The students' processes never touch this checkout: CI may clone it anywhere (under /root, mode
0700, where other users cannot enter). They run a venv of Debian's Python in HOME, a folder every
user can enter outside the checkout, with mexone installed from a wheel of the checkout (not
editable), rebuilt when the wheel changes. `python tests/hub/classroom.py` (scripts/test.sh)
builds it ahead of the tests; the tests' session fixture brings it up to date.

Shared by tests/hub (two students in a browser) and benchmarks/hub_class.py (twenty)."""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import pwd
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
# one per checkout (helpers' worktrees on one machine do not share their classes)
HOME = Path(os.environ.get("MEXONE_HUB_DIR")
            or f"/var/tmp/mexone-hub-{hashlib.sha256(str(ROOT).encode()).hexdigest()[:12]}")
VENV = HOME / "venv"
# the test's own Python may live where the students cannot enter (pyenv's, in /root)
DEBIAN_PYTHON = Path("/usr/bin/python3")
PACKAGES = ("mexone[hub]", "jupyterhub")  # deploy/zero-to-jupyterhub/Dockerfile's (test_deploy.py)
CHP = Path(__file__).resolve().parent / "node_modules" / ".bin" / "configurable-http-proxy"
PASSWORD = "mexone-class"


def missing() -> str | None:
    """Why a class cannot run here, or None."""
    if os.geteuid() != 0:
        return "a class on this machine needs root (one Unix user per student)"
    if not CHP.exists():
        return "configurable-http-proxy is missing: npm install --prefix tests/hub"
    if subprocess.run([DEBIAN_PYTHON, "-c", "import ensurepip, venv"], capture_output=True).returncode:
        return f"the students' venv needs {DEBIAN_PYTHON} with venv: apt-get install python3-venv"
    closed = _closed_folder(HOME)
    if closed:
        return f"{closed} is closed to other users: the students cannot run {VENV} (MEXONE_HUB_DIR)"
    return None


def _closed_folder(path: Path) -> Path | None:
    """The first existing folder on `path` (or above it) other users cannot enter."""
    for folder in [path, *path.parents]:
        if folder.exists() and not folder.stat().st_mode & 0o001:
            return folder
    return None


def _record(wheel: Path) -> str:
    """What a wheel holds: its RECORD's hash (every file's own hash and size)."""
    with zipfile.ZipFile(wheel) as z:
        (name,) = [n for n in z.namelist() if n.endswith(".dist-info/RECORD")]
        return hashlib.sha256(z.read(name)).hexdigest()


def students_venv(wheel: Path | None = None) -> Path:
    """VENV with PACKAGES, its mexone installed from `wheel` (by default one built here from the
    checkout's files git knows): created when missing, mexone reinstalled when the wheel differs
    from the one installed. Readable by every user whatever the umask. Returns VENV."""
    if wheel is None:
        import wheelenv  # tests/

        with tempfile.TemporaryDirectory() as tmp:
            (Path(tmp) / "tree").mkdir()
            return students_venv(wheelenv.wheel_of_checkout(Path(tmp) / "tree", Path(tmp)))
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    stamp, record = VENV / "mexone-wheel.sha256", _record(wheel)
    umask = os.umask(0o022)
    try:
        HOME.mkdir(mode=0o755, parents=True, exist_ok=True)
        with (HOME / "venv.lock").open("w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # two sessions of one checkout: one builds
            if stamp.exists() and stamp.read_text() == record:
                return VENV
            if not (VENV / "bin" / "python").exists():
                subprocess.run([DEBIAN_PYTHON, "-m", "venv", str(VENV)], check=True, env=env)
            pip = [str(VENV / "bin" / "python"), "-m", "pip", "install", "-q",
                   "--disable-pip-version-check"]
            extra = PACKAGES[0].removeprefix("mexone")
            for args in ([f"{wheel}{extra}", *PACKAGES[1:]],  # what it needs (none when there)
                         ["--no-deps", "--force-reinstall", str(wheel)]):  # this mexone
                out = subprocess.run(pip + args, capture_output=True, text=True, env=env)
                if out.returncode:
                    raise RuntimeError(f"the students' venv {VENV}: pip {' '.join(args)}:\n"
                                       f"{out.stderr[-3000:]}")
            stamp.write_text(record)
    finally:
        os.umask(umask)
    return VENV


def class_names(*roles: str) -> list[str]:
    """Unix user names for a class's students, e.g. mexone-3fa2-a: another class (a second test
    run on the machine) never shares them."""
    tag = secrets.token_hex(2)
    return [f"mexone-{tag}-{role}" for role in roles]


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class Classroom:
    """`students` Unix users (created here, deleted by stop()) and a hub serving them."""

    students: list[str]
    folder: Path = field(default_factory=lambda: _class_folder())
    port: int = field(default_factory=_free_port)
    api_token: str = field(default_factory=lambda: secrets.token_hex(16))
    hub: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self, timeout: float = 120.0) -> Classroom:
        _end_stale_classes()
        self.folder.chmod(0o755)
        (self.folder / "students").write_text("\n".join(self.students))
        for name in self.students:
            self._add_user(name)
        config = self.folder / "jupyterhub_config.py"
        config.write_text(self._config())
        log = (self.folder / "hub.log").open("w")
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
        self.hub = subprocess.Popen([sys.executable, "-m", "jupyterhub", "-f", str(config)],
                                    cwd=self.folder, stdout=log, stderr=subprocess.STDOUT, env=env,
                                    start_new_session=True)
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.hub.poll() is not None:
                raise RuntimeError(f"jupyterhub exited:\n{self.log()[-3000:]}")
            try:
                self.api("GET", "/")
                return self
            except (OSError, urllib.error.URLError):
                time.sleep(0.3)
        raise TimeoutError(f"jupyterhub did not answer in {timeout} s:\n{self.log()[-3000:]}")

    def log(self) -> str:
        path = self.folder / "hub.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def _config(self) -> str:
        keep = [k for k in ("OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE", "MUJOCO_GL") if k in os.environ]
        return f"""
c.JupyterHub.bind_url = {self.url + '/'!r}
c.JupyterHub.hub_bind_url = 'http://127.0.0.1:{_free_port()}'
c.ConfigurableHTTPProxy.command = [{str(CHP)!r}]
c.ConfigurableHTTPProxy.api_url = 'http://127.0.0.1:{_free_port()}'
c.JupyterHub.db_url = 'sqlite:///{self.folder}/jupyterhub.sqlite'
c.JupyterHub.cookie_secret_file = '{self.folder}/cookie_secret'
c.JupyterHub.pid_file = '{self.folder}/hub.pid'
c.JupyterHub.authenticator_class = 'dummy'
c.DummyAuthenticator.password = {PASSWORD!r}
c.Authenticator.allowed_users = {set(self.students)!r}
c.JupyterHub.spawner_class = 'localprocess'
c.Spawner.cmd = [{str(VENV / 'bin' / 'jupyterhub-singleuser')!r}]
c.Spawner.default_url = '/lab'
c.Spawner.env_keep = ['PATH', 'LANG', 'LC_ALL'] + {keep!r}
c.Spawner.start_timeout = 180
c.Spawner.http_timeout = 180
c.JupyterHub.services = [{{'name': 'teacher', 'api_token': {self.api_token!r}}}]
c.JupyterHub.load_roles = [{{'name': 'teacher', 'services': ['teacher'],
    'scopes': ['admin:users', 'admin:servers', 'tokens', 'access:servers', 'list:users',
               'read:users']}}]
"""

    def _add_user(self, name: str) -> None:
        self._remove_user(name)
        home = self.folder / "home" / name
        home.parent.mkdir(exist_ok=True)
        home.parent.chmod(0o755)
        subprocess.run(["useradd", "--create-home", "--home-dir", str(home), "--shell", "/bin/bash",
                        "--comment", "mexone test student", name], check=True, capture_output=True)
        home.chmod(0o700)

    @staticmethod
    def _remove_user(name: str) -> None:
        try:
            uid = pwd.getpwnam(name).pw_uid
        except KeyError:
            return
        for pid in pids_of(uid):  # every process of a user this class created
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        subprocess.run(["userdel", "--force", name], capture_output=True)

    def api(self, method: str, path: str, body: dict | None = None, token: str | None = None):
        request = urllib.request.Request(
            f"{self.url}/hub/api{path}", method=method,
            data=None if body is None else json.dumps(body).encode(),
            headers={"Authorization": f"token {token or self.api_token}",
                     "Content-Type": "application/json"})
        with urllib.request.urlopen(request, timeout=60) as response:
            text = response.read()
        return json.loads(text) if text else None

    def spawn(self, name: str, timeout: float = 180.0) -> str:
        """Start `name`'s Jupyter server (as logging in does) and return a token of theirs."""
        try:
            self.api("POST", f"/users/{name}/server")
        except urllib.error.HTTPError as exc:
            if exc.code != 400:  # 400: already running
                raise
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            user = self.api("GET", f"/users/{name}")
            server = user.get("servers", {}).get("", {})
            if server.get("ready"):
                break
            time.sleep(0.5)
        else:
            raise TimeoutError(f"{name}'s server did not start:\n{self.log()[-3000:]}")
        return self.api("POST", f"/users/{name}/tokens", {"note": "test"})["token"]

    def stop_server(self, name: str, timeout: float = 60.0) -> None:
        """What the hub's idle culler does to an idle student: stop their server."""
        try:
            self.api("DELETE", f"/users/{name}/server")
        except urllib.error.HTTPError as exc:
            if exc.code != 400:
                raise
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if not self.api("GET", f"/users/{name}").get("servers"):
                return
            time.sleep(0.3)
        raise TimeoutError(f"{name}'s server did not stop")

    def stop(self) -> None:
        if self.hub is not None and self.hub.poll() is None:
            for name in self.students:  # the users' processes are killed below anyway
                with contextlib.suppress(Exception):
                    self.stop_server(name, timeout=20)
            os.killpg(self.hub.pid, signal.SIGTERM)
            try:
                self.hub.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(self.hub.pid, signal.SIGKILL)
                self.hub.wait()
        for name in self.students:
            self._remove_user(name)
        shutil.rmtree(self.folder, ignore_errors=True)


def _class_folder() -> Path:
    HOME.mkdir(mode=0o755, parents=True, exist_ok=True)
    folder = Path(tempfile.mkdtemp(prefix="class-", dir=HOME))
    (folder / "owner").write_text(_process_id(os.getpid()))
    return folder


def _process_id(pid: int) -> str:
    """A process named so that a later one reusing its pid is not mistaken for it."""
    try:
        return f"{pid} {Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[19]}"
    except (FileNotFoundError, ProcessLookupError):
        return ""


def _end_stale_classes() -> None:
    """The classes of this checkout whose test run ended without its teardown (a killed run):
    their hub's process group (the hub and its proxy), their students (users and processes)
    and folder. A class whose run is alive (another session of this checkout) is left alone."""
    for folder in HOME.glob("class-*"):
        with contextlib.suppress(OSError):
            owner = (folder / "owner").read_text()
            if owner and _process_id(int(owner.split()[0])) == owner:
                continue
        with contextlib.suppress(ValueError, OSError):
            pid = int((folder / "hub.pid").read_text())
            if str(folder) in Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace"):
                os.killpg(pid, signal.SIGKILL)
        with contextlib.suppress(OSError):
            for name in (folder / "students").read_text().split():
                Classroom._remove_user(name)
        shutil.rmtree(folder, ignore_errors=True)


def pids_of(uid: int) -> list[int]:
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if entry.stat().st_uid == uid:
                    out.append(int(entry.name))
            except FileNotFoundError:
                pass
    return out


@dataclass(frozen=True)
class Lab:
    """A student's running `mexone sim`, as root sees it in /proc."""

    pid: int
    port: int
    uid: int


def labs_of(name: str) -> list[Lab]:
    uid = pwd.getpwnam(name).pw_uid
    found = []
    for pid in pids_of(uid):
        try:
            argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        except (FileNotFoundError, ProcessLookupError):
            continue
        words = [a.decode(errors="replace") for a in argv]
        if "mexone" in words and "sim" in words and "--port" in words:
            found.append(Lab(pid, int(words[words.index("--port") + 1]), uid))
    return found


def as_user(name: str, code: str, timeout: float = 60.0) -> dict:
    """Run Python `code` as Unix user `name` (another student's process on this machine); it
    prints one JSON object."""
    account = pwd.getpwnam(name)
    out = subprocess.run([str(VENV / "bin" / "python"), "-c", code], user=account.pw_uid,
                         group=account.pw_gid, extra_groups=[], capture_output=True, text=True,
                         timeout=timeout, cwd="/tmp", env={"PATH": "/usr/bin:/bin", "HOME": "/tmp"})
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


if __name__ == "__main__":  # scripts/test.sh: the students' venv before the tests
    sys.path.insert(0, str(ROOT / "tests"))
    import wheelenv

    # the wheel scripts/test.sh builds meanwhile for the tests' venv, when there is one
    print(f"the students' venv (tests/hub): {students_venv(wheelenv.prebuilt_wheel())}")
