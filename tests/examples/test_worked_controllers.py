"""The four worked controllers of examples/controllers/ do what their READMEs measure (issue 25's
acceptance), each measured here independently of the controller's own report: joint positions
and the hand sampled from the simulation every step, falls by the push-recovery rule.

- gravity compensation alone floats the right arm: it drifts < 2 mrad in 1 s (without g(q) it
  falls > 500 mrad), and a push moves it to a new pose where it stays;
- computed torque tracks a minimum-jerk move of the right arm >= 20x closer than the shipped PIDs
  fed the same trajectory;
- the right hand draws a 4 cm circle within 4 mm RMS;
- the LQR on the sideways sway settles a sideways push at least 2x sooner than the shipped PD,
  with a smaller excursion, its gain being the LQR's of the linear model (a closed form);
- each runs headless from its YAML and reports in `mexone sim --json`.

They teach the methods of course exercises 5-8 on other joints and other tasks: none of them is
an exercise's answer (issue 36): a copy of the fourth handed in for exercise 8 fails it.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mexone.cli.common import read_pose
from mexone.control import load_control_config
from mexone.lab import Lab
from mexone.motion.push import PUSH_SECONDS
from mexone.physics.compile import Spawn

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "controllers"
GRAVITY, TRACKING, CIRCLE, SWAY = (EXAMPLES / n for n in (
    "01_gravity_float", "02_computed_torque_move", "03_hand_circle", "04_lqr_sway"))
ARM = ["r_shoulder_pitch", "r_shoulder_roll", "r_elbow"]


def make_lab(example: Path, shipped: bool = False, in_process: bool = False) -> Lab:
    """The example's YAML (or, `shipped`, Mex-One's own controllers) with the example's pose;
    `in_process`: its class handed over in Python (a test that reaches into the object), not
    run in a process of its own."""
    pose = example / "pose.yaml"
    joints = tuple(read_pose(pose).items()) if pose.exists() else ()
    controllers = None if shipped else example / "controllers.yaml"
    if in_process:
        controllers = load_control_config(controllers, classes=_classes(controllers))
    return Lab.create(controllers=controllers, spawn=Spawn(joints=joints))


def _classes(yaml_path: Path) -> dict[str, type]:
    """{type: class} of the YAML's controllers whose file is beside it, imported here."""
    import importlib.util

    import yaml

    out = {}
    for entry in next(iter(yaml.safe_load(yaml_path.read_text()).values())).values():
        stem, _, name = str(entry.get("type", "")).rpartition("/")
        file = yaml_path.parent / f"{stem}.py"
        if file.is_file():
            spec = importlib.util.spec_from_file_location(f"handed_{stem}", file)
            module = importlib.util.module_from_spec(spec)
            sys.modules[spec.name] = module
            spec.loader.exec_module(module)
            out[entry["type"]] = getattr(module, name)
    return out


class JointLog:
    """Every step's positions of `joints` (read in the simulation thread, between steps)."""

    def __init__(self, lab: Lab, joints: list[str]):
        model = lab.sim.model
        self.adr = [int(model.joint(j).qposadr[0]) for j in joints]
        self.times: list[float] = []
        self.q: list[np.ndarray] = []
        lab.sim.add_periodic(lab.sim.timestep, self.sample)

    def sample(self, sim) -> None:
        self.times.append(sim.time)
        self.q.append(sim.data.qpos[self.adr].copy())


def example_module(example: Path, name: str):
    """The example's own module (its reference or constants), imported from its folder."""
    sys.path.insert(0, str(example))
    try:
        return __import__(name)
    finally:
        sys.path.remove(str(example))


def farthest(lab: Lab, joints: list[str], seconds: float) -> float:
    """The farthest any of `joints` gets from where it is, over `seconds` (rad)."""
    log = JointLog(lab, joints)
    lab.sim.run(seconds)
    return float(np.abs(np.array(log.q) - log.q[0]).max())


def test_gravity_compensation_floats_the_arm_where_it_is_left():
    floating = make_lab(GRAVITY)
    drift = farthest(floating, ARM, 1.0)
    falling = make_lab(GRAVITY)
    falling.manager.controllers["gravity_float"].set_param("gravity", 0.0)  # damping alone
    fell = farthest(falling, ARM, 1.0)
    assert drift < 2e-3, f"the floating arm drifted {drift * 1e3:.2f} mrad"
    assert fell > 0.5, f"without g(q) the arm fell only {fell * 1e3:.0f} mrad"
    log = JointLog(floating, ARM)  # a push moves it; released, it stays (no spring to return)
    floating.sim.apply_joint_effort("r_shoulder_pitch", 0.5, duration=0.2)
    floating.sim.run(0.7)
    pushed = log.q[-1] - log.q[0]
    floating.sim.run(0.5)
    assert pushed[0] > 0.1, pushed
    assert np.abs(log.q[-1] - log.q[0] - pushed).max() < 2e-3, (pushed, log.q[-1] - log.q[0])


def move_rms(lab: Lab, command=None) -> float:
    """RMS of q - q_r over the 1 s minimum-jerk move and 0.5 s of hold, every step."""
    move = example_module(TRACKING, "computed_torque_move")
    joints = ["r_shoulder_pitch", "r_elbow"]
    q0 = np.array([v for _, v in read_pose(TRACKING / "pose.yaml").items()])
    delta = np.array([-0.8, -0.9])  # the YAML's move_shoulder, move_elbow

    def reference(t: float) -> np.ndarray:
        return q0 + move.minimum_jerk(t, 1.0)[0] * delta

    log = JointLog(lab, joints)
    if command is not None:  # the shipped PIDs: a new setpoint every step, as a node would send
        lab.sim.add_periodic(lab.sim.timestep, lambda sim: command(reference(sim.time)))
        command(q0)
    lab.sim.run(1.5)
    errors = np.array(log.q) - np.array([reference(t) for t in log.times])
    return float(np.sqrt(np.mean(errors**2)))


def test_computed_torque_moves_twenty_times_closer_than_the_shipped_pid():
    joints = ["r_shoulder_pitch", "r_elbow"]
    assert list(read_pose(TRACKING / "pose.yaml")) == joints  # q0 in the joints' order
    computed = move_rms(make_lab(TRACKING))
    pids = [f"{j}_position_controller" for j in joints]
    lab = make_lab(TRACKING, shipped=True)

    def command(q):
        for name, value in zip(pids, q, strict=True):
            lab.manager.command(name, [float(value)])

    shipped = move_rms(lab, command)
    print(f"computed torque {computed * 1e3:.3f} mrad RMS, shipped PIDs {shipped * 1e3:.2f}")
    assert computed * 20 <= shipped, (computed, shipped)
    assert shipped > 5e-3  # the PIDs did track (not a lab where nothing moved)


def test_the_hand_draws_its_circle():
    example = example_module(CIRCLE, "hand_circle")
    lab = make_lab(CIRCLE)
    sim = lab.sim
    body = sim.body_id(example.HAND)

    def hand() -> np.ndarray:  # as the simulation has it
        return sim.data.xpos[body] + sim.data.xmat[body].reshape(3, 3) @ example.HAND_POINT

    start, misses = hand(), []  # the circle starts where the hand is, at t = 0
    sim.add_periodic(sim.timestep, lambda s: misses.append(
        hand() - example.circle(s.time, start, 0.04, 0.5)[0]))  # the YAML's radius, frequency
    sim.run(4.0)  # two turns
    rms = float(np.sqrt(np.mean(np.sum(np.array(misses) ** 2, axis=1))))
    print(f"the hand's RMS distance from the circle: {rms * 1e3:.2f} mm")
    assert rms < 4e-3, rms


def sway_after_push(lab: Lab, impulse: float = 1.0) -> tuple[float, float]:
    """A sideways push of `impulse` N s at the torso after 0.5 s standing -> (the centre of
    mass's largest sideways excursion, m; the time from the push until it stays within 10 % of
    that of where it ends, s), the COM sampled from the simulation every step for 2 s."""
    sim = lab.sim
    sim.run(0.5)
    y: list[float] = []
    sim.add_periodic(sim.timestep, lambda s: y.append(float(s.data.subtree_com[1][1])))
    sim.apply_wrench("torso", (0.0, impulse / PUSH_SECONDS, 0.0), duration=PUSH_SECONDS)
    sim.run(2.0)
    off = np.array(y) - y[0]
    miss = np.abs(off - off[-200:].mean())
    settled = (np.nonzero(miss > 0.1 * miss.max())[0][-1] + 1) * sim.timestep
    return float(np.abs(off).max()), float(settled)


def test_lqr_settles_the_sideways_sway_sooner_than_pd_alone():
    """1 N s sideways: the LQR's gain (the closed form of the 2-state Riccati equation) damps
    the sway the shipped PD leaves ringing (its damping ratio about 0.1)."""
    sway = example_module(SWAY, "lqr_sway")
    lab = make_lab(SWAY, in_process=True)
    lab.sim.run(0.01)
    impl = lab.manager.controllers["lqr_sway"].impl
    a, b = sway.sway_model(impl.dynamics.mass(), impl.height, 600.0)
    a21, b2 = a[1, 0], b[1, 0]  # the Riccati equation solved by hand for x'' = a21 x + b2 u:
    k1 = a21 / b2 + np.sqrt((a21 / b2) ** 2 + 100.0 / 1e-4)  # the YAML's q_tilt / r_torque
    k2 = np.sqrt((1.0 + 2 * k1 * 1e-4 / b2) / 1e-4)  # q_rate, and 2 P12 = 2 r k1 / b2
    assert impl.gain == pytest.approx([k1, k2], rel=1e-6)
    assert 0.45 < impl.height < 0.55  # the COM above the ankles' axes
    lqr_peak, lqr_settle = sway_after_push(make_lab(SWAY))
    pd_peak, pd_settle = sway_after_push(make_lab(SWAY, shipped=True))
    print(f"1 N s sideways: LQR {lqr_peak * 1e3:.2f} mm, settled in {lqr_settle:.3f} s; "
          f"PD {pd_peak * 1e3:.2f} mm, {pd_settle:.3f} s")
    assert lqr_settle * 2 <= pd_settle, (lqr_settle, pd_settle)
    assert lqr_peak < pd_peak, (lqr_peak, pd_peak)
    assert pd_peak > 1e-3  # the push did move it


@pytest.mark.slow
def test_a_copy_of_the_worked_lqr_handed_in_for_exercise_8_fails_it(tmp_path):
    """The worked LQR renamed to exercise 8's class (as a student would hand it in) scores
    below the pass mark; the teacher's reference still passes (issue 36: worked examples teach
    the method, they are not an exercise's answer)."""
    from mexone.exercises import find_exercise, grade

    exercise = find_exercise("balance_under_pushes")
    copy = tmp_path / exercise.file
    copy.write_text((SWAY / "lqr_sway.py").read_text().replace("class LqrSway", "class Balance"))
    copied = grade(exercise, copy)
    assert copied.score < exercise.pass_mark, [c.output for c, _, _ in copied.checks]
    reference = grade(exercise, exercise.solution)
    print(f"exercise 8: the worked LQR's copy {copied.score:.1f}, the reference "
          f"{reference.score:.1f} of {exercise.points:g} (pass {exercise.pass_mark:g})")
    assert reference.score >= exercise.pass_mark, [c.output for c, _, _ in reference.checks]


@pytest.mark.parametrize("example, seconds, check", [
    (GRAVITY, 0.5, lambda r: r["gravity_float"]["moved_mrad"] < 2.0),
    (TRACKING, 0.5, lambda r: r["computed_torque_move"]["max_error_mrad"] < 5.0),
    (CIRCLE, 0.5, lambda r: r["hand_circle"]["rms_error_mm"] < 5.0),
    (SWAY, 0.5, lambda r: r["lqr_sway"]["max_sway_mm"] < 5.0 and r["lqr_sway"]["gain"][0] > 0),
], ids=["gravity", "tracking", "circle", "sway"])
def test_each_runs_headless_with_a_json_report(example, seconds, check):
    pose = ["--pose", str(example / "pose.yaml")] if (example / "pose.yaml").exists() else []
    out = subprocess.run([sys.executable, "-m", "mexone", "sim", "--headless", "--json",
                          "--duration", str(seconds), "--controllers",
                          str(example / "controllers.yaml"), *pose],
                         capture_output=True, text=True, timeout=120, env=dict(os.environ))
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert report["sim_time"] == pytest.approx(seconds) and not report["diverged"]
    assert check(report["controllers"]), report["controllers"]
    assert "Traceback" not in out.stderr
    assert math.isfinite(report["rtf"])


def test_a_report_that_raises_or_holds_numpy_does_not_end_the_summary():
    from mexone.cli.sim import controller_reports

    lab = make_lab(GRAVITY, in_process=True)
    lab.sim.run(0.01)
    impl = lab.manager.controllers["gravity_float"].impl
    impl.report = lambda: {"start": impl.start, "worst": np.float64(impl.moved)}
    reports = controller_reports(lab)
    assert reports["gravity_float"]["start"] == pytest.approx(list(impl.start))
    lab.manager.switch(stop=["gravity_float"])
    assert "gravity_float" not in controller_reports(lab)  # stopped: no report
    lab.manager.switch(start=["gravity_float"])
    impl.report = lambda: 1 / 0
    assert reports != (broken := controller_reports(lab))
    assert broken["gravity_float"]["error"] == "report() raised ZeroDivisionError: division by zero"
    assert set(broken["gravity_float"]) == {"error", "budget"}  # the budget meter goes on


def test_a_controller_a_fault_stopped_is_in_the_summary_with_its_line():
    from mexone.cli.sim import controller_reports

    lab = make_lab(GRAVITY, in_process=True)
    impl = lab.manager.controllers["gravity_float"].impl

    def update(state, t, dt):
        raise RuntimeError("student's bug")

    impl.update = update
    lab.sim.run(0.01)
    assert not lab.manager.controllers["gravity_float"].running
    entry = controller_reports(lab)["gravity_float"]  # not a clean-looking run
    assert entry["fault"].startswith("update raised") and "student's bug" in entry["fault"]
    assert "moved_mrad" in entry  # its report up to the fault


def test_a_report_with_nan_is_strict_json():
    from mexone.cli.sim import controller_reports

    lab = make_lab(GRAVITY, in_process=True)
    impl = lab.manager.controllers["gravity_float"].impl
    impl.report = lambda: {"worst": float("nan"), "gain": [np.inf, 2.0], "ok": np.float32(1.5)}
    text = json.dumps(controller_reports(lab))  # was NaN / Infinity: not JSON, jq refuses it
    read = json.loads(text, parse_constant=lambda c: pytest.fail(c))
    assert read["gravity_float"].pop("budget")["updates"] == 0  # the meter's, beside it
    assert read == {"gravity_float": {"worst": None, "gain": [None, 2.0], "ok": 1.5}}
