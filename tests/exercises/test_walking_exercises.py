"""Course exercises 11-13 (issue 39): the walking stack's COM planner, whole-body weights and
estimator, each graded through the framework on a short walk under the hidden variant (masses,
friction, a push). The reference scores full marks, the starter fails, and a cheat fails its
method check: the shipped planner under the student's name, a key that is not a QP weight,
an estimator that copies the simulator's base (which the grader hides from it)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from mexone.exercises import find_exercise, grade

COURSE = Path(__file__).resolve().parents[2] / "src" / "mexone" / "exercises" / "course"
WRONG = Path(__file__).resolve().parent / "wrong"
NAMES = ("walk_com_planner", "walk_faster", "walk_estimator")


@pytest.fixture(scope="module")
def graded():
    """grade(name, which) once per (exercise, reference | starter | cheat), shared by the
    tests below (each grading is a walk of a few seconds in the isolated child)."""
    cache: dict = {}

    def get(name: str, which: str):
        if (name, which) not in cache:
            exercise = find_exercise(name)
            path = {"reference": exercise.solution, "starter": exercise.starter,
                    "cheat": WRONG / name / exercise.file}[which]
            cache[name, which] = grade(exercise, path)
        return cache[name, which]
    return get


def checks(result) -> dict:
    return {c.name: (score, c.output) for c, score, _ in result.checks}


def why(result) -> list[str]:
    return [f"{c.name}: {c.output}" for c, _, _ in result.checks] + [result.failure or ""]


@pytest.mark.parametrize("name", NAMES)
def test_the_hidden_variant_is_not_the_given_robot(name):
    spec = importlib.util.spec_from_file_location(f"grader_{name}", COURSE / name / "grader.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    hidden = module.variant(np.random.default_rng(1))
    assert hidden != module.variant(None) and hidden.push is not None


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_the_reference_walks_for_full_marks_on_the_hidden_variant(graded, name):
    result = graded(name, "reference")
    assert result.score == pytest.approx(find_exercise(name).points), why(result)


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_the_starter_fails(graded, name):
    result = graded(name, "starter")
    assert result.score < find_exercise(name).pass_mark, why(result)
    if name == "walk_estimator":  # it walks, on a robot it believes stands still
        assert checks(result)["estimate tracks the truth"][0] == 0, why(result)
    else:  # it falls, or (on a variant where it stays up) walks nowhere near the speed
        said = checks(result)
        assert said["stays up"][0] == 0 or said.get("speed", (1,))[0] == 0, why(result)


def test_the_shipped_planner_under_the_students_name_scores_zero(graded):
    result = graded("walk_com_planner", "cheat")
    assert result.score == 0, why(result)
    assert "imports mexone.walking.mpc" in checks(result)["your planner in the chain"][1]


def test_the_shipped_planner_imported_by_name_at_run_time_scores_zero():
    exercise = find_exercise("walk_com_planner")
    result = grade(exercise, WRONG / "walk_com_planner" / "dynamic.py")
    assert result.score == 0 and "imports by name at run time (importlib)" in why(result)[1], \
        why(result)


def test_a_key_that_is_not_a_weight_of_the_qp_scores_zero_in_one_line(graded):
    result = graded("walk_faster", "cheat")
    assert result.score == 0 and "'max_forward' is not a task weight or gain" in why(result)[0], \
        why(result)


@pytest.mark.slow
def test_an_estimator_that_copies_the_simulators_base_fails(graded):
    """The grader hides the floating base from the student's class: a copy of state.all_q's
    base is the robot where it was put, so the stack walks on a robot standing still."""
    result = graded("walk_estimator", "cheat")
    assert result.score < find_exercise("walk_estimator").pass_mark, why(result)
    assert checks(result)["estimate tracks the truth"][0] == 0, why(result)


@pytest.mark.slow
def test_leg_odometry_without_a_filter_fails_on_the_noisy_encoders(tmp_path):
    """The skeleton `controllers new --part estimator` writes (leg odometry) walks, but the
    encoders' noise reaches its velocity: it earns nothing for the estimate and so no speed."""
    from mexone.walking.skeletons import walking_skeleton_files

    path = tmp_path / "estimator.py"
    path.write_text(walking_skeleton_files("my_estimator", "estimator")["my_estimator.py"])
    result = grade(find_exercise("walk_estimator"), path)
    assert result.score < find_exercise("walk_estimator").pass_mark, why(result)
    said = checks(result)
    assert said["stays up"][0] > 0 and said["estimate tracks the truth"][0] == 0, why(result)


@pytest.mark.slow
def test_the_com_planner_skeleton_handed_in_as_it_was_written_fails(tmp_path):
    """What `controllers new --part com_planner` writes, renamed as the exercise asks (and
    reading the estimator's base, optional): a DCM plan without its feedback, which is the
    student's part: it falls at its first steps, before any push (it scored 10/10 when the
    skeleton held the feedback)."""
    from mexone.walking.skeletons import walking_skeleton_files

    text = walking_skeleton_files("my_planner", "com_planner")["my_planner.py"]
    inputs = 'inputs = {"steps": Steps.LENGTH}'
    assert "class MyPlanner(" in text and inputs in text
    text = text.replace("class MyPlanner(", "class MyComPlanner(").replace(
        inputs, 'inputs = {"steps": Steps.LENGTH, "base": 13}\n    optional_inputs = ("base",)')
    path = tmp_path / "com_planner.py"
    path.write_text(text)
    result = grade(find_exercise("walk_com_planner"), path)
    assert result.score < find_exercise("walk_com_planner").pass_mark, why(result)
    said = checks(result)
    assert said["your planner in the chain"][0] > 0 and said["stays up"][0] == 0, why(result)


def test_the_shipped_estimator_under_the_students_name_scores_zero():
    result = grade(find_exercise("walk_estimator"), WRONG / "walk_estimator" / "shipped.py")
    assert result.score == 0, why(result)
    assert "imports mexone.walking.estimator" in checks(result)["estimate tracks the truth"][1]


SPY = '''
from mexone.control import PythonController


class MyEstimator(PythonController):
    exports = {"base": 13, "contact": 2}

    def update(self, state, t, dt):  # what it sees, in its base export (it may run elsewhere)
        self.exports["base"][:4] = (state.all_q[0], state.base.position[0],
                                    self.dynamics.pose("pelvis")[0][0], state.all_dq[0])
'''


def test_the_estimators_view_of_the_floating_base_is_where_the_robot_was_put(tmp_path):
    """The mechanism of exercise 13's method check: the robot moved 0.3 m forward at 1 m/s, the
    student's class still reads it at the start, at rest (all_q, state.base, self.dynamics),
    while the other parts read the simulator."""
    from mexone.exercises.course._walktools import blind_base, stack_yaml
    from mexone.lab import Lab

    source = tmp_path / "spy.py"
    source.write_text(SPY)
    work = tmp_path / "run"
    work.mkdir()
    lab = Lab.create(controllers=stack_yaml(work, "estimator", source, "spy.py", "MyEstimator"))
    start = float(lab.sim.data.qpos[0])
    blind_base(lab, "estimator")
    lab.sim.data.qpos[0] += 0.3
    lab.sim.data.qvel[0] = 1.0
    lab.sim.step(10)
    seen = lab.manager.controllers["estimator"].exports["base"][:4]
    assert np.allclose(seen[:3], start) and seen[3] == 0.0, (seen, start)
    whole_body = lab.manager.controllers["whole_body"]
    assert whole_body.state.all_q[0] > start + 0.29  # the others read the truth


@pytest.mark.parametrize("name, part, cls", [("walk_com_planner", "com_planner", "MyComPlanner"),
                                             ("walk_estimator", "estimator", "MyEstimator"),
                                             ("walk_faster", None, None)])
def test_start_writes_the_stack_with_the_students_class_in_its_place(name, part, cls, tmp_path):
    """`mexone exercise start` hands out controllers.yaml beside the starter: mexone's
    walking.yaml with the student's class in its part's place and the graded gait, which the
    lab loads from the started folder (the class from the student's own file); nothing the
    student made is overwritten without --force."""
    import yaml

    from helpers import run_cli
    from mexone.robots import mex_one

    folder = tmp_path / name
    code, out, err = run_cli(["exercise", "start", name, folder])
    assert code == 0 and "controllers.yaml" in out, err
    exercise = find_exercise(name)
    assert sorted(p.name for p in folder.iterdir()) == sorted(
        ["README.md", "check.py", "controllers.yaml", exercise.file])
    handed = next(iter(yaml.safe_load((folder / "controllers.yaml").read_text()).values()))
    shipped = next(iter(yaml.safe_load(mex_one.walking_path().read_text()).values()))
    assert handed.keys() == shipped.keys()
    gait = {"vx", "settle"} | ({"max_forward", "single_support", "double_support"} if part is None
                               else set())
    for key, entry in shipped.items():  # the shipped stack but the student's part and the gait
        changed = {k for k in entry.keys() | handed[key].keys() if entry.get(k) != handed[key].get(k)}
        assert changed == ({"type"} if key == part else gait if key == "footsteps" else set()), key
    if part is not None:
        assert handed[part]["type"] == f"{exercise.file[:-3]}/{cls}"
        from mexone.lab import Lab

        lab = Lab.create(controllers=folder / "controllers.yaml")
        ran = lab.manager.controllers[part]
        assert type(ran.impl).__name__ == cls
        assert ran.code_file and Path(ran.code_file).resolve() == (folder / exercise.file).resolve()
    assert "mexone sim --controllers controllers.yaml" in (folder / "controllers.yaml").read_text()
    (folder / "controllers.yaml").write_text("mine\n")
    code, _, err = run_cli(["exercise", "start", name, folder])
    assert code == 2 and "exists" in err and (folder / "controllers.yaml").read_text() == "mine\n"


def test_a_graders_files_naming_a_folder_is_one_line_and_writes_nothing(tmp_path):
    """A teacher's grader.py whose files() names a path out of the student's folder: refused."""
    from helpers import run_cli

    exercise = tmp_path / "mine"
    assert run_cli(["exercise", "new", "mine", exercise])[0] == 0
    with (exercise / "grader.py").open("a") as grader:
        grader.write("\n\ndef files():\n    return {'../escaped.yaml': 'x: 1\\n'}\n")
    code, _, err = run_cli(["exercise", "start", exercise, tmp_path / "st"])
    assert code == 2 and "files() names '../escaped.yaml'" in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "escaped.yaml").exists() and not (tmp_path / "st").exists()


ENCODER_SPY = '''
from mexone.control import PythonController


class MyEstimator(PythonController):
    exports = {"base": 13, "contact": 2}

    def update(self, state, t, dt):  # a joint's angle and velocity as it reads them
        self.exports["base"][:4] = (state.all_q[7], state.all_dq[6], state.all_q[8], state.all_dq[7])
'''


def test_the_estimators_encoders_are_noisy_and_only_its_own(tmp_path):
    """Exercise 13's encoders: the student's class reads each joint's angle and velocity with
    the noise Encoders names (measured: the standard deviation of what it reads less the
    truth), drawn from the seed; the other parts read the simulator."""
    from mexone.exercises.course._walktools import Encoders, blind_base, stack_yaml
    from mexone.lab import Lab

    source = tmp_path / "spy.py"
    source.write_text(ENCODER_SPY)
    work = tmp_path / "run"
    work.mkdir()
    lab = Lab.create(controllers=stack_yaml(work, "estimator", source, "spy.py", "MyEstimator"))
    blind_base(lab, "estimator", Encoders(angle=0.01, velocity=0.5, seed=3))
    sim, base = lab.sim, lab.manager.controllers["estimator"].exports["base"]
    errors = []
    for _ in range(200):
        sim.step(1)
        errors.append(np.array(base[:4]) - sim.data.qpos[7:9].repeat(2) * [1, 0, 1, 0]
                      - sim.data.qvel[6:8].repeat(2) * [0, 1, 0, 1])
    spread = np.std(errors, axis=0)
    assert np.all((spread[[0, 2]] > 0.007) & (spread[[0, 2]] < 0.013)), spread
    assert np.all((spread[[1, 3]] > 0.35) & (spread[[1, 3]] < 0.65)), spread
    whole_body = lab.manager.controllers["whole_body"]
    assert np.array_equal(whole_body.state.all_dq[6:], sim.data.qvel[6:])  # the others: exact
