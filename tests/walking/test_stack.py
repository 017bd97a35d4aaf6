"""The walking stack in the simulation: the shipped parts chained by the manager walk Mex-One
torque-level with the estimator in the loop; each part swapped for a student's (the skeletons
`mexone controllers new --part` writes) still walks; bad input is one line and a safe stop."""

from __future__ import annotations

import logging
import math

import pytest

from mexone.bus.msgs import Twist, Vector3
from mexone.lab import Lab
from mexone.robots import mex_one
from mexone.walking.skeletons import PARTS, walking_skeleton_files


def _yaw(q) -> float:
    return math.degrees(2 * math.atan2(q[6], q[3]))


def _run(lab, seconds: float, lowest: list | None = None) -> None:
    """Step `seconds` of sim time, noting the base's lowest height."""
    sim = lab.sim
    for _ in range(round(seconds / 0.05)):
        sim.step(50)
        if lowest is not None:
            lowest[0] = min(lowest[0], float(sim.data.qpos[2]))


def _command(lab, vx=0.0, vy=0.0, wz=0.0) -> None:
    for key, value in (("vx", vx), ("vy", vy), ("wz", wz)):
        lab.manager.set_param("footsteps", key, value)


@pytest.fixture(scope="module")
def course():
    """One walk of the shipped stack shared by the tests below (the acceptance course, 1 m
    sideways, the worlds and the pushes are benchmarks/walking_stack.py's): torque-level, the
    base from the estimator; 0.3 m/s forward, a stop, a quarter turn left, a stop, 0.3 m to
    the right. Returns what each leg measured."""
    lab = Lab.create(controllers=mex_one.walking_path())
    out = {"lowest": [1.0], "lab": lab}
    lowest = out["lowest"]
    _run(lab, 1.0, lowest)
    _command(lab, vx=0.3)
    _run(lab, 3.5, lowest)  # up to speed
    x0, t0 = lab.sim.data.qpos[0], lab.sim.time
    _run(lab, 2.0, lowest)
    out["speed"] = (lab.sim.data.qpos[0] - x0) / (lab.sim.time - t0)
    _command(lab)
    _run(lab, 1.0, lowest)
    yaw0 = _yaw(lab.sim.data.qpos)
    _command(lab, wz=0.75)
    for _ in range(40):
        _run(lab, 0.25, lowest)
        if _yaw(lab.sim.data.qpos) - yaw0 >= 90.0:
            break
    out["turned"] = _yaw(lab.sim.data.qpos) - yaw0
    _command(lab)
    _run(lab, 1.0, lowest)
    q = lab.sim.data.qpos
    heading = math.radians(_yaw(q))
    start = q[:2].copy()
    _command(lab, vy=-0.3)
    for _ in range(40):
        _run(lab, 0.25, lowest)
        moved = lab.sim.data.qpos[:2] - start
        if -moved[0] * math.sin(heading) + moved[1] * math.cos(heading) <= -0.3:
            break
    moved = lab.sim.data.qpos[:2] - start
    out["sideways"] = -moved[0] * math.sin(heading) + moved[1] * math.cos(heading)
    out["reports"] = {n: c.impl.report() for n, c in lab.manager.controllers.items()
                      if hasattr(c, "impl")}
    return out


@pytest.mark.slow
def test_the_stack_walks_torque_level_at_0_3_m_s_with_the_estimator_in_the_loop(course):
    whole_body = course["lab"].manager.controllers["whole_body"]
    assert whole_body.interface_name == "effort" and len(whole_body.joints) == 21
    assert course["speed"] >= 0.28
    assert course["reports"]["estimator"]["velocity_error_rms_mps"] < 0.05
    assert whole_body.budget()["updates"] > 0


@pytest.mark.slow
def test_the_stack_turns_a_quarter_and_walks_sideways_without_a_fall(course):
    assert course["turned"] >= 90.0
    assert course["sideways"] <= -0.3  # to its right
    assert course["lowest"][0] > 0.5
    reports = course["reports"]
    assert reports["whole_body"]["stopped"] is None and reports["whole_body"]["standing"] is None
    assert reports["com_planner"]["stopped"] is None


# what a student adds to the com_planner skeleton (exercise 11): the DCM's feedback
PLAN_ONLY = "        zmp = p_ref\n"
FEEDBACK = "        zmp = p_ref + (1.0 + 14.0 / omega) * (xi - xi_ref)\n"


@pytest.mark.slow
@pytest.mark.parametrize("kind", list(PARTS))
def test_each_part_swapped_for_a_students_still_walks(kind, tmp_path):
    """Each skeleton walks as written; com_planner's once the student adds the DCM's feedback
    (as written it falls: test_walking_exercises.py grades it)."""
    files = walking_skeleton_files(f"my_{kind}", kind)
    if kind == "com_planner":
        stem = "my_com_planner.py"
        assert files[stem].count(PLAN_ONLY) == 1
        files[stem] = files[stem].replace(PLAN_ONLY, FEEDBACK)
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    lab = Lab.create(controllers=tmp_path / "controllers.yaml")
    assert type(lab.manager.controllers[PARTS[kind][2]].impl).__name__ == \
        "My" + "".join(p.title() for p in kind.split("_"))
    lowest = [1.0]
    _run(lab, 1.0, lowest)
    if kind != "footsteps":  # the student's planner walks by itself
        _command(lab, vx=0.3)
    _run(lab, 3.0, lowest)
    assert lowest[0] > 0.5
    assert lab.sim.data.qpos[0] > 0.25  # it walked forward
    assert not [c.fault for c in lab.manager.controllers.values() if getattr(c, "fault", None)]


@pytest.fixture
def walking_lab():
    lab = Lab.create(controllers=mex_one.walking_path())
    _run(lab, 1.0)
    _command(lab, vx=0.2)
    _run(lab, 0.8)  # the first step is in the air
    return lab


def test_a_nan_cmd_vel_is_one_line_and_the_robot_stops_walking(walking_lab, caplog):
    lab = walking_lab
    lab.manager.set_param("footsteps", "timeout", 60.0)
    with caplog.at_level(logging.ERROR, logger="mexone.control.student"):
        lab.bus.publish(f"{lab.namespace}/cmd_vel", Twist(Vector3(float("nan"), 0.0, 0.0), Vector3()))
        _run(lab, 2.0)
    lines = [r.getMessage() for r in caplog.records if "not finite" in r.getMessage()]
    assert len(lines) == 1 and "cmd_vel (nan, 0, 0) is not finite" in lines[0]
    planner = lab.manager.controllers["footsteps"].impl
    assert not planner.planner.walking and planner.report()["refused"] == "cmd_vel not finite"
    assert lab.sim.data.qpos[2] > 0.5


def test_an_unreachable_step_is_one_line_and_the_robot_stands(walking_lab, caplog):
    """A planner (here: the shipped one, its next step moved 1 m aside) asks for a step the legs
    cannot take: the whole-body controller refuses it and stands."""
    lab = walking_lab
    planner = lab.manager.controllers["footsteps"].impl
    original = planner.planner.update

    def far(t):
        steps = original(t)
        steps[8 + 2] += 1.0  # the first planned step's y
        return steps

    planner.planner.update = far
    with caplog.at_level(logging.ERROR, logger="mexone.control.student"):
        _run(lab, 1.5)
    lines = [r.getMessage() for r in caplog.records if "out of reach" in r.getMessage()
             or "the legs reach" in r.getMessage()]
    assert len(lines) == 1 and "refused, the robot stands" in lines[0]
    assert lab.manager.controllers["whole_body"].impl.report()["standing"]
    assert lab.sim.data.qpos[2] > 0.5


def test_a_nan_com_reference_is_one_line_and_the_robot_stands(walking_lab, caplog):
    """A COM planner exporting a NaN acceleration (which would make the QP's cost NaN): one line,
    the step under way lands, the robot stands."""
    lab = walking_lab
    com = lab.manager.controllers["com_planner"].impl
    update = com.update

    def broken(state, t, dt):
        update(state, t, dt)
        com.exports["com"][6] = float("nan")

    com.update = broken
    with caplog.at_level(logging.ERROR, logger="mexone.control.student"):
        _run(lab, 1.5)
    lines = [r.getMessage() for r in caplog.records if "not finite" in r.getMessage()]
    assert len(lines) == 1 and "the COM reference is not finite" in lines[0]
    assert "robot stands" in lines[0]
    assert lab.manager.controllers["whole_body"].impl.report()["standing"]
    assert lab.sim.data.qpos[2] > 0.5


def test_the_renamed_kind_option_still_writes_a_part_and_says_its_new_name(tmp_path):
    """`controllers new --kind PART` was renamed `--part` (a walking part is not a controller's
    kind): for one release it works the same and says the new name on stderr."""
    import warnings

    from helpers import run_cli
    from mexone.walking import skeletons

    code, _, err = run_cli(["controllers", "new", "my_est", str(tmp_path / "old"),
                            "--kind", "estimator"])
    assert code == 0 and "--kind is renamed --part" in err, err
    code, _, err = run_cli(["controllers", "new", "my_est", str(tmp_path / "new"),
                            "--part", "estimator"])
    assert code == 0 and "renamed" not in err, err
    for name in ("my_est.py", "controllers.yaml"):
        assert (tmp_path / "old" / name).read_text() == (tmp_path / "new" / name).read_text()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert skeletons.KINDS is skeletons.PARTS
    assert "renamed PARTS" in str(caught[0].message)
