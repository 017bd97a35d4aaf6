"""The seed's 4.3 acceptance on Mex-One: home position, arms routine, joint states, routines."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from mexone.bus.msgs import JointState
from mexone.control.metrics import TrackingRecorder
from mexone.lab import Lab
from mexone.routines.runner import RoutineRunner

ARM_JOINTS = ("l_shoulder_pitch", "r_shoulder_pitch", "l_elbow", "r_elbow")


def tilt(sim) -> float:
    rot = sim.data.xmat[sim.compiled.root_body].reshape(3, 3)
    return float(np.arccos(np.clip(rot[2, 2], -1, 1)))


@pytest.mark.slow
def test_home_position_is_held_for_10_seconds():
    lab = Lab.create()
    worst = 0.0
    for _ in range(1000):
        lab.sim.step(10)
        worst = max(worst, float(np.abs(lab.sim.joint_positions()).max()))
    assert worst < 0.02
    assert lab.sim.base_height == pytest.approx(0.60, abs=0.005) and tilt(lab.sim) < 0.02


@pytest.mark.slow
def test_arms_routine_tracks_and_the_robot_stays_standing():
    lab = Lab.create()
    recorder = TrackingRecorder(lab.sim, lab.manager)
    runner = RoutineRunner(lab, "arms")
    runner.run(9.0)
    assert runner.error is None
    metrics = recorder.metrics()
    for joint in ARM_JOINTS:
        assert metrics[joint].rms_error < 0.05, metrics[joint]
        assert metrics[joint].steps > 20  # it really moved them
    assert lab.sim.base_height == pytest.approx(0.60, abs=0.01) and tilt(lab.sim) < 0.05


def test_joint_states_at_50hz_alphabetical_with_applied_effort():
    lab = Lab.create()
    got: list[JointState] = []
    lab.bus.subscribe("/mex_rb/joint_states", JointState, got.append)
    lab.sim.step(1000)
    assert len(got) == 50
    stamps = np.array([m.header.stamp.to_sec() for m in got])
    np.testing.assert_allclose(stamps, 0.02 * np.arange(1, 51), atol=1e-9)
    assert got[-1].name == sorted(got[-1].name) and len(got[-1].name) == 21
    last = got[-1]
    hw = lab.manager.hw
    rows = np.array([hw.index[n] for n in last.name])
    np.testing.assert_allclose(last.effort, lab.sim.data.qfrc_actuator[hw.dof_adr[rows]], atol=1e-9)
    np.testing.assert_allclose(last.position, lab.sim.data.qpos[hw.qpos_adr[rows]])


def test_routine_timing_follows_sim_time_and_is_deterministic():
    runs = []
    for _ in range(2):
        lab = Lab.create()
        runner = RoutineRunner(lab, "joint_steps")
        runner.run(2.5)
        runs.append((runner.log_lines, lab.sim.joint_positions()))
    (logs, q), (logs2, q2) = runs
    times = [t for t, _, _ in logs]
    np.testing.assert_allclose(times, 0.1 * np.arange(len(times)), atol=1e-9)  # Rate(10)
    assert [text for _, _, text in logs[:3]] == ["Publishing: 0", "Publishing: 1", "Publishing: 2"]
    assert logs == logs2 and np.array_equal(q, q2)


def test_a_students_rospy_routine(tmp_path):
    routine = tmp_path / "student.py"
    routine.write_text('''
from mexone import rospy
from mexone.msgs import Float64, JointState

rospy.init_node("student")
state = rospy.wait_for_message("/mex_rb/joint_states", JointState, timeout=1.0)
rospy.loginfo("first joint state at %.3f with %d joints", state.header.stamp.to_sec(), len(state.name))
gain = rospy.get_param("/mex_rb/l_elbow_position_controller/pid/p")
target = rospy.get_param("~target", -0.5)
pub = rospy.Publisher("/mex_rb/l_elbow_position_controller/command", Float64, queue_size=10)
pub.publish(target)
rospy.sleep(1.0)
rospy.loginfo("p=%g t=%.3f", gain, rospy.get_time())
''')
    lab = Lab.create()
    runner = RoutineRunner(lab, routine, {"_target": -0.8})
    runner.run(5.0)
    assert runner.error is None
    texts = [text for _, _, text in runner.log_lines]
    assert texts[0] == "first joint state at 0.020 with 21 joints"
    assert texts[1] == "p=60 t=1.020"
    assert lab.sim.time == pytest.approx(1.02)  # the run ends when the routine does
    elbow = lab.sim.joint_names.index("l_elbow")
    assert lab.sim.joint_positions()[elbow] == pytest.approx(-0.8, abs=0.03)


def test_a_failing_routine_reports_the_students_line(tmp_path):
    routine = tmp_path / "broken.py"
    routine.write_text("from mexone import rospy\nrospy.init_node('b')\nrospy.sleep(0.5)\n1 / 0\n")
    out = subprocess.run([sys.executable, "-m", "mexone", "run", str(routine), "--json"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 1
    report = json.loads(out.stdout)
    assert "ZeroDivisionError" in report["error"] and f'{routine}", line 4' in report["error"]


def test_run_cli_report():
    out = subprocess.run([sys.executable, "-m", "mexone", "run", "joint_steps", "--duration", "3",
                          "--json", "_joint:=r_elbow"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert report["routine"] == "joint_steps" and report["fell"] is False and report["error"] is None
    elbow = report["joints"]["r_elbow"]
    assert elbow["steps"] >= 20 and elbow["rms_error"] < 0.1
    assert {"rms_error", "max_error", "overshoot", "settling_time"} <= set(elbow)


def test_run_bad_input():
    out = subprocess.run([sys.executable, "-m", "mexone", "run", "nowhere"], capture_output=True,
                         text=True)
    assert out.returncode == 2
    from mexone.routines.runner import shipped_routines

    shipped = ", ".join(shipped_routines())  # joint_steps, arms, home, then whatever joined them
    assert shipped.startswith("joint_steps, arms, home")
    assert out.stderr == f"mexone: no routine 'nowhere' (give a Python file or one of: {shipped})\n"
    out = subprocess.run([sys.executable, "-m", "mexone", "run", "joint_steps", "joint=r_elbow"],
                         capture_output=True, text=True)
    assert out.returncode == 2 and "is not name:=value" in out.stderr
