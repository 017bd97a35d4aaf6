"""The shipped `excitation` routine, run by `mexone record` as a student would: every joint moves,
inside its limits, and a standing Mex-One stays on its feet through the squat."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from mexone.description.loader import load_model
from mexone.record.reader import read_bag, read_joint_series
from mexone.robots import mex_one


def record(tmp_path, *args: str):
    bag = tmp_path / "excite.mcap"
    out = subprocess.run([sys.executable, "-m", "mexone", "record", "excitation", *args, "-o",
                          str(bag), "--duration", "7"], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    return bag


def _check_limits(series, robot, moving: set[str]) -> None:
    for name in moving:
        limit = robot.joints[name].limit
        q = series[name].position
        assert limit.lower <= q.min() and q.max() <= limit.upper, name
        assert np.ptp(q[len(q) // 2:]) > 0.02, name  # excited, not just posed


@pytest.mark.slow
def test_on_a_stand_every_joint_moves_within_its_limits(tmp_path):
    bag = record(tmp_path, "_base:=fixed", "--fixed-base", "-z", "0.3")
    robot = load_model(mex_one.urdf_path())
    _check_limits(read_joint_series(bag), robot, {j.name for j in robot.actuated_joints})


def test_standing_it_squats_and_stays_on_its_feet(tmp_path):
    bag = record(tmp_path)
    robot = load_model(mex_one.urdf_path())
    series = read_joint_series(bag)
    upper = {j.name for j in robot.actuated_joints
             if not any(w in j.name for w in ("hip", "knee", "ankle"))}
    _check_limits(series, robot, upper | {"l_knee", "r_knee", "l_hip_pitch", "r_hip_pitch"})
    for still in ("l_hip_yaw", "r_hip_roll", "l_ankle_roll"):  # would tip it over
        assert np.ptp(series[still].position) < 0.02, still
    tf = [s for s in read_bag(bag, frames=(robot.base_link,)).transforms
          if s.child == robot.base_link]
    z = np.array([s.xyz[2] for s in tf])
    up = np.array([1 - 2 * (s.quat[1] ** 2 + s.quat[2] ** 2) for s in tf])  # body z . world z
    assert z.min() > 0.8 * z[0] and z.max() < z[0] + 0.02  # squats a little, never falls
    assert up.min() > np.cos(np.radians(15))  # the pelvis stays upright
