"""Course exercises 5-8 (issue 27): each one's reference solution scores full marks on the given
robot and on a hidden variant, its starter scores low, a deliberately wrong solution scores below
the pass mark with the failing check named, and the same submission graded twice scores the
same. Graded in-process through each exercise's grader.py (the framework's sandbox aside)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from mexone.exercises.course._labtools import score

COURSE = Path(__file__).resolve().parents[2] / "src" / "mexone" / "exercises" / "course"
WRONG = Path(__file__).resolve().parent / "wrong"
PASS_MARK = 0.7
SEED = 12345  # the hidden variant's seed in these tests

# exercise folder, the check the wrong solution fails
CASES = [("05_gravity_compensation", "holds the arm"),
         ("06_computed_torque", "tracks the sine"),
         ("07_task_space_impedance", "F/K up"),
         ("08_balance_under_pushes", "survives 4.5 N s")]


def grader(folder: str):
    spec = importlib.util.spec_from_file_location(f"grader_{folder}", COURSE / folder / "grader.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
@pytest.mark.parametrize("folder, failing", CASES, ids=[c[0] for c in CASES])
def test_reference_full_starter_low_wrong_fails_its_check(folder, failing):
    g = grader(folder)
    here = COURSE / folder
    assert g.variant(SEED) != g.variant(None)  # the hidden robot is not the given one
    for seed in (None, SEED):
        checks = g.grade(here / "solution", seed)
        assert score(checks) == pytest.approx(1.0), [c.output for c in checks]
    again = g.grade(here / "solution", SEED)
    assert [c.output for c in again] == [c.output for c in checks]  # deterministic
    starter = score(g.grade(here / "starter", SEED))
    assert starter < 0.5, starter
    wrong = g.grade(WRONG / folder, SEED)
    assert score(wrong) < PASS_MARK, [c.output for c in wrong]
    assert not next(c for c in wrong if c.name == failing).passed, [c.output for c in wrong]
