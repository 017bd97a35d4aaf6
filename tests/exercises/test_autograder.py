"""Gradescope's autograder zip (`mexone exercise autograder`), run as Gradescope runs it: the zip
unpacked into a folder laid out as /autograder (source/, submission/, results/), its setup.sh
installing the zip's mexone wheel into the venv there, run_autograder grading a submission.
results.json must hold Gradescope's documented fields only, score as `mexone exercise grade`
does with the same secret, and a submission that hunts for the secret must find none of it.

The venv: a hard-linked copy of the session's fresh wheel venv (tests/wheelenv.py, shared with
the docs and wheel tests), so setup.sh's own install (the zip's wheel forced in, then its
dependencies) runs without downloading the dependencies a second time. The pieces that need no
venv are in test_autograder_pieces.py (beside other files: tests/phases.py)."""

from __future__ import annotations

import json
import shutil
import subprocess
import tempfile
import zipfile
from pathlib import Path

import jsonschema
import pytest

from mexone.exercises import find_exercise
from mexone.exercises.autograder import ROOT_ENV

SCHEMA = json.loads((Path(__file__).parent.parent / "data" / "exercises" /
                     "gradescope_results.schema.json").read_text())
EXERCISE = "identify_damping"  # its student's part is Python; the truth comes from the secret
SECRET = "teacher-3f9c1e-not-for-students"
SOLUTION = find_exercise(EXERCISE).solution

# off by 15 % of the truth: partial marks (full within 10 %, none beyond 30 %)
HONEST = SOLUTION.read_text().replace("return float(result.fit.values[0])",
                                      "return 1.15 * float(result.fit.values[0])")
assert SOLUTION.read_text() != HONEST

# looks everywhere a student's code could: its environment, every file of the autograder's
# folder, every process's environment and command line; says where it found the secret (the
# test's oracle: a real cheater does not know the string) and how many places it read
CHEATER = '''
import os
from pathlib import Path

def estimate(bag):
    secret, root = {secret!r}, Path({root!r})
    seen, hits = [], []
    places = [("env", "\\n".join(f"{{k}}={{v}}" for k, v in os.environ.items()))]
    for path in sorted(root.rglob("*")):
        if "mexone-venv" not in path.parts and "submission" not in path.parts \
                and path.is_file():  # (its own text holds the test's oracle)
            try:
                places.append((str(path.relative_to(root)), path.read_bytes().decode("latin-1")))
            except OSError:
                pass
    for proc in Path("/proc").iterdir():
        for name in ("environ", "cmdline"):
            try:
                places.append((f"/proc/{{proc.name}}/{{name}}",
                               (proc / name).read_bytes().decode("latin-1")))
            except OSError:
                pass
    for where, text in places:
        seen.append(where)
        if secret in text:
            hits.append(where)
    raise RuntimeError(f"found the secret in {{hits}}; read {{len(seen)}} places: "
                       + " ".join(w for w in seen if not w.startswith("/proc")))
'''


@pytest.fixture(scope="module")
def bundle(venv, tmp_path_factory) -> Path:
    """The zip, as a teacher with mexone installed from the wheel writes it (the wheel the
    zip carries: the installed mexone packed again)."""
    out = tmp_path_factory.mktemp("zip") / "autograder.zip"
    made = subprocess.run([str(venv.bin / "mexone"), "exercise", "autograder", EXERCISE, "-o",
                           str(out)], env=dict(venv.env, MEXONE_EXERCISE_SECRET=SECRET),
                          cwd=venv.work, capture_output=True, text=True, timeout=300)
    assert made.returncode == 0, made.stderr[-2000:]
    assert "your secret" in made.stdout
    return out


def _layout(bundle: Path, venv_copy: Path, folder: Path) -> Path:
    """Gradescope's /autograder: source/ the unpacked zip, submission/, results/."""
    for name in ("source", "submission", "results"):
        (folder / name).mkdir(parents=True)
    with zipfile.ZipFile(bundle) as zf:
        zf.extractall(folder / "source")
    for info in zipfile.ZipFile(bundle).infolist():  # extractall drops the modes
        (folder / "source" / info.filename).chmod(info.external_attr >> 16 & 0o777)
    (folder / "mexone-venv").symlink_to(venv_copy)
    return folder


@pytest.fixture(scope="module")
def autograder(bundle, venv, tmp_path_factory, request):
    """A function: grade a submission's text through setup.sh's venv and run_autograder in a
    fresh /autograder layout; (results.json, run's output). setup.sh runs once."""
    # as on Gradescope (/autograder), the venv and the layouts in a folder every user can
    # enter: a root grader's jails run as a uid of their own, and pytest's folders are 0700
    shared = Path(tempfile.mkdtemp(prefix="mexone-gs-", dir="/var/tmp"))
    shared.chmod(0o755)
    request.addfinalizer(lambda: shutil.rmtree(shared, ignore_errors=True))
    copy = shared / "mexone-venv"
    root = Path(venv.bin).parent
    try:  # hard links: instant, and pip replaces files (never writes into them)
        subprocess.run(["cp", "-al", str(root), str(copy)], check=True, capture_output=True)
    except (subprocess.CalledProcessError, FileNotFoundError):
        shutil.copytree(root, copy, symlinks=True)
    first = _layout(bundle, copy, Path(tempfile.mkdtemp(dir=shared)))
    env = dict(venv.env, **{ROOT_ENV: str(first)})
    setup = subprocess.run(["bash", str(first / "source" / "setup.sh")], env=env,
                           capture_output=True, text=True, timeout=600)
    assert setup.returncode == 0, setup.stderr[-3000:]

    def grade(text: str, env_extra: dict | None = None) -> tuple[dict, str]:
        folder = _layout(bundle, copy, Path(tempfile.mkdtemp(dir=shared)))
        (folder / "submission" / "identify_damping.py").write_text(
            text.replace("ROOT", str(folder)))
        run_env = dict(env, **{ROOT_ENV: str(folder)}, **(env_extra or {}))
        run = subprocess.run([str(folder / "source" / "run_autograder")], env=run_env,
                             capture_output=True, text=True, timeout=600)
        assert run.returncode == 0, (run.stdout + run.stderr)[-3000:]
        assert not (folder / "source" / "secret").exists()  # gone before the student ran
        return json.loads((folder / "results" / "results.json").read_text()), run.stdout

    return grade


def test_zip_is_gradescopes_layout(bundle):
    with zipfile.ZipFile(bundle) as zf:
        modes = {i.filename: i.external_attr >> 16 & 0o777 for i in zf.infolist()}
        config = json.loads(zf.read("mexone-autograder.json"))
        assert zf.read("secret").decode() == SECRET
        with zf.open(config["wheel"]) as wheel_file, zipfile.ZipFile(wheel_file) as wheel:
            names = set(wheel.namelist())
    assert modes["setup.sh"] & 0o111 and modes["run_autograder"] & 0o111
    assert modes["secret"] == 0o600
    assert config["exercise"] == EXERCISE and config["file"] == "identify_damping.py"
    # the packed-again wheel: the package, its data and its entry points, nothing of pip's
    assert "mexone/exercises/autograder.py" in names
    assert f"mexone/exercises/course/{EXERCISE}/grader.py" in names
    info = next(n.split("/")[0] for n in names if n.endswith(".dist-info/METADATA"))
    assert {f"{info}/entry_points.txt", f"{info}/RECORD", f"{info}/WHEEL"} <= names
    assert not {f"{info}/INSTALLER", f"{info}/direct_url.json"} & names


def test_autograder_scores_as_grade_does_and_keeps_the_secret(autograder, venv, tmp_path):
    """The acceptance: the same score and checks as `mexone exercise grade` with the teacher's
    secret (the truth is drawn from it: a zip that lost it would state another truth),
    results.json valid against Gradescope's schema; a submission that hunts for the secret
    finds nothing."""
    submission = tmp_path / "identify_damping.py"
    submission.write_text(HONEST)
    env = dict(venv.env, MEXONE_EXERCISE_SECRET=SECRET)
    reference = subprocess.Popen(  # meanwhile: the teacher's own grading, the same secret
        [str(venv.bin / "mexone"), "exercise", "grade", EXERCISE, str(submission), "--json",
         str(tmp_path / "grade.json")], env=env, cwd=tmp_path, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True)
    results, _ = autograder(HONEST)
    _, err = reference.communicate(timeout=600)
    assert reference.returncode == 0, err[-2000:]
    expected = json.loads((tmp_path / "grade.json").read_text())

    jsonschema.validate(results, SCHEMA)
    assert 0 < results["score"] < 10, results  # partial marks: a score that could differ
    assert results["score"] == expected["score"]
    assert sum(t["score"] for t in results["tests"]) == pytest.approx(results["score"], abs=1e-3)
    assert [(t["name"], t["score"], t["max_score"], t["output"], t["visibility"])
            for t in results["tests"]] == \
        [(t["name"], t["score"], t["max_score"], t["output"], t["visibility"])
         for t in expected["tests"]]

    cheated, _ = autograder(CHEATER.format(secret=SECRET, root="ROOT"))
    jsonschema.validate(cheated, SCHEMA)
    (test,) = cheated["tests"]
    assert cheated["score"] == 0
    assert "found the secret in []" in test["output"], test["output"]
    assert "read " in test["output"] and " env" in test["output"]  # it ran, and looked
    assert "source/" not in test["output"]  # its jail shows none of the autograder's folder
    assert SECRET not in json.dumps(cheated)
