"""The shipped exercises 1-4: the reference scores full marks, the starter low, a deliberately
wrong solution below the pass mark with the failing check named; grading is repeatable."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from mexone.exercises import find_exercise, grade

COURSE = ("model_checks", "home_hold", "pid_spec", "arms_routine")


def _wrong_model_checks(ex, folder: Path) -> Path:
    """COM and inertia fixed, but the misplaced foot collision deleted instead of moved: check
    is silent, the fall is not the reference's."""
    text = ex.starter.read_text()
    text = text.replace('<origin xyz="0.01 0.3 0.13"', '<origin xyz="0.01 0 0.13"')
    text = text.replace('izz="0.08"', 'izz="0.0008"')
    start = text.index('<collision name="l_foot_collision_0">')
    end = text.index("</collision>", start) + len("</collision>")
    return _write(folder / ex.file, text[:start] + text[end:])


def _scaled_gains(text: str, p: float, d: float) -> str:
    text = re.sub(r"(\n\s+p: )([0-9.]+)", lambda m: f"{m.group(1)}{float(m.group(2)) * p:g}", text)
    return re.sub(r"(\n\s+d: )([0-9.]+)", lambda m: f"{m.group(1)}{float(m.group(2)) * d:g}", text)


def _wrong_home_hold(ex, folder: Path) -> Path:
    """Gains a fifth of the reference's: it stands, but sags off home."""
    return _write(folder / ex.file, _scaled_gains(ex.solution.read_text(), 0.2, 1.0))


def _wrong_pid_spec(ex, folder: Path) -> Path:
    """Fast and stiff but with no derivative gain: it overshoots."""
    text = re.sub(r"(l_elbow\n    pid:\n      p: )[0-9.]+(\n      i: )[0-9.]+(\n      d: )[0-9.]+",
                  r"\g<1>150.0\g<2>0.0\g<3>0.0", ex.solution.read_text())
    return _write(folder / ex.file, text)


def _wrong_arms_routine(ex, folder: Path) -> Path:
    """The seed's Listing 4.2 mistake: the poses in degrees, sent as radians."""
    text = ex.solution.read_text().replace("for joint, value in zip(JOINTS, command(",
                                           "for joint, value in zip(JOINTS, command_deg(")
    text = text.replace("\n\nwhile not", "\n\ndef command_deg(t):\n"
                        "    return [math.degrees(v) for v in command(t)]\n\n\nwhile not")
    return _write(folder / ex.file, "import math\n" + text)


WRONG = {"model_checks": (_wrong_model_checks, {"fall time like the reference",
                                                "rest pose like the reference"}),
         "home_hold": (_wrong_home_hold, {"holds home"}),
         "pid_spec": (_wrong_pid_spec, {"overshoot"}),
         "arms_routine": (_wrong_arms_routine, {"pose 1 at 1.5-2 s"})}


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.mark.parametrize("name", COURSE)
def test_reference_full_marks_starter_low_wrong_named(name, tmp_path):
    ex = find_exercise(name)
    reference = grade(ex, ex.solution)
    assert reference.failure is None, reference.failure
    assert reference.score == ex.points, [(c.name, c.output) for c, _, _ in reference.checks]
    starter = grade(ex, ex.starter)
    assert starter.score <= 0.4 * ex.points, starter.score
    make, failing = WRONG[name]
    wrong = grade(ex, make(ex, tmp_path))
    assert wrong.failure is None, wrong.failure
    assert wrong.score < ex.pass_mark and not wrong.passed
    assert failing <= set(wrong.failing), wrong.failing


def test_same_submission_same_score_and_hidden_variation_differs():
    ex = find_exercise("home_hold")
    first, second = grade(ex, ex.solution), grade(ex, ex.solution)
    assert [(c.name, c.output, s) for c, s, _ in first.checks] == \
        [(c.name, c.output, s) for c, s, _ in second.checks]
    local = grade(ex, ex.solution, local=True)  # the nominal robot: other numbers
    assert [c.output for c, _, _ in local.checks] != [c.output for c, _, _ in first.checks]


def test_model_checks_gives_nothing_for_deleting_the_robot(tmp_path):
    # was 4.5/10: the three "fixed" checks passed because the links that held the mistakes
    # were gone (with the rest of the robot)
    ex = find_exercise("model_checks")
    one_link = _write(tmp_path / ex.file, '<robot name="mex_rb"><link name="a"><inertial>'
                      '<mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" '
                      'ixz="0" iyz="0"/></inertial></link></robot>\n')
    result = grade(ex, one_link)
    assert result.score == 0, [(c.name, c.output) for c, _, _ in result.checks]
    model = [c for c, _, _ in result.checks if c.name.endswith(" fixed") or c.name == "check clean"]
    assert len(model) == 4 and all("not the given robot: link pelvis is missing" in c.output
                                   for c in model)


def test_pid_spec_grades_a_pid_not_an_ideal_servo(tmp_path):
    # was 10/10: ideal_servo teleports the elbow (rise time 0 s) and every metric passed
    ex = find_exercise("pid_spec")
    text = re.sub(r"(l_elbow_position_controller:\n)    type: effort_controllers/JointPositionController"
                  r"\n    joint: l_elbow\n    pid:\n(      .*\n)+",
                  r"\1    type: position_controllers/JointPositionController\n    joint: l_elbow\n"
                  r"    ideal_servo: true\n", ex.solution.read_text())
    assert "ideal_servo: true" in text
    result = grade(ex, _write(tmp_path / ex.file, text))
    assert result.score < 1.2 and "rise time" in result.failing, result.score
    rise = next(c for c, _, _ in result.checks if c.name == "rise time")
    assert rise.output.startswith("l_elbow_position_controller must stay effort_controllers/")


def test_a_fallen_robot_holds_no_home(tmp_path):
    # was 3/10: the robot lay still on the floor with its joints near 0 and earned "holds home"
    # (or "no oscillation"); what presumes standing now requires "stays upright"
    ex = find_exercise("home_hold")
    limp = _write(tmp_path / ex.file, _scaled_gains(ex.solution.read_text(), 0.01, 0.01))
    result = grade(ex, limp, local=True)
    assert result.failure is None, result.failure
    assert result.score == 0, [(c.name, c.output) for c, _, _ in result.checks]
    assert result.failing == ["stays upright", "holds home", "no oscillation"]
    fell = next(c for c, _, _ in result.checks if c.name == "stays upright").output
    assert fell.startswith("fell at ")
    for check, _, _ in result.checks[1:]:
        assert check.output == f"not counted: stays upright failed ({fell})"
