"""Course exercises 11-12 (issue 38), graded through the framework: the observer of the tilt and
the design with margins. The reference solution scores full marks on the given robot and on the
hidden variant, the starter scores low, a wrong solution (a truth-reader; a soft arm) fails its
check, graded in the isolated child as every exercise is."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from mexone.exercises import find_exercise, grade

COURSE = Path(__file__).resolve().parents[2] / "src" / "mexone" / "exercises" / "course"
WRONG = Path(__file__).resolve().parent / "wrong"
CASES = [("tilt_observer", ["tracks the tilt", "uses the IMU"]),
         ("robust_arm", ["holds against a push"])]


def failed(result) -> list[str]:
    return [c.name for c, _, _ in result.checks if not c.passed]


@pytest.mark.slow
@pytest.mark.parametrize("name, failing", CASES, ids=[c[0] for c in CASES])
def test_reference_full_starter_low_wrong_fails_its_check(name, failing):
    exercise = find_exercise(name)
    spec = importlib.util.spec_from_file_location(f"grader_{name}", COURSE / name / "grader.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.variant(np.random.default_rng(1)) != module.variant(None)  # hidden != given
    for local in (True, False):
        result = grade(exercise, COURSE / name / "solution" / exercise.file, local=local)
        assert result.score == pytest.approx(exercise.points), [c.output for c, _, _ in result.checks]
    starter = grade(exercise, COURSE / name / "starter" / exercise.file)
    assert starter.score <= 0.4 * exercise.points, [c.output for c, _, _ in starter.checks]
    wrong = grade(exercise, WRONG / name / exercise.file)
    assert wrong.score < exercise.pass_mark, [c.output for c, _, _ in wrong.checks]
    for check in failing:
        assert check in failed(wrong), [c.output for c, _, _ in wrong.checks]
