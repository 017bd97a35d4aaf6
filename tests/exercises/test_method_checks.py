"""Where an exercise's statement states a method, the grade checks it, not only the outcome
(issue 36): a cheat that reaches the outcome another way scores below the pass mark with the
method check named, and the reference passes. The cheats are the reference with the method's
part taken out (or a law that ignores the grader's gains).

- 5, gravity compensation "at kp 5": a stiff PD without g(q) held the arm (9.6/10);
- 7, task-space impedance "a spring K and damper D to where it started, the weight
  compensated": without the damper, or without g(q), the pushes scored 10/10;
- 6, computed torque "with M(q) and h": a stiff PD with h, or M written down as constants,
  misses 3 mrad on the hidden payload; but a stiffer PD plus g(q) (kp 1e6, kd 2000: the
  starter's two numbers changed) tracked within 1.7 mrad, 10/10 (session 7's red team): the
  acceleration the torque asks for, M^-1 (tau - h) less the sine's, is fitted against e and de
  under pushes, its kp and kd the grader's.
"""

from __future__ import annotations

import pytest

from mexone.exercises import find_exercise, grade

STIFF_PD = '''"""A stiff PD: it ignores kp and kd and leaves g(q) out."""
import numpy as np
from mexone.control import Param, PythonController


class GravityCompensation(PythonController):
    command_interface = "effort"
    kp = Param(5.0, low=0.0, high=1e4)
    kd = Param(0.5, low=0.0, high=1e3)

    def activate(self, state):
        self.q0 = np.array(state.q, dtype=float)

    def update(self, state, t, dt):
        return 500.0 * (self.q0 - state.q) - 1.5 * state.dq
'''


def scores(name: str, tmp_path, cheats: dict[str, str]) -> dict:
    exercise = find_exercise(name)
    out = {"reference": grade(exercise, exercise.solution)}
    for label, text in cheats.items():
        path = tmp_path / f"{label}.py"
        path.write_text(text)
        out[label] = grade(exercise, path)
    return out


def failing(result) -> dict[str, str]:
    return {c.name: c.output for c, _, _ in result.checks if not c.passed}


@pytest.mark.slow
def test_gravity_compensation_checks_kp_kd_and_gravity(tmp_path):
    exercise = find_exercise("gravity_compensation")
    reference = exercise.solution.read_text()
    results = scores("gravity_compensation", tmp_path, {
        "stiff": STIFF_PD,
        "own_gains": reference.replace("self.kp * (", "40.0 * (").replace("self.kd *", "2.0 *"),
    })
    assert results["reference"].score == exercise.points, failing(results["reference"])
    method = next(c for c, _, _ in results["reference"].checks if c.name == "applies kp and kd")
    assert method.output.startswith("kp 5.0"), method.output  # measured, not declared
    for label in ("stiff", "own_gains"):
        result = results[label]
        assert result.score < exercise.pass_mark, (label, failing(result))
        assert "applies kp and kd" in failing(result), (label, failing(result))
        assert failing(result)["holds the arm"].startswith("not counted: applies kp and kd failed")
    # the stiff PD holds the arm well (within 3 mrad): only the method check tells it apart
    assert "kp 50" in failing(results["stiff"])["applies kp and kd"]


@pytest.mark.slow
def test_task_space_impedance_checks_the_damper_and_the_weight(tmp_path):
    exercise = find_exercise("task_space_impedance")
    reference = exercise.solution.read_text()
    no_gravity = reference.replace(" + self.dynamics.gravity()[self.dofs]", "")
    no_damper = reference.replace(" - self.damping * velocity", "")
    assert no_gravity != reference and no_damper != reference
    results = scores("task_space_impedance", tmp_path, {"no_gravity": no_gravity,
                                                        "no_damper": no_damper})
    assert results["reference"].score == exercise.points, failing(results["reference"])
    method = "a spring K, damper D to the start"
    for label in ("no_gravity", "no_damper"):
        result = results[label]
        assert result.score < exercise.pass_mark, (label, failing(result))  # was 10/10
        assert method in failing(result) and "F/K up" in failing(result), failing(result)
    assert "rest point -" in failing(results["no_gravity"])[method]  # the arm's weight: down
    assert "D 0.0" in failing(results["no_damper"])[method]


@pytest.mark.slow
def test_computed_torque_without_the_model_misses_the_tracking(tmp_path):
    exercise = find_exercise("computed_torque")
    reference = exercise.solution.read_text()
    law = "        return self.dynamics.inverse_dynamics(qacc, contacts=True)[self.dofs]"
    assert law in reference
    stiff_pd = reference.replace(law, "        return self.dynamics.bias()[self.dofs] + 3000.0 * "
                                      "error + 40.0 * (dq_ref - state.dq)")
    written_down = reference.replace(law, "        inertia = np.array([[0.0261, 0.0068], "
                                          "[0.0068, 0.0044]])  # M of the given arm\n"
                                          "        return inertia @ ddq + self.dynamics.bias()"
                                          "[self.dofs]")
    stiffer_pd = reference.replace(law, "        return self.dynamics.gravity()[self.dofs] + 1e6 "
                                        "* error + 2000.0 * (dq_ref - state.dq)")
    results = scores("computed_torque", tmp_path, {"stiff_pd": stiff_pd,
                                                   "written_down": written_down,
                                                   "stiffer_pd": stiffer_pd})
    assert results["reference"].score == exercise.points, failing(results["reference"])
    for label in ("stiff_pd", "written_down", "stiffer_pd"):
        assert results[label].score < exercise.pass_mark, (label, failing(results[label]))
        assert "tracks the sine" in failing(results[label])
    assert "applies computed torque" in failing(results["stiffer_pd"])
