"""Gradescope's autograder zip (`mexone exercise autograder`), run as Gradescope runs it: the zip
unpacked into a folder laid out as /autograder (source/, submission/, results/), its setup.sh
installing the zip's mexone wheel into the venv there, run_autograder grading a submission.
results.json must hold Gradescope's documented fields only, score as `mexone exercise grade`
does with the same secret, and a submission that hunts for the secret must find none of it.

The venv: a hard-linked copy of the session's fresh wheel venv (tests/wheelenv.py, shared with
the docs and wheel tests), so setup.sh's own install (the zip's wheel forced in, then its
dependencies) runs without downloading the dependencies a second time."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
import zipfile
from pathlib import Path

import jsonschema
import pytest

from helpers import run_cli
from mexone.exercises import Check, GradeContext, Result, find_exercise
from mexone.exercises.autograder import ROOT_ENV, build_wheel, results_json

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


def test_the_truth_depends_on_the_secret(monkeypatch):
    """What makes the comparison above tell: with another secret, the same seed draws another
    true damping (and so another output and score)."""
    ex = find_exercise(EXERCISE)
    grader = ex.grader()
    truths = []
    for secret in (SECRET, SECRET + "-another"):
        monkeypatch.setenv("MEXONE_EXERCISE_SECRET", secret)
        truths.append(grader.variant(GradeContext(ex, SOLUTION, ex.seeds[0]).rng))
    assert truths[0] != pytest.approx(truths[1], rel=1e-3)


def test_results_json_shows_hidden_checks_after_the_due_date():
    ex = find_exercise(EXERCISE)
    result = Result(ex, Path("x.py"), 5.0, [(Check("shown", 1.0), 5.0, 5.0),
                                            (Check("secret", 0.0, visibility="hidden"), 0.0, 5.0)])
    data = results_json(result)
    jsonschema.validate(data, SCHEMA)
    assert [t["visibility"] for t in data["tests"]] == ["visible", "after_due_date"]
    assert [t["visibility"] for t in results_json(result, "hidden")["tests"]] == \
        ["visible", "hidden"]


def test_refusals_are_one_line(tmp_path):
    out = tmp_path / "autograder.zip"
    code, _, err = run_cli(["exercise", "autograder", EXERCISE, "-o", out],
                           env={"MEXONE_EXERCISE_SECRET": ""})
    assert code == 2 and "MEXONE_EXERCISE_SECRET is not set" in err
    assert len(err.strip().splitlines()) == 1 and not out.exists()
    out.write_text("the teacher's")
    wheel = tmp_path / "mexone-0.1.0-py3-none-any.whl"
    wheel.write_bytes(b"PK")
    code, _, err = run_cli(["exercise", "autograder", EXERCISE, "-o", out, "--wheel", wheel],
                           env={"MEXONE_EXERCISE_SECRET": SECRET})
    assert code != 0 and "exists" in err and "--force" in err
    assert len(err.strip().splitlines()) == 1 and out.read_text() == "the teacher's"
    code, _, err = run_cli(["exercise", "autograder", EXERCISE, "-o", tmp_path / "b.zip",
                            "--wheel", tmp_path / "other.whl"], env={"MEXONE_EXERCISE_SECRET": SECRET})
    assert code == 2 and "mexone's wheel" in err and not (tmp_path / "b.zip").exists()


def test_a_teachers_exercise_travels_without_its_solution(tmp_path):
    assert run_cli(["exercise", "new", "my_arms", tmp_path / "my_arms"])[0] == 0
    wheel = tmp_path / "mexone-0.1.0-py3-none-any.whl"
    wheel.write_bytes(b"PK")
    out = tmp_path / "autograder.zip"
    code, said, err = run_cli(["exercise", "autograder", tmp_path / "my_arms", "-o", out,
                               "--wheel", wheel], env={"MEXONE_EXERCISE_SECRET": SECRET})
    assert code == 0, err
    assert "wrote" in said and "your secret" in said
    with zipfile.ZipFile(out) as zf:
        names = set(zf.namelist())
        config = json.loads(zf.read("mexone-autograder.json"))
    assert config["exercise"] == "exercise"
    assert {"exercise/exercise.yaml", "exercise/grader.py", "exercise/starter/routine.py"} <= names
    assert not [n for n in names if "solution" in n]


@pytest.mark.slow
def test_wheel_from_the_checkout(tmp_path):
    """A teacher running mexone from a clone (an editable install): `pip wheel --no-deps` of
    a clean copy of it."""
    path = build_wheel(tmp_path)
    with zipfile.ZipFile(path) as zf:
        names = set(zf.namelist())
    assert "mexone/exercises/autograder.py" in names
    assert not [n for n in names if "__pycache__" in n or n.endswith(".pyc")]


def test_a_missing_submission_or_a_broken_zip_still_writes_results(tmp_path, monkeypatch):
    """No file handed in: 0 points saying what the upload holds; a zip whose config is broken:
    results.json saying so (for the teacher), exit 2; the secret file is gone either way."""
    from mexone.exercises import autograder

    monkeypatch.setenv("MEXONE_EXERCISE_SECRET", "")  # run() sets it: undone after the test
    for name in ("source", "submission", "results"):
        (tmp_path / name).mkdir()
    (tmp_path / "source" / "mexone-autograder.json").write_text(json.dumps(
        {"exercise": EXERCISE, "file": "identify_damping.py"}))
    (tmp_path / "source" / "secret").write_text(SECRET)
    (tmp_path / "submission" / "notes.txt").write_text("oops")
    assert autograder.run(tmp_path) == 0
    results = json.loads((tmp_path / "results" / "results.json").read_text())
    jsonschema.validate(results, SCHEMA)
    assert results["score"] == 0 and "notes.txt" in results["tests"][0]["output"]
    assert not (tmp_path / "source" / "secret").exists()
    assert os.environ["MEXONE_EXERCISE_SECRET"] == SECRET

    nested = tmp_path / "submission" / "my upload" / "identify_damping.py"
    nested.parent.mkdir()
    nested.write_text("")
    assert autograder._submission(tmp_path / "submission", nested.name) == nested

    (tmp_path / "source" / "mexone-autograder.json").write_text("{not json")
    assert autograder.run(tmp_path) == 2
    results = json.loads((tmp_path / "results" / "results.json").read_text())
    jsonschema.validate(results, SCHEMA)
    assert "could not grade" in results["output"] and "mexone-autograder.json" in results["output"]
