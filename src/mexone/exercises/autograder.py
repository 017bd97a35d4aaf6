"""Gradescope's autograder for an exercise (`mexone exercise autograder NAME -o autograder.zip`):
the zip Gradescope documents (gradescope-autograders.readthedocs.io, "Autograder
Specifications"): `setup.sh`, run once as root on Gradescope's Ubuntu image, makes a venv with
mexone's wheel (carried in the zip: mexone is on no package index) and its dependencies from
PyPI; `run_autograder`, run for each submission, grades /autograder/submission through
`mexone exercise grade`'s own grading (grading.grade: the student's part in isolated
processes) and writes /autograder/results/results.json, one test per check.

The teacher's $MEXONE_EXERCISE_SECRET travels in the zip (students never see the zip): the run
reads it into the grading process's memory and deletes the file before any student code runs;
the student's processes never get it (isolate.py leaves it out of their environment), and the
grading process is made non-dumpable (its /proc memory and environment closed to other
non-root processes). A teacher's own exercise folder travels in the zip without its solution/.
"""

from __future__ import annotations

import base64
import contextlib
import ctypes
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

from mexone.errors import InputError, MexoneError
from mexone.exercises.exercise import COURSE, Exercise, find_exercise, load_exercise
from mexone.exercises.isolate import SECRET_ENV
from mexone.files import replacing

__all__ = ["Bundle", "write_bundle", "build_wheel", "results_json", "run"]

ROOT_ENV = "MEXONE_AUTOGRADER_ROOT"  # where Gradescope's /autograder is (a test's own folder)
CONFIG = "mexone-autograder.json"  # in source/: which exercise, which file, which wheel
SECRET_FILE = "secret"  # in source/: the teacher's secret, deleted by the first run
EXERCISE_DIR = "exercise"  # in source/: a teacher's exercise folder (not a shipped one)
HIDDEN = ("after_due_date", "hidden", "after_published")  # Gradescope's non-visible kinds
_SKIP = {"__pycache__", "solution", ".ipynb_checkpoints"}  # never in the zip's exercise/

SETUP_SH = """\
#!/usr/bin/env bash
# Gradescope runs this once, as root, on its Ubuntu image: a Python >= 3.11 (the image's, else
# Ubuntu's or the deadsnakes PPA's python3.11), a venv with mexone's wheel and its dependencies
# from PyPI. Written by `mexone exercise autograder` (mexone {version}) for {exercise}.
set -euo pipefail
ROOT="${{{root_env}:-/autograder}}"
VENV="$ROOT/mexone-venv"
python_ok() {{ "$1" -c 'import sys, ensurepip, venv; sys.exit(sys.version_info < (3, 11))' \\
    >/dev/null 2>&1; }}
find_python() {{
    for py in python3 python3.13 python3.12 python3.11; do
        if command -v "$py" >/dev/null && python_ok "$py"; then command -v "$py"; return 0; fi
    done
    return 1
}}
if [ ! -x "$VENV/bin/python" ]; then  # (a venv there already: setup.sh run again)
    if ! PY="$(find_python)"; then
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -q
        if python3 -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
            apt-get install -y -q python3-venv python3-pip
        elif ! apt-get install -y -q python3.11 python3.11-venv; then
            apt-get install -y -q software-properties-common
            add-apt-repository -y ppa:deadsnakes/ppa
            apt-get update -q
            apt-get install -y -q python3.11 python3.11-venv
        fi
        PY="$(find_python)" || {{ echo "setup.sh: no Python >= 3.11 with venv" >&2; exit 1; }}
    fi
    "$PY" -m venv "$VENV"
fi
PIP=("$VENV/bin/python" -m pip install -q --disable-pip-version-check)
"${{PIP[@]}}" --force-reinstall --no-deps "$ROOT/source/{wheel}"  # this zip's mexone, always
"${{PIP[@]}}" "$ROOT/source/{wheel}"  # and what it needs
"$VENV/bin/python" -c "import mexone.exercises.autograder"
"""

RUN_AUTOGRADER = """\
#!/usr/bin/env bash
# Gradescope runs this for each submission: grades /autograder/submission as
# `mexone exercise grade` does and writes /autograder/results/results.json.
ROOT="${{{root_env}:-/autograder}}"
exec "$ROOT/mexone-venv/bin/python" -m mexone.exercises.autograder "$ROOT"
"""


@dataclass(frozen=True)
class Bundle:
    """What `write_bundle` wrote: the zip, the wheel it carries, whether it holds a secret."""

    path: Path
    wheel: str
    secret: bool
    files: tuple[str, ...]


def _checkout() -> Path | None:
    """The source tree mexone runs from (pyproject.toml beside src/mexone), or None when it
    is installed from a wheel."""
    import mexone

    root = Path(mexone.__file__).resolve().parents[2]
    if (root / "pyproject.toml").is_file() and (root / "src" / "mexone").is_dir():
        return root
    return None


def build_wheel(folder: Path) -> Path:
    """mexone's wheel, in `folder`: `pip wheel --no-deps` of the checkout mexone runs from
    (a clean copy: no build/, egg-info or byte-code of the checkout's rides along), or the
    installed distribution's own files packed again (mexone installed from a wheel)."""
    root = _checkout()
    if root is None:
        return _repack(folder)
    junk = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info", "build", "dist")
    with tempfile.TemporaryDirectory(prefix="mexone-wheel-") as tmp:
        tree = Path(tmp) / "tree"
        tree.mkdir()
        for name in ("pyproject.toml", "MANIFEST.in", "README.md", "LICENSE", "setup.py"):
            if (root / name).is_file():
                shutil.copy2(root / name, tree / name)
        shutil.copytree(root / "src", tree / "src", ignore=junk)
        env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        # setuptools at hand: build with it (no download of a build environment)
        offline = ["--no-build-isolation"] if _importable("setuptools", "wheel") else []
        built = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q",
                                *offline, "--disable-pip-version-check", "-w", str(folder),
                                str(tree)],
                               capture_output=True, text=True, env=env)
    if built.returncode != 0:
        tail = (built.stderr.strip().splitlines() or ["(no output)"])[-1]
        raise MexoneError(f"pip wheel of {root} failed: {tail}",
                          hint="build it yourself (pip wheel --no-deps .) and pass --wheel FILE")
    found = sorted(folder.glob("mexone-*.whl"))
    if not found:
        raise MexoneError(f"pip wheel of {root} wrote no mexone wheel",
                          hint="pass --wheel FILE")
    return found[0]


def _importable(*names: str) -> bool:
    import importlib.util

    return all(importlib.util.find_spec(name) is not None for name in names)


def _record_hash(data: bytes) -> str:
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"sha256={digest}"


def _repack(folder: Path) -> Path:
    """The installed mexone as a wheel again: its package files and dist-info as RECORD lists
    them (not the scripts pip wrote, nor pip's own INSTALLER/REQUESTED/direct_url.json)."""
    dist = metadata.distribution("mexone")
    info = next((Path(str(f)).parts[0] for f in dist.files or ()
                 if Path(str(f)).parts[0].endswith(".dist-info")), None)
    try:
        editable = json.loads(dist.read_text("direct_url.json") or "{}").get(
            "dir_info", {}).get("editable", False)
    except ValueError:
        editable = False
    if info is None or editable:
        raise MexoneError("cannot find mexone's installed files to pack",
                          hint="build the wheel in your clone (pip wheel --no-deps .) and pass "
                               "--wheel FILE")
    wheel_meta = dist.read_text("WHEEL") or ""
    tag = next((line.split(":", 1)[1].strip() for line in wheel_meta.splitlines()
                if line.startswith("Tag:")), "py3-none-any")
    path = folder / f"mexone-{dist.version}-{tag}.whl"
    pip_own = {"RECORD", "INSTALLER", "REQUESTED", "direct_url.json"}
    record = []
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for f in sorted(dist.files or (), key=str):
            parts = Path(str(f)).parts
            if parts[0] not in ("mexone", info) or "__pycache__" in parts \
                    or (parts[0] == info and parts[-1] in pip_own):
                continue
            source = Path(dist.locate_file(f))
            if not source.is_file():
                continue
            data = source.read_bytes()
            entry = zipfile.ZipInfo("/".join(parts), date_time=(1980, 1, 1, 0, 0, 0))
            entry.external_attr = (source.stat().st_mode & 0o777 | 0o100000) << 16
            entry.compress_type = zipfile.ZIP_DEFLATED
            zf.writestr(entry, data)
            record.append(f"{'/'.join(parts)},{_record_hash(data)},{len(data)}")
        record.append(f"{info}/RECORD,,")
        zf.writestr(f"{info}/RECORD", "\n".join(record) + "\n")
    return path


def _exercise_files(ex: Exercise) -> dict[str, Path]:
    """A teacher's exercise folder for the zip (None of a shipped one: the wheel has it)."""
    files = {}
    for path in sorted(ex.folder.rglob("*")):
        rel = path.relative_to(ex.folder)
        if path.is_file() and not _SKIP.intersection(rel.parts) and path.suffix != ".pyc":
            files[f"{EXERCISE_DIR}/{rel.as_posix()}"] = path
    return files


def _add(zf: zipfile.ZipFile, name: str, data: bytes, mode: int) -> None:
    entry = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
    entry.external_attr = (mode | 0o100000) << 16
    entry.compress_type = zipfile.ZIP_DEFLATED
    zf.writestr(entry, data)


def write_bundle(name: str, out: Path, force: bool = False, wheel: Path | None = None,
                 secret: str | None = None) -> Bundle:
    """Write the autograder zip for exercise `name` (a shipped one or a folder) to `out`,
    carrying `wheel` (default: built from the mexone that runs this) and `secret` (the
    teacher's $MEXONE_EXERCISE_SECRET, which grading needs)."""
    ex = find_exercise(name)
    shipped = ex.folder.parent == COURSE
    if wheel is not None and not (wheel.is_file() and wheel.name.startswith("mexone-")
                                  and wheel.suffix == ".whl"):
        raise InputError("is not mexone's wheel", file=wheel,
                         hint="pip wheel --no-deps . in your clone writes mexone-*.whl")
    with tempfile.TemporaryDirectory(prefix="mexone-autograder-") as tmp, \
            replacing(out, force) as temporary:  # refused before the wheel is built
        wheel_path = wheel if wheel is not None else build_wheel(Path(tmp))
        config = {"exercise": ex.name if shipped else EXERCISE_DIR, "file": ex.file,
                  "mexone": metadata.version("mexone"), "wheel": wheel_path.name}
        words = {"root_env": ROOT_ENV, "version": config["mexone"], "exercise": ex.name,
                 "wheel": wheel_path.name}
        names = []
        with zipfile.ZipFile(temporary, "w", zipfile.ZIP_DEFLATED) as zf:
            entries = [("setup.sh", SETUP_SH.format(**words).encode(), 0o755),
                       ("run_autograder", RUN_AUTOGRADER.format(**words).encode(), 0o755),
                       (CONFIG, (json.dumps(config, indent=2) + "\n").encode(), 0o644),
                       (wheel_path.name, wheel_path.read_bytes(), 0o644)]
            if secret:
                entries.append((SECRET_FILE, secret.encode(), 0o600))
            if not shipped:
                entries += [(n, p.read_bytes(), 0o644)
                            for n, p in _exercise_files(ex).items()]
            for entry_name, data, mode in entries:
                _add(zf, entry_name, data, mode)
                names.append(entry_name)
        temporary.chmod(0o600 if secret else 0o644)  # the zip holds the teacher's secret
    return Bundle(out, wheel_path.name, bool(secret), tuple(names))


def results_json(result, hidden: str = "after_due_date") -> dict:
    """Gradescope's results.json of a graded Result (grading.gradescope_json), with each check
    the grader marked not visible shown as `hidden` says (default: after the due date)."""
    from mexone.exercises.grading import gradescope_json

    if hidden not in HIDDEN:
        raise InputError(f"hidden visibility '{hidden}'", hint="one of: " + ", ".join(HIDDEN))
    data = gradescope_json(result)
    for test in data["tests"]:
        if test["visibility"] != "visible":
            test["visibility"] = hidden
    return data


def _not_dumpable() -> None:
    """This process's memory and /proc files closed to other non-root processes (prctl
    PR_SET_DUMPABLE 0): it holds the secret."""
    with contextlib.suppress(OSError, AttributeError):  # not Linux: nothing to close
        ctypes.CDLL(None, use_errno=True).prctl(4, 0, 0, 0, 0)


def _take_secret(source: Path) -> None:
    """The teacher's secret into this process's memory (os.environ: grading reads it there; it
    is not in /proc/PID/environ, which shows the environment the process started with), its
    file deleted before any student code runs."""
    path = source / SECRET_FILE
    if path.is_file():
        os.environ[SECRET_ENV] = path.read_text()
        path.unlink()


def _submission(folder: Path, file: str) -> Path:
    """The student's file: submission/FILE, else the one FILE anywhere under it (Gradescope
    keeps the folders a student uploads)."""
    direct = folder / file
    if direct.is_file():
        return direct
    found = sorted(p for p in folder.rglob(file) if p.is_file()) if folder.is_dir() else []
    return found[0] if len(found) == 1 else direct


def run(root: Path) -> int:
    """Grade Gradescope's submission under `root` (/autograder) into root/results/results.json
    (written even when grading cannot start, saying why); 0 when graded."""
    from mexone.exercises.grading import grade, not_handed_in

    _not_dumpable()
    source, results = root / "source", root / "results"
    results.mkdir(parents=True, exist_ok=True)
    try:
        _take_secret(source)
        try:
            config = json.loads((source / CONFIG).read_text())
            exercise, file = config["exercise"], config["file"]
        except (OSError, ValueError, KeyError) as exc:
            raise InputError(f"unreadable: {exc}", file=source / CONFIG,
                             hint="rebuild the zip with mexone exercise autograder") from None
        ex = load_exercise(source / exercise) if exercise == EXERCISE_DIR \
            else find_exercise(exercise)
        path = _submission(root / "submission", file)
        result = grade(ex, path) if path.is_file() else not_handed_in(ex, path)
        data = results_json(result)
        code = 0
    except MexoneError as exc:  # the teacher's zip, not the student, is at fault
        data = {"score": 0.0, "output": f"The autograder could not grade this submission "
                f"(tell your teacher): {exc.one_line()}", "visibility": "visible",
                "tests": []}
        code = 2
    (results / "results.json").write_text(json.dumps(data, indent=2) + "\n")
    print(data.get("output", ""))
    return code


if __name__ == "__main__":
    sys.exit(run(Path(sys.argv[1] if len(sys.argv) > 1 else
                      os.environ.get(ROOT_ENV, "/autograder"))))
