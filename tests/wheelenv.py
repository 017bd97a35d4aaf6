"""The wheel a user gets from `pip install .`, installed into a fresh venv: built once per test
session (the `wheel` and `venv` fixtures in conftest.py) and shared by tests/test_wheel.py and
tests/test_docs_commands.py, which run the shipped commands and the documented ones from it.

Built ahead: `python3 tests/wheelenv.py DIR` builds both into DIR while scripts/test.sh's set-up
(ruff, mypy) keeps one core busy, and MEXONE_TEST_PREBUILT=DIR hands them to the test session.
One session takes them (a session changes its venv: docs/teaching.md installs Ray), and only
if they were built from the files the checkout holds now (FOR: their hash); else it builds its
own.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TIMES: dict[str, float] = {}  # what building and installing cost, for the report
PREBUILT_ENV = "MEXONE_TEST_PREBUILT"  # a folder `python3 tests/wheelenv.py DIR` built
FOR, TAKEN = "for.sha256", "taken.sha256"  # the files' hash: ready, then taken by a session
WHEEL, FAILED = "wheel.txt", "failed.txt"  # the wheel's path once built; why the build failed
PID = "pid"  # the build's process (scripts/test.sh writes it): gone without a wheel, it failed
_TAKEN: dict[Path, Path] = {}  # a prebuilt wheel -> its venv, for make_venv
# what tests/test_notebooks.py installs (as docs/notebooks.md tells users), installed with the
# wheel: one resolve, its byte-code compiled with the rest, and ahead (in scripts/test.sh's
# set-up) rather than in the serial phase
EXTRAS = "[notebook]"


# a clean environment: with this checkout's src/ on PYTHONPATH, pip sees its mexone.egg-info
# (left by an editable install) as mexone "already installed" and skips the wheel
CLEAN_ENV = {k: v for k, v in os.environ.items()
             if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "ROS_PACKAGE_PATH")}


def git(*args: str) -> str:
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        import pytest  # not at the top: scripts/test.sh runs this file before pytest is installed

        pytest.skip("the wheel tests compare with git: run them in a git checkout")
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True,
                          check=True).stdout


def build_wheel(tmp_path_factory, project: str = "", name: str = "mexone") -> Path:
    """The wheel built from a copy of the files git knows (tracked, or new and not ignored): a
    stale build/ or egg-info in the checkout cannot leak into it. `project`: a folder of the
    checkout holding another distribution (teacher: the teacher's pack, `name` mexone_teacher).
    mexone's own is the prebuilt one (MEXONE_TEST_PREBUILT) when that was built from these files."""
    if not project:
        taken = take_prebuilt()
        if taken:
            return taken
    return wheel_of_checkout(tmp_path_factory.mktemp("tree"), tmp_path_factory.mktemp("dist"),
                             project, name)


def checkout_files(project: str = "") -> list[str]:
    """The checkout's files git knows (tracked, or new and not ignored) under `project`."""
    return [file for file in git("ls-files", "-z", "--cached", "--others", "--exclude-standard",
                                 "--", project or ".").split("\0")
            if file and (ROOT / file).is_file()]


def files_hash(root: Path, files: list[str]) -> str:
    """What a wheel is built from: each file's path, executable bit and bytes."""
    digest = hashlib.sha256()
    for file in sorted(files):
        path = root / file
        digest.update(f"{file}\0{os.access(path, os.X_OK):d}\0{path.stat().st_size}\0".encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def wheel_of_checkout(tree: Path, out: Path, project: str = "", name: str = "mexone") -> Path:
    """build_wheel's work, in the folders given: the checkout's files git knows (under `project`)
    copied to `tree`, the wheel built into `out` (also tests/hub's students' venv, outside
    pytest)."""
    for file in checkout_files(project):
        (tree / file).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / file, tree / file)
    start = time.monotonic()
    built = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q",
                            "--disable-pip-version-check", "-w", str(out), str(tree / project)],
                           capture_output=True, text=True, timeout=600, env=CLEAN_ENV)
    TIMES[f"build {name} wheel"] = time.monotonic() - start
    assert built.returncode == 0, built.stderr[-3000:]
    (path,) = out.glob(f"{name}-*.whl")
    return path


@dataclass(frozen=True)
class Venv:
    bin: Path
    work: Path  # a folder outside the source tree, where the commands run
    env: dict

    def run(self, *args: str, cwd: Path | None = None, timeout: float = 600) -> subprocess.CompletedProcess:
        """A command (the venv's own if it has one by that name); failing is an AssertionError
        naming the command and the end of its stderr."""
        exe = str(self.bin / args[0]) if (self.bin / args[0]).exists() else args[0]
        out = subprocess.run([exe, *args[1:]], cwd=cwd or self.work, env=self.env,
                             capture_output=True, text=True, timeout=timeout)
        said = (out.stderr + out.stdout)[-3000:]  # `run --json` reports a routine's error on stdout
        assert out.returncode == 0, f"{' '.join(args)}: exit {out.returncode}\n{said}"
        return out


def make_venv(wheel: Path, tmp_path_factory) -> Venv:
    """A fresh venv (no system site-packages: those hold the editable mexone) with the wheel:
    the prebuilt one if build_wheel took it."""
    root = _TAKEN.get(wheel)
    if root is None:
        root = tmp_path_factory.mktemp("venv")
        venv_with(wheel, root)
    work = tmp_path_factory.mktemp("work")
    assert not work.resolve().is_relative_to(ROOT)
    return Venv(root / "bin", work, _venv_env(root))


def _venv_env(root: Path) -> dict:
    return dict(CLEAN_ENV, PATH=f"{root / 'bin'}{os.pathsep}{CLEAN_ENV.get('PATH', '/usr/bin:/bin')}",
                VIRTUAL_ENV=str(root))


def venv_with(wheel: Path, root: Path) -> None:
    """make_venv's work: the venv at `root` (a new folder) with the wheel (and EXTRAS) and its
    byte-code."""
    env = _venv_env(root)
    start = time.monotonic()
    subprocess.run([sys.executable, "-m", "venv", str(root)], check=True, timeout=300, env=env)
    root.chmod(0o755)  # as a user's venv (pytest's folders are 0700): a root grader's jails,
    # of a uid of their own, read it (sandbox.spawn refuses a folder they cannot enter)
    TIMES["create venv"] = time.monotonic() - start
    start = time.monotonic()
    python = str(root / "bin" / "python")
    pip = subprocess.run([python, "-m", "pip", "install", "-q", "--no-compile",
                          "--disable-pip-version-check", f"{wheel}{EXTRAS}"],
                         capture_output=True, text=True, timeout=1200, env=env)
    TIMES["pip install wheel + deps"] = time.monotonic() - start
    assert pip.returncode == 0, pip.stderr[-3000:]
    # the byte-code pip would have compiled one file after another, on every core: a user's
    # install has it, and compiling scipy on first import is no part of a routine's first step
    start = time.monotonic()
    subprocess.run([python, "-m", "compileall", "-q", "-j", "0", str(root / "lib")], check=True,
                   capture_output=True, timeout=1200, env=env)
    TIMES["compile byte-code"] = time.monotonic() - start


def prebuild(folder: Path) -> None:
    """The wheel and its venv in `folder` (new or empty), ready for one session to take: FOR
    written last, holding the hash of the files the wheel was built from."""
    folder.mkdir(parents=True, exist_ok=True)
    tree, dist = folder / "tree", folder / "dist"
    tree.mkdir()
    dist.mkdir()
    try:
        wheel = wheel_of_checkout(tree, dist)
    except BaseException as exc:
        _publish(folder / FAILED, f"{type(exc).__name__}: {exc}")
        raise
    _publish(folder / WHEEL, str(wheel))  # tests/hub/classroom.py's, while the venv is built
    venv_with(wheel, folder / "venv")
    (folder / "times.json").write_text(json.dumps(TIMES))
    _publish(folder / FOR, files_hash(tree, checkout_files()))  # the copies, as they were built


def _publish(path: Path, text: str) -> None:
    """`text` in `path`, whole or not at all for a reader that waits on it."""
    path.with_name(f"{path.name}.part").write_text(text)
    path.with_name(f"{path.name}.part").rename(path)


def prebuilt_wheel(timeout: float = 600.0) -> Path | None:
    """The wheel MEXONE_TEST_PREBUILT's build makes, once built (waiting up to `timeout` s, the
    build's own limit), or None: none asked for, or its build failed."""
    value = os.environ.get(PREBUILT_ENV)
    if not value:
        return None
    folder, end = Path(value), time.monotonic() + timeout
    while time.monotonic() < end and not (folder / FAILED).exists():
        if (folder / WHEEL).exists():
            return Path((folder / WHEEL).read_text())
        if not _building(folder):
            return Path((folder / WHEEL).read_text()) if (folder / WHEEL).exists() else None
        time.sleep(0.1)  # a poll on the build's file, not a wait for a guessed time
    return None


def _building(folder: Path) -> bool:
    """Whether the build's process still runs (no PID file: assumed so, the timeout bounds it)."""
    pid_file = folder / PID
    if not pid_file.exists():
        return True
    try:
        stat = Path(f"/proc/{int(pid_file.read_text())}/stat").read_text()
    except FileNotFoundError:
        return False  # ended (and reaped)
    except (OSError, ValueError):
        return True
    return stat.rsplit(")", 1)[1].split()[0] != "Z"  # a zombie has ended too


def take_prebuilt() -> Path | None:
    """The prebuilt wheel (its venv kept for make_venv) if MEXONE_TEST_PREBUILT names a folder
    built from the files the checkout holds now and no session took it yet; else None."""
    folder = Path(os.environ.get(PREBUILT_ENV) or "/nonexistent")
    try:
        built_from = (folder / FOR).read_text()
    except OSError:
        return None  # none asked for, not built, or failed (this session builds its own)
    if built_from != files_hash(ROOT, checkout_files()):
        print(f"\n{folder}: built from other files than the checkout holds now; building again")
        return None
    try:
        (folder / FOR).rename(folder / TAKEN)  # atomic: one session takes it
    except FileNotFoundError:
        return None
    (wheel,) = (folder / "dist").glob("mexone-*.whl")
    _TAKEN[wheel] = folder / "venv"
    TIMES.update({f"{k} (ahead)": v for k, v in json.loads((folder / "times.json").read_text()).items()})
    return wheel


if __name__ == "__main__":
    prebuild(Path(sys.argv[1]))
