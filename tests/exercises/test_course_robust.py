"""Course exercises 11-12 (issue 38), graded through the framework: the observer of the tilt and
the design with margins. The reference solution scores full marks on the given robot and on the
hidden variant, the starter scores low, a wrong solution (a truth-reader; a soft arm) fails its
check, and a cheat (the truth offset by the slope it measured; a design that changes its gains
when it sees the grader's trial) fails, graded in the isolated child as every exercise is."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from mexone.exercises import find_exercise, grade

COURSE = Path(__file__).resolve().parents[2] / "src" / "mexone" / "exercises" / "course"
WRONG = Path(__file__).resolve().parent / "wrong"
CHEAT = Path(__file__).resolve().parent / "cheat"
CASES = [("tilt_observer", ["tracks the tilt", "uses the IMU"]),
         ("robust_arm", ["holds against a push"])]


def grader(name: str):
    spec = importlib.util.spec_from_file_location(f"grader_{name}", COURSE / name / "grader.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def failed(result) -> list[str]:
    return [c.name for c, _, _ in result.checks if not c.passed]


@pytest.mark.slow
@pytest.mark.parametrize("name, failing", CASES, ids=[c[0] for c in CASES])
def test_reference_full_starter_low_wrong_fails_its_check(name, failing):
    exercise = find_exercise(name)
    module = grader(name)
    assert module.variant(np.random.default_rng(1)) != module.variant(None)  # hidden != given
    for local in (True, False):
        result = grade(exercise, exercise.solution, local=local)
        assert result.score == pytest.approx(exercise.points), [c.output for c, _, _ in result.checks]
    starter = grade(exercise, COURSE / name / "starter" / exercise.file)
    assert starter.score <= 0.4 * exercise.points, [c.output for c, _, _ in starter.checks]
    wrong = grade(exercise, WRONG / name / exercise.file)
    assert wrong.score < exercise.pass_mark, [c.output for c, _, _ in wrong.checks]
    for check in failing:
        assert check in failed(wrong), [c.output for c, _, _ in wrong.checks]


def outputs(result) -> dict[str, str]:
    return {c.name: c.output for c, _, _ in result.checks}


@pytest.mark.slow
def test_the_truth_offset_by_the_accelerometers_slope_is_caught():
    # the simulator's base orientation plus the slope measured at rest tracks the tilt from
    # gravity (it passed both checks when the second run made the whole IMU louder): it never
    # reads the gyro, so its estimate does not move with it, and its tracking is not counted
    exercise = find_exercise("tilt_observer")
    cheat = CHEAT / "tilt_observer" / exercise.file
    # (it tracked within the full marks when the observer read the truth; it reads none since the
    # held-out round: test_attacks_held_out.py::test_the_tilt_observer_reads_no_truth)
    result = grade(exercise, cheat)
    said = outputs(result)
    assert failed(result) == ["tracks the tilt", "uses the IMU"], said
    assert said["uses the IMU"].startswith("with the gyro's noise 10 % larger the estimate "
                                           "changed by up to 0.000 mrad: it does not fuse the"), said
    assert said["tracks the tilt"].startswith("not counted: uses the IMU failed"), said
    assert result.score == pytest.approx(1.0)


@pytest.mark.slow
def test_a_design_that_changes_its_gains_when_it_sees_the_trial_is_caught():
    # stiff gains (which ring under the delay and the doubled commands) unless it sees the
    # grader's perturbation: a subclass around it (no more: the grader scales the gear) or the
    # live model (it runs in a worker of its own since issue 36: a copy, the trial not in it)
    exercise = find_exercise("robust_arm")
    result = grade(exercise, CHEAT / "robust_arm" / exercise.file)
    assert result.score < exercise.pass_mark, outputs(result)
