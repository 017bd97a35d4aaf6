"""Course exercises 5-10 (issue 27), graded through the framework (`grade`, the student's part in
an isolated child): each one's reference solution scores full marks on the given robot (the
self-check) and on the hidden variant, its starter scores low, a deliberately wrong solution
scores below the pass mark with the failing check named, and grading twice scores the same."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from mexone.exercises import find_exercise, grade

COURSE = Path(__file__).resolve().parents[2] / "src" / "mexone" / "exercises" / "course"
WRONG = Path(__file__).resolve().parent / "wrong"

# exercise, the check its wrong solution fails, whether the self-check (the given robot) and a
# second grading are also run (the cheap ones: the suite's time; the others take 5-10 s a grading)
CASES = [("gravity_compensation", "holds the arm", True),
         ("computed_torque", "tracks the sine", True),
         ("task_space_impedance", "F/K up", True),
         ("balance_under_pushes", "survives 5 N s", False),
         ("walk_course", "stays up", False),
         ("identify_damping", "damping", False)]


# the wrong solutions that are the reference with one mistake: (what, the reference's line, it
# made wrong) -- the others are files of their own under wrong/
WRONG_EDITS = {
    # gravity torques written down once, for the given arm in the given pose (measured once
    # with g(q)): the hidden payload and pose are not compensated
    "gravity_compensation": ("g = self.dynamics.gravity()[self.dofs]",
                             "g = np.array([-1.4191, 0.0, -0.363])"),
    # computed torque with the inertia left out (M taken as the identity, tau = ddq + h): the
    # error is no longer linear, the arm lags the sine by tens of mrad
    "computed_torque": ("return self.dynamics.inverse_dynamics(qacc, contacts=True)[self.dofs]",
                        "return ddq + self.dynamics.bias()[self.dofs]"),
    # the hand's force mapped to joint torques through J instead of its transpose (the arm's J
    # is 3 x 3, so it runs): pushed up, the hand moves 5-8x F/K
    "task_space_impedance": ("return jacobian.T @ force", "return jacobian @ force"),
}


def wrong_solution(exercise, folder: Path) -> Path:
    """The exercise's deliberately wrong solution: an edit of the reference, or wrong/'s file."""
    if exercise.name not in WRONG_EDITS:
        return WRONG / exercise.name / exercise.file
    right, wrong = WRONG_EDITS[exercise.name]
    text = exercise.solution.read_text()
    assert right in text, (exercise.name, right)
    path = folder / exercise.file
    path.write_text(text.replace(right, wrong))
    return path


def failed(result) -> list[str]:
    return [c.name for c, _, _ in result.checks if not c.passed]


@pytest.mark.slow
@pytest.mark.parametrize("name, failing, thorough", CASES, ids=[c[0] for c in CASES])
def test_reference_full_starter_low_wrong_fails_its_check(name, failing, thorough, tmp_path):
    exercise = find_exercise(name)
    file = exercise.file
    spec = importlib.util.spec_from_file_location(f"grader_{name}", COURSE / name / "grader.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.variant(np.random.default_rng(1)) != module.variant(None)  # hidden != given
    for local in (True, False) if thorough else (False,):
        result = grade(exercise, exercise.solution, local=local)
        assert result.score == pytest.approx(exercise.points), [c.output for c, _, _ in result.checks]
    if thorough:  # graded twice: the same numbers
        again = grade(exercise, exercise.solution)
        assert [c.output for c, _, _ in again.checks] == [c.output for c, _, _ in result.checks]
    starter = grade(exercise, COURSE / name / "starter" / file)
    assert starter.score <= 0.4 * exercise.points, [c.output for c, _, _ in starter.checks]
    wrong = grade(exercise, wrong_solution(exercise, tmp_path))
    assert wrong.score < exercise.pass_mark, [c.output for c, _, _ in wrong.checks]
    assert failing in failed(wrong), [c.output for c, _, _ in wrong.checks]


@pytest.mark.parametrize("text, reason", [
    ("x = 1\n", "has no class 'GravityCompensation'"),
    ("from mexone.control import Param, PythonController\n\n\n"
     "class GravityCompensation(PythonController):\n    command_interface = 'effort'\n"
     "    kp = Param(5.0)\n    kd = Param(0.5)\n\n    def update(self, state, t, dt):\n"
     "        raise ValueError('oops')\n", "ValueError: oops"),
], ids=["no class", "update raises"])
def test_a_controller_that_does_not_load_or_raises_scores_zero_with_its_line(tmp_path, text, reason):
    exercise = find_exercise("gravity_compensation")
    submission = tmp_path / "mine.py"  # any name: the grader copies it under the one it needs
    submission.write_text(text)
    result = grade(exercise, submission)
    assert result.score == 0, [c.output for c, _, _ in result.checks]
    runs = next(c for c, _, _ in result.checks if c.name == "runs")
    assert reason in runs.output and "Traceback" not in runs.output
    assert "/tmp" not in runs.output  # the student's file by its name, not the grader's copy


@pytest.mark.parametrize("answer", ["None", "'0.5 N m s/rad'", "[0.5]"])
def test_an_estimate_that_is_not_a_number_is_the_students_reason(tmp_path, answer):
    from mexone.exercises import SubmissionFailed

    spec = importlib.util.spec_from_file_location("grader_id", COURSE / "identify_damping" / "grader.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    submission = tmp_path / "identify_damping.py"
    submission.write_text(f"def estimate(bag):\n    return {answer}\n")
    # was: "the grader could not run the submission: TypeError: float() argument must be ..."
    with pytest.raises(SubmissionFailed, match=r"estimate\(bag\) returned \w+ .*, not a number"):
        module.estimate(submission, tmp_path / "unused.bag")


@pytest.mark.parametrize("name", ["gravity_compensation", "computed_torque"])
def test_a_position_interface_ideal_servo_scores_zero(tmp_path, name):
    # was 10/10 on exercise 5: command_interface "position" without gains is an ideal servo
    exercise = find_exercise(name)
    text = exercise.solution.read_text()
    submission = tmp_path / exercise.file
    submission.write_text(text.replace('command_interface = "effort"',
                                       'command_interface = "position"'))
    result = grade(exercise, submission)
    assert result.score == 0, [c.output for c, _, _ in result.checks]
    runs = next(c for c, _, _ in result.checks if c.name == "runs")
    assert runs.output.startswith("command_interface is 'position': the exercise is a torque law")


def test_a_gait_the_walk_routine_refuses_is_named_by_the_students_file(tmp_path):
    exercise = find_exercise("walk_course")
    gait = tmp_path / "walk.yaml"
    gait.write_text(exercise.starter.read_text().replace("step_length: 0.015", "step_length: -1"))
    result = grade(exercise, gait)
    runs = next(c for c, _, _ in result.checks if c.name == "runs")
    # was: "the grader could not run the submission: mexone.errors.RoutineError: .../walk.py:20:
    # mexone.errors.InputError: /tmp/tmp.../gait.yaml: ..."
    assert runs.output.startswith("the walk routine cannot walk this gait: walk.yaml: period, dt, "
                                  "step_length"), runs.output
    assert "/tmp" not in runs.output and result.score == 0
