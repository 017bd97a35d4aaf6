"""The pieces of Gradescope's autograder (`mexone exercise autograder`, mexone.exercises.autograder)
that need no installed wheel: results.json's fields, the refusals, a teacher's exercise in the
zip, the wheel of a checkout, a run with no submission or a broken config, and why the secret
decides the truth. They only compute, beside other files (tests/phases.py); the zip run as
Gradescope runs it, from the session's venv, is tests/exercises/test_autograder.py."""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

import jsonschema
import pytest

from helpers import run_cli
from mexone.exercises import Check, GradeContext, Result, find_exercise
from mexone.exercises.autograder import build_wheel, results_json

# as in tests/exercises/test_autograder.py
SCHEMA = json.loads((Path(__file__).parent.parent / "data" / "exercises" /
                     "gradescope_results.schema.json").read_text())
EXERCISE = "identify_damping"  # its student's part is Python; the truth comes from the secret
SECRET = "teacher-3f9c1e-not-for-students"
SOLUTION = find_exercise(EXERCISE).solution


def test_the_truth_depends_on_the_secret(monkeypatch):
    """What makes test_autograder.py's comparison with `mexone exercise grade` tell: with another
    secret, the same seed draws another true damping (and so another output and score)."""
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
