"""joint_trajectory_controller's goals (what FollowJointTrajectory serves): success within the
goal tolerance, path and goal tolerance violations with control_msgs' codes, preemption, and
query_state sampling the reference."""

from __future__ import annotations

import numpy as np
import pytest

from mexone.bus.msgs import Duration, JointTrajectory, JointTrajectoryPoint
from mexone.control.config import parse_control_config
from mexone.control.controllers.trajectory import (
    GOAL_TOLERANCE_VIOLATED,
    INVALID_JOINTS,
    PATH_TOLERANCE_VIOLATED,
    PREEMPTED,
    SUCCESSFUL,
    TrajectoryGoal,
)
from mexone.description.urdf import read_urdf
from mexone.lab import Lab

YAML = """turntable:
  arm:
    type: effort_controllers/JointTrajectoryController
    joints: [yaw]
    gains: {yaw: {p: 40.0, d: 4.0}}
"""


@pytest.fixture()
def arm(tmp_path, turntable):
    lab = Lab.create(read_urdf(turntable[0](tmp_path)), parse_control_config(YAML))
    return lab, lab.manager.controllers["arm"]


def trajectory(*points):
    return JointTrajectory(joint_names=["yaw"], points=[
        JointTrajectoryPoint([q], time_from_start=Duration.from_sec(t)) for t, q in points])


def goal(outcome, path=0.0, position=0.0, velocity=0.0, time=0.0):
    return TrajectoryGoal(np.array([path]), np.array([position]), np.array([velocity]), time,
                          lambda code, text: outcome.append((code, text)))


def test_a_goal_succeeds_within_its_tolerance_and_query_state_samples_it(arm):
    lab, ctrl = arm
    outcome = []
    ctrl.execute(trajectory((1.0, 0.5)), goal(outcome, position=0.01, time=1.0), lab.sim.time)
    lab.sim.step(500)
    q, v, a = ctrl.query_state(0.5)
    assert q[0] == pytest.approx(0.25, abs=1e-6) and v[0] == pytest.approx(0.5, abs=1e-6)
    assert outcome == []
    lab.sim.step(1500)
    assert outcome and outcome[0][0] == SUCCESSFUL
    assert lab.sim.joint_positions()[0] == pytest.approx(0.5, abs=0.01)


def test_path_and_goal_tolerances_abort_with_their_codes(arm):
    lab, ctrl = arm
    outcome = []
    ctrl.execute(trajectory((0.05, 2.0)), goal(outcome, path=0.01), lab.sim.time)  # too fast
    lab.sim.step(40)
    assert outcome[0][0] == PATH_TOLERANCE_VIOLATED and "yaw" in outcome[0][1]
    lab.sim.step(200)  # it holds where it was when aborted
    held = lab.sim.joint_positions()[0]
    lab.sim.step(200)
    assert lab.sim.joint_positions()[0] == pytest.approx(held, abs=0.01)
    outcome.clear()
    ctrl.execute(trajectory((0.1, 1.0)), goal(outcome, position=1e-6, time=0.05), lab.sim.time)
    lab.sim.step(300)
    assert outcome[0][0] == GOAL_TOLERANCE_VIOLATED


def test_wrong_joints_and_preemption(arm):
    lab, ctrl = arm
    outcome = []
    wrong = JointTrajectory(joint_names=["pitch"], points=[JointTrajectoryPoint([0.1])])
    ctrl.execute(wrong, goal(outcome), lab.sim.time)
    assert outcome[0][0] == INVALID_JOINTS
    first, second = [], []
    ctrl.execute(trajectory((2.0, 1.0)), goal(first, position=0.01), lab.sim.time)
    lab.sim.step(100)
    ctrl.execute(trajectory((0.5, -0.2)), goal(second, position=0.02, time=2.0), lab.sim.time)
    assert first[0][0] == PREEMPTED
    lab.sim.step(2000)
    assert second[0][0] == SUCCESSFUL
