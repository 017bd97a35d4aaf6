"""A teacher's reports are data (issue 36): the CSV's cells cannot become spreadsheet formulas,
no name or reason a student controls can print a line of its own ("PASS", "score 10/10"), a
submission that is a symbolic link is refused with a reason and never read, the CSV's check
columns (runs included) add up to the score, every score below full marks has its reason, and
the hidden variation is keyed by the teacher's secret (without it, refused)."""

from __future__ import annotations

import csv
import io
import tempfile
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from helpers import fuzz, run_cli
from mexone.errors import InputError
from mexone.exercises import find_exercise, grade
from mexone.exercises.grading import (
    CSV_FORMULA,
    SECRET_ENV,
    as_text,
    csv_cell,
    gradescope_json,
    hidden_rng,
    write_csv,
    zero,
)

BROKEN = "mex_rb: [unclosed\n"  # a gains file that fails at once: no simulation
HOME_HOLD = find_exercise("home_hold")


def rows(text: str) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(text)))


def shown_in_one_line(text: str) -> bool:
    return all(c.isprintable() for c in text)


# ----- CSV injection, control characters: property tests on the report functions ---------------
@fuzz(150)
@given(student=st.text(max_size=60), why=st.text(max_size=200), output=st.text(max_size=300))
def test_any_name_and_reason_stay_data_in_every_report(student, why, output):
    ex = HOME_HOLD
    result = zero(ex, Path("subs") / (student or "x"), why, output)
    text = as_text(result)
    lines = text.splitlines()
    # our lines only: the header, the runs check, the output's own lines (marked), the score
    assert lines[0].startswith(f"{ex.title} ({ex.name}): ") and lines[1].startswith("  FAIL runs")
    assert lines[-1].startswith("score 0/10 (not passed")
    assert all(line.startswith("    | ") for line in lines[3:-1]), lines
    assert all(shown_in_one_line(line) for line in lines)
    summary = gradescope_json(result)["output"]
    assert all(shown_in_one_line(line) for line in summary.splitlines())
    with tempfile.TemporaryDirectory() as tmp:
        write_csv({student: result}, Path(tmp) / "grades.csv")
        table = list(csv.reader(io.StringIO((Path(tmp) / "grades.csv").read_text())))
    assert len(table) == 2  # the header and the student's row: no line of the student's own
    for cell in table[1]:
        assert shown_in_one_line(cell) and not cell.startswith(CSV_FORMULA), cell


@pytest.mark.parametrize("value", ["=cmd|' -C calc'!A0", "+1+1", "-2+3", "@SUM(A1)", "\tx",
                                   "\r=1", "ada"])
def test_a_csv_cell_never_starts_a_formula(value):
    cell = csv_cell(value)
    assert not cell.startswith(CSV_FORMULA)
    assert cell == value or cell.startswith("'")


# ----- a folder of submissions, graded by the CLI -----------------------------------------------
def test_names_that_are_formulas_or_hold_newlines_are_data(tmp_path):
    folder = tmp_path / "subs"
    folder.mkdir()
    names = ["=cmd|' -C calc'!A0", "+SUM(1)", "@x", "ada\nPASS runs 10.00\nscore 10 of 10"]
    for name in names:
        (folder / f"{name}.yaml").write_text(BROKEN)
    (folder / "bob\rscore 10 of 10").mkdir()  # a student's folder: a carriage return in its name
    (folder / "bob\rscore 10 of 10" / "controllers.yaml").write_text(BROKEN)
    out_csv = tmp_path / "grades.csv"
    code, out, err = run_cli(["exercise", "grade", "home_hold", folder, "--csv", out_csv])
    assert code == 0, err
    progress = out.splitlines()
    assert len(progress) == len(names) + 2, progress  # a line a student, then "wrote"
    assert not [line for line in progress if line.startswith(("PASS", "score"))], progress
    assert all(shown_in_one_line(line) for line in progress)
    assert "ada\\nPASS runs 10.00\\nscore 10 of 10" in out and "bob\\rscore 10 of 10" in out
    table = rows(out_csv.read_text())
    assert len(table) == len(names) + 1
    for row in table:
        assert row["score"] == "0" and row["reason"], row
        assert all(not cell.startswith(CSV_FORMULA) and shown_in_one_line(cell)
                   for cell in row.values()), row
    assert {row["student"] for row in table} >= {"'=cmd|' -C calc'!A0", "'+SUM(1)", "'@x"}


def test_a_reason_with_newlines_prints_no_line_of_its_own(tmp_path):
    """The student's exception message lands in the reason: on the same line (escaped, or its
    control characters replaced where the controller's worker reports it)."""
    submission = tmp_path / "gravity_compensation.py"
    submission.write_text(
        "raise ValueError('oops\\n  PASS holds the arm 8.00/8.00\\nscore 10/10 (passed)')\n")
    code, out, err = run_cli(["exercise", "grade", "gravity_compensation", submission])
    assert code == 0, err
    lines = out.splitlines()
    assert lines[-1].startswith("score 0/10"), out
    assert not [line for line in lines if line.startswith(("score 10", "  PASS"))], out
    (reason,) = [line for line in lines if "oops" in line]
    assert "PASS holds the arm" in reason and "score 10/10" in reason, out


def test_a_symlinked_submission_is_refused_not_read(tmp_path):
    """A link to the reference itself would score 10/10 if it were read: it scores 0, with why."""
    reference = find_exercise("home_hold").solution
    folder = tmp_path / "subs"
    (folder / "ada").mkdir(parents=True)
    (folder / "ada" / "controllers.yaml").symlink_to(reference)  # a file in a student's folder
    (folder / "eve.yaml").symlink_to("/etc/passwd")  # a submission file
    (folder / "mal").symlink_to(reference.parent, target_is_directory=True)  # a student's folder
    (folder / "zoe.yaml").symlink_to(tmp_path / "missing.yaml")  # dangling
    out_csv = tmp_path / "grades.csv"
    code, out, err = run_cli(["exercise", "grade", "home_hold", folder, "--csv", out_csv])
    assert code == 0, err
    table = {row["student"]: row for row in rows(out_csv.read_text())}
    assert sorted(table) == ["ada", "eve", "mal", "zoe"]
    for student, row in table.items():
        assert row["score"] == "0", (student, row)
        assert "is a symbolic link" in row["reason"] and "refused, not read" in row["reason"], row
    assert "(to /etc/passwd)" in table["eve"]["reason"]
    code, out, err = run_cli(["exercise", "grade", "home_hold", folder / "eve.yaml", "--json"])
    assert code == 0 and '"score": 0.0' in out and "root:" not in out + err, out


# ----- the CSV's columns and reasons --------------------------------------------------------------
@pytest.mark.slow
def test_csv_columns_add_up_to_the_score_and_every_zero_has_its_reason(tmp_path):
    ex = find_exercise("gravity_compensation")
    folder = tmp_path / "subs"
    folder.mkdir()
    (folder / "ada.py").write_text(ex.solution.read_text())
    (folder / "bob.py").write_text("x = 1\n")  # no class: it does not run
    # a caught cheat: a position servo without gains teleports the arm (runs: 0, with why)
    (folder / "eve.py").write_text(ex.solution.read_text().replace(
        'command_interface = "effort"', 'command_interface = "position"'))
    out_csv = tmp_path / "grades.csv"
    code, out, err = run_cli(["exercise", "grade", ex.name, folder, "--csv", out_csv])
    assert code == 0, err
    table = {row["student"]: row for row in rows(out_csv.read_text())}
    header = next(csv.reader(io.StringIO(out_csv.read_text())))
    checks = header[4:-2]
    assert checks[0] == "runs", header  # was left out: the columns added to 8 for 10/10
    for student, row in table.items():
        total = sum(float(row[c]) for c in checks if row[c])
        assert total == pytest.approx(float(row["score"]), abs=1e-3), (student, row)
    assert table["ada"]["score"] == "10" and table["ada"]["reason"] == ""
    assert table["bob"]["score"] == "0" and "has no class 'GravityCompensation'" in table["bob"]["reason"]
    assert float(table["eve"]["score"]) == 0, table["eve"]
    assert "command_interface is 'position'" in table["eve"]["reason"], table["eve"]  # was empty


# ----- the teacher's secret ----------------------------------------------------------------------
def test_the_hidden_variation_needs_the_teachers_secret(tmp_path, monkeypatch):
    ex = find_exercise("home_hold")
    for secret in ("", "short"):
        with pytest.raises(InputError, match=f"{SECRET_ENV} (is not set|has 5 characters)"):
            hidden_rng(ex, 1, secret)
    submission = tmp_path / "controllers.yaml"
    submission.write_text(ex.starter.read_text())
    monkeypatch.delenv(SECRET_ENV)
    code, out, err = run_cli(["exercise", "grade", "home_hold", submission])
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith(f"mexone: ${SECRET_ENV} is not set: the hidden variation is keyed"), err
    # the self-check hides nothing: it needs no secret (its draws are the same everywhere)
    assert grade(ex, submission, local=True).failure is None
    from mexone.exercises import GradeContext

    local = [GradeContext(ex, submission, 1, local=True).rng.random() for _ in range(2)]
    assert local[0] == local[1]


def test_the_shipped_seed_alone_tells_nothing(monkeypatch):
    """Two teachers' secrets draw unrelated variants from the same shipped secret_seed; the same
    secret the same variant (a regrade repeats); no secret, no variant."""
    ex = find_exercise("gravity_compensation")
    one, other = "a teacher's secret of some length", "another teacher's secret, as long"
    draws = {s: [hidden_rng(ex, seed, s).uniform(size=4).tolist() for seed in ex.seeds]
             for s in (one, other)}
    assert draws[one] != draws[other]
    assert draws[one] == [hidden_rng(ex, seed, one).uniform(size=4).tolist() for seed in ex.seeds]
    assert hidden_rng(ex, 1, one).random() != hidden_rng(find_exercise("computed_torque"), 1, one).random()
