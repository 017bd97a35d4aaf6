"""What a graded report tells a student, and what grading reads of a handed-in file (a red team's
round, session 7). The hidden variant is the class's -- keyed by the teacher's secret, the same
for every submission -- so a report that states it answers the exercise to a resubmission; and a
submission is read as any file a user names (regular, within the input size cap) before a copy
of it is made."""

from __future__ import annotations

import json
import math
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


DEAD_RECKONING = """
import numpy as np
from mexone.control import PythonController


class TiltObserver(PythonController):
    exports = {"tilt": 2}

    def activate(self, state):
        self.tilt = np.zeros(2)

    def update(self, state, t, dt):
        gyro = np.asarray(state.sensors["imu"].angular_velocity, dtype=float)[:2]
        self.tilt += dt * gyro
        self.exports["tilt"][:] = self.tilt
"""


def test_tilt_observer_report_states_no_slope_nor_gyro_bias(tmp_path, monkeypatch):
    """Was: "slope 0.0/2.0 deg, gyro 0.0181006 rad/s (bias +0.0040, +0.0032), ..." in every
    graded report: the gyro integrated from that slope less that bias -- no accelerometer, no
    observer -- scored 8.6/10 on a resubmission. The self-check still shows the given robot."""
    monkeypatch.setenv(grading.SECRET_ENV, "red-team-secret-of-this-test-0123")
    exercise = find_exercise("tilt_observer")
    submission = tmp_path / exercise.file
    submission.write_text(DEAD_RECKONING)
    grader = exercise.grader()
    var = grader.variant(GradeContext(exercise, submission, exercise.seeds[0]).rng)
    result = grade(exercise, submission)
    shown = as_text(result) + json.dumps(gradescope_json(result))
    tracks = next(c for c, _, _ in result.checks if c.name == "tracks the tilt")
    assert "hidden variant" in tracks.output, tracks.output  # it ran, and said what it hid
    secrets = [abs(math.degrees(a)) for a in var["slope"] if a] + \
        [abs(b) for b in var["bias"]] + [var["gyro"], var["acc"]]
    found = [n for n in _numbers(shown) for x in secrets if abs(n / x - 1) < 0.02]
    assert not found, (var, shown)


@pytest.mark.parametrize("kind", ["folder", "fifo"])
def test_a_submission_that_is_no_regular_file_is_a_zero_not_the_grader_s_error(tmp_path, kind):
    """A file grading cannot read is the student's zero with the reason, never an error that
    ends a class's grading at that student (grade() is what each row of the CSV calls)."""
    exercise = find_exercise("home_hold")
    submission = tmp_path / exercise.file
    submission.write_text("x")

    def swapped(path, label=None, follow=True):  # what is there when it is read (a race, a device)
        path.unlink()
        if kind == "folder":
            path.mkdir()
        else:
            os.mkfifo(path)
        return read_input(path, label, follow)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(grading, "read_input", swapped, raising=False)
        result = grade(exercise, submission)
    assert result.score == 0 and result.failure is not None
    assert "not a regular file" in result.failure, result.failure
