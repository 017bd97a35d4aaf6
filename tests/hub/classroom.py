"""A real class on this machine: JupyterHub from PyPI, its proxy (configurable-http-proxy from
npm), LocalProcessSpawner and one Unix user per student, each student's Jupyter server running
mexone's launcher entry (jupyter-server-proxy) from the .venv-hub scripts/test.sh builds with
Debian's Python (the students cannot enter /root, where the test's own Python lives).

Shared by tests/hub (two students in a browser) and benchmarks/hub_class.py (twenty)."""

from __future__ import annotations

import contextlib
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
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
VENV = ROOT / ".venv-hub"
CHP = Path(__file__).resolve().parent / "node_modules" / ".bin" / "configurable-http-proxy"
PASSWORD = "mexone-class"


def missing() -> str | None:
    """Why a class cannot run here, or None."""
    if os.geteuid() != 0:
        return "a class on this machine needs root (one Unix user per student)"
    if not (VENV / "bin" / "jupyterhub-singleuser").exists():
        return ".venv-hub is missing: bash scripts/test.sh builds it"
    if not CHP.exists():
        return "configurable-http-proxy is missing: npm install --prefix tests/hub"
    for folder in [ROOT, *ROOT.parents]:  # the students run .venv-hub and import this checkout
        if not folder.stat().st_mode & 0o001:
            return f"{folder} is closed to other users: the students cannot run .venv-hub there"
    return None


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class Classroom:
    """`students` Unix users (created here, deleted by stop()) and a hub serving them."""

    students: list[str]
    folder: Path = field(default_factory=lambda: Path(tempfile.mkdtemp(prefix="mexone-class-")))
    port: int = field(default_factory=_free_port)
    api_token: str = field(default_factory=lambda: secrets.token_hex(16))
    hub: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self, timeout: float = 120.0) -> Classroom:
        _end_stale_classes()
        self.folder.chmod(0o755)
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


def _end_stale_classes() -> None:
    """A class a killed test run left behind (its teardown never ran): its hub's process group
    (the hub and its proxy; the students' processes go with their users) and its folder."""
    for pid_file in Path(tempfile.gettempdir()).glob("mexone-class-*/hub.pid"):
        with contextlib.suppress(ValueError, OSError):
            pid = int(pid_file.read_text())
            if str(pid_file.parent) in Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace"):
                os.killpg(pid, signal.SIGKILL)
        shutil.rmtree(pid_file.parent, ignore_errors=True)


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
