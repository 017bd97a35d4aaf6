"""`mexone exercise` as a teacher uses it: grade's outputs are checked before any grading (a
class's folder takes minutes to grade; a --csv into a missing folder must not be found out after
it) and written whole or not at all; start and new refuse a file for a folder; a grader.py that
does not import is one line with its line."""

from __future__ import annotations

import json

import pytest

from helpers import run_cli
from mexone.exercises import find_exercise


def test_bad_outputs_are_refused_before_grading(tmp_path, monkeypatch):
    import mexone.exercises.grading as grading

    graded = []
    monkeypatch.setattr(grading, "grade", lambda *a, **k: graded.append(a))
    folder = tmp_path / "submissions"
    folder.mkdir()
    (folder / "ada.yaml").write_text(find_exercise("home_hold").solution.read_text())
    (tmp_path / "plots.png").write_text("not a folder")
    cases = {  # argv after the submission: a piece of the one line it must get
        ("--csv", tmp_path / "missing" / "grades.csv"): "output folder does not exist",
        ("--csv", tmp_path): "is a folder, not a file",
        ("--plots", tmp_path / "plots.png"): "--plots names a file, not a folder",
    }
    for extra, message in cases.items():
        code, _, err = run_cli(["exercise", "grade", "home_hold", folder, *extra])
        assert code == 2 and message in err and len(err.strip().splitlines()) == 1, (extra, err)
    code, _, err = run_cli(["exercise", "grade", "home_hold", folder / "ada.yaml", "--json",
                            tmp_path / "missing" / "results.json"])
    assert code == 2 and "output folder does not exist" in err, err
    assert graded == [] and not (tmp_path / "missing").exists()


def test_results_json_replaced_only_with_force(tmp_path):
    submission = tmp_path / "controllers.yaml"
    submission.write_text(find_exercise("home_hold").solution.read_text())
    results = tmp_path / "results.json"
    results.write_text("mine\n")
    code, _, err = run_cli(["exercise", "grade", "home_hold", submission, "--json", results])
    assert code == 2 and "exists" in err and results.read_text() == "mine\n"
    code, _, err = run_cli(["exercise", "grade", "home_hold", submission, "--json", results,
                            "--force"])
    assert code == 0, err
    assert json.loads(results.read_text())["score"] == 10
    assert sorted(p.name for p in tmp_path.iterdir()) == ["controllers.yaml", "results.json"]


def test_start_hands_out_the_starter_without_bytecode(tmp_path):
    code, _, err = run_cli(["exercise", "new", "mine", tmp_path / "mine"])
    assert code == 0, err
    cache = tmp_path / "mine" / "starter" / "__pycache__"  # as pip compiles an installed one
    cache.mkdir()
    (cache / "routine.cpython-311.pyc").write_bytes(b"\x00stale")
    (tmp_path / "mine" / "starter" / "old.pyc").write_bytes(b"\x00stale")
    code, _, err = run_cli(["exercise", "start", tmp_path / "mine", tmp_path / "st"])
    assert code == 0, err
    assert sorted(p.name for p in (tmp_path / "st").iterdir()) == ["README.md", "check.py",
                                                                   "routine.py"]


def test_list_aligns_long_names():
    code, out, _ = run_cli(["exercise", "list"])
    assert code == 0
    columns = {line.index(" pts ") for line in out.splitlines()}
    assert len(columns) == 1, out  # gravity_compensation is longer than 16 characters


def test_start_and_new_into_a_file_are_one_line(tmp_path):
    (tmp_path / "afile").write_text("mine\n")
    for argv in (["start", "home_hold", tmp_path / "afile"],
                 ["start", "home_hold", tmp_path / "afile" / "sub"],
                 ["new", "zz", tmp_path / "afile" / "sub"]):
        code, _, err = run_cli(["exercise", *argv])
        assert code == 2 and err.strip() == f"mexone: {tmp_path / 'afile'}: is a file, not a " \
                                             "folder (name a folder)", (argv, err)
    assert (tmp_path / "afile").read_text() == "mine\n"


@pytest.mark.parametrize("text, line, error", [
    ("syntax error here(\n", 1, "SyntaxError: '(' was never closed"),
    ("import numpy\nx = numpy.nope\n", 2, "AttributeError: module 'numpy' has no attribute 'nope'"),
    ("import sys\n\nsys.exit(3)\n", 3, "SystemExit: 3"),
], ids=["syntax", "raises", "exits"])
def test_a_teachers_grader_that_does_not_import_is_one_line_with_its_line(tmp_path, text, line,
                                                                           error):
    code, _, err = run_cli(["exercise", "new", "mine", tmp_path / "mine"])
    assert code == 0, err
    grader = tmp_path / "mine" / "grader.py"
    grader.write_text(text)
    code, _, err = run_cli(["exercise", "grade", tmp_path / "mine",
                            tmp_path / "mine" / "solution" / "routine.py"])
    assert code == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert err.startswith(f"mexone: {grader}:{line}: grader.py does not import: {error}"), err


def test_the_self_check_without_the_file_is_one_line(tmp_path, capsys):
    from mexone.exercises import self_check

    assert self_check("home_hold", str(tmp_path / "controllers.yaml")) == 2  # was a traceback
    err = capsys.readouterr().err
    assert err == f"mexone: no submission file {tmp_path / 'controllers.yaml'} (hand in the " \
                  "exercise's controllers.yaml)\n"


def test_csv_dash_is_stdout_not_a_file_named_dash(tmp_path):
    folder = tmp_path / "submissions"
    folder.mkdir()
    (folder / "eve.yaml").write_text("mex_rb: [unclosed\n")  # fails at once: no simulation
    code, out, err = run_cli(["exercise", "grade", "home_hold", folder, "--csv", "-"], cwd=tmp_path)
    assert code == 0, err
    assert out.splitlines()[0].startswith("student,score,max_score,passed")
    assert out.splitlines()[1].startswith("eve,0,10,no,") and "eve " in err  # progress: stderr
    assert not (tmp_path / "-").exists()


def test_plots_replaced_only_with_force_checked_before_grading(tmp_path, monkeypatch):
    # was: `grade --plots DIR` wrote over DIR's PNGs of an earlier grading without --force
    import mexone.exercises.grading as grading

    graded = []
    monkeypatch.setattr(grading, "grade", lambda *a, **k: graded.append(k) or 1 / 0)
    submission = tmp_path / "controllers.yaml"
    submission.write_text(find_exercise("home_hold").solution.read_text())
    plots = tmp_path / "plots"
    (plots / "bob").mkdir(parents=True)
    mine = [plots / "home_hold-seed2-joints.png", plots / "bob" / "home_hold-seed1-x.png"]
    for path in mine:
        path.write_text("mine\n")
    folder = tmp_path / "class"
    folder.mkdir()
    for student in ("ada", "bob"):
        (folder / f"{student}.yaml").write_text(submission.read_text())
    for argv, clash in (([submission], mine[0]), ([folder, "--csv", tmp_path / "g.csv"], mine[1])):
        code, _, err = run_cli(["exercise", "grade", "home_hold", *argv, "--plots", plots])
        assert code == 2 and err == f"mexone: {clash}: already exists; nothing was graded (pass " \
                                    "--force to overwrite the plots, or give another --plots " \
                                    "folder)\n", err
    assert graded == [] and all(path.read_text() == "mine\n" for path in mine)
    assert not (tmp_path / "g.csv").exists()
    with pytest.raises(ZeroDivisionError):  # --force: past the check, into grading
        run_cli(["exercise", "grade", "home_hold", submission, "--plots", plots, "--force"])
    assert graded == [{"local": False, "plots": plots, "force": True}]


def test_saved_figures_replace_a_file_only_with_force(tmp_path):
    from mexone.errors import OutputExistsError
    from mexone.exercises.grading import GradeContext

    ex = find_exercise("home_hold")
    path = tmp_path / "home_hold-seed1-joints.png"
    path.write_text("mine\n")  # appeared while the grader ran
    ctx = GradeContext(ex, tmp_path / "controllers.yaml", 1, plots=tmp_path)
    ctx.figure("joints").add_subplot().plot([0, 1])
    with pytest.raises(OutputExistsError, match="already exists"):
        ctx.save_figures()
    assert path.read_text() == "mine\n" and [p.name for p in tmp_path.iterdir()] == [path.name]
    ctx = GradeContext(ex, tmp_path / "controllers.yaml", 1, plots=tmp_path, force=True)
    ctx.figure("joints").add_subplot().plot([0, 1])
    assert ctx.save_figures() == [path] and path.read_bytes().startswith(b"\x89PNG")
