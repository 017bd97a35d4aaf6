"""What a graded report tells a student, and what grading reads of a handed-in file (a red team's
round, session 7). The hidden variant is the class's -- keyed by the teacher's secret, the same
for every submission -- so a report that states it answers the exercise to a resubmission; and a
submission is read as any file a user names (regular, within the input size cap) before a copy
of it is made."""

from __future__ import annotations

import json
import os
import re

import pytest

from mexone.exercises import GradeContext, find_exercise, grade, grading
from mexone.exercises.grading import as_text, gradescope_json
from mexone.inputs import DEFAULT_LIMIT_MB, LIMIT_ENV, read_input


def _numbers(text: str) -> list[float]:
    return [float(n) for n in re.findall(r"\d+\.\d+|\d+", text)]


def test_identify_damping_report_states_no_hidden_truth(tmp_path, monkeypatch):
    """Was: "estimated 0.2 N m s/rad, truth 0.3284: off by 39.1%" in the visible results.json:
    the starter handed in once, then `return 0.3284` scored 10/10 (the same truth for the whole
    class). No number in any report is within 5 % of the truth but the student's own."""
    monkeypatch.setenv(grading.SECRET_ENV, "red-team-secret-of-this-test-0123")
    exercise = find_exercise("identify_damping")
    submission = tmp_path / exercise.file
    submission.write_text("def estimate(bag):\n    return 0.2\n")  # never within 30 %
    grader = exercise.grader()
    truth = grader.variant(GradeContext(exercise, submission, exercise.seeds[0]).rng)
    result = grade(exercise, submission)
    assert result.failure is None and result.score == 0, as_text(result)
    shown = as_text(result) + json.dumps(gradescope_json(result))
    near = [n for n in _numbers(shown) if n > 0 and abs(n / truth - 1) < 0.05]
    assert not near, (truth, shown)
    assert "off by more than 30%" in result.checks[0][0].output, as_text(result)


def test_a_submission_over_the_input_cap_is_refused_unread(tmp_path, monkeypatch):
    """Was: a sparse 800 MB com_planner.py copied whole into the grader's /tmp and read into its
    memory (1.7 GB peak; a few GB more and the class's grading ends), then 'No space left on
    device' in the jail. Now 0 points at once, with the size and the cap, the grader not run."""
    monkeypatch.delenv(LIMIT_ENV, raising=False)

    def graded(*args, **kwargs):
        raise AssertionError("the grader ran on a submission over the cap")

    monkeypatch.setattr(grading, "_grade", graded)
    exercise = find_exercise("walk_com_planner")
    submission = tmp_path / exercise.file
    with open(submission, "wb") as f:
        f.truncate(int((DEFAULT_LIMIT_MB + 1) * 1e6))  # sparse: no disk used
    result = grade(exercise, submission)
    assert result.score == 0 and result.failure is not None
    assert result.failure.startswith(f"{exercise.file}: is 5.0 MB, over the 4 MB limit"), \
        result.failure
    assert result.failing == ["runs"]
    assert os.path.getsize(submission) > DEFAULT_LIMIT_MB * 1e6  # the student's file untouched


@pytest.mark.parametrize("kind", ["folder", "fifo"])
def test_a_submission_that_is_no_regular_file_is_a_zero_not_the_grader_s_error(tmp_path, kind):
    """A file grading cannot read is the student's zero with the reason, never an error that
    ends a class's grading at that student (grade() is what each row of the CSV calls)."""
    exercise = find_exercise("home_hold")
    submission = tmp_path / exercise.file
    submission.write_text("x")

    def swapped(path, label=None):  # what is there when it is read (a race, a device)
        path.unlink()
        if kind == "folder":
            path.mkdir()
        else:
            os.mkfifo(path)
        return read_input(path, label)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(grading, "read_input", swapped, raising=False)
        result = grade(exercise, submission)
    assert result.score == 0 and result.failure is not None
    assert "not a regular file" in result.failure, result.failure
