"""Hostile commands from a ROS 2 graph, property-tested on the conversion the bridge runs in rclpy's
thread (convert.py reads messages only by attribute, so stand-ins with rclpy's field names serve):
every message is either a bus message of finite numbers or an InputError, never another
exception; and the parameter checks refuse every value of the wrong type or range."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest
from hypothesis import given
from hypothesis import strategies as st

from helpers import fuzz
from mexone.bus import msgs
from mexone.errors import InputError
from mexone.ros2 import convert

anything = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**6, 10**6))


def _stamp(sec=0, nanosec=0):
    return SimpleNamespace(sec=sec, nanosec=nanosec)


@fuzz(60)
@given(st.lists(anything, max_size=5))
def test_commands_to_a_one_joint_controller(values):
    build = convert.commands_to(msgs.Float64)
    try:
        out = build(SimpleNamespace(data=values))
    except InputError as exc:
        assert "values" in str(exc) or "finite" in str(exc)
        assert len(values) != 1 or not math.isfinite(values[0])
        return
    assert len(values) == 1 and out.data == float(values[0]) and math.isfinite(out.data)


@fuzz(60)
@given(st.lists(anything, max_size=8))
def test_group_commands_are_finite_or_refused(values):
    try:
        out = convert.from_ros2(SimpleNamespace(data=[float(v) for v in values]),
                                msgs.Float64MultiArray)
    except InputError:
        assert not all(math.isfinite(v) for v in values)
        return
    assert out.data == [float(v) for v in values]


@fuzz(40)
@given(st.floats(allow_nan=True, allow_infinity=True), st.floats(allow_nan=True,
                                                                  allow_infinity=True))
def test_cmd_vel_is_finite_or_refused(vx, wz):
    twist = SimpleNamespace(linear=SimpleNamespace(x=vx, y=0.0, z=0.0),
                            angular=SimpleNamespace(x=0.0, y=0.0, z=wz))
    try:
        out = convert.from_ros2(twist, msgs.Twist)
    except InputError:
        assert not (math.isfinite(vx) and math.isfinite(wz))
        return
    assert (out.linear.x, out.angular.z) == (vx, wz)


@fuzz(40)
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=1, max_size=3))
def test_trajectory_points_are_finite_or_refused(positions):
    point = SimpleNamespace(positions=positions, velocities=[], accelerations=[], effort=[],
                            time_from_start=_stamp(0, 5))
    ros = SimpleNamespace(header=SimpleNamespace(stamp=_stamp(), frame_id=""),
                          joint_names=["a"] * len(positions), points=[point])
    try:
        out = convert.from_ros2(ros, msgs.JointTrajectory)
    except InputError:
        assert not all(math.isfinite(p) for p in positions)
        return
    assert out.points[0].positions == positions
    assert out.points[0].time_from_start == msgs.Duration(0, 5)


@pytest.mark.parametrize("name, value, refused", [
    ("physics.time_step", 0.002, False), ("physics.time_step", 1.0, True),
    ("physics.time_step", "fast", True), ("physics.time_step", float("nan"), True),
    ("physics.gravity", [0.0, 0.0, -9.81], False), ("physics.gravity", [0.0, -9.81], True),
    ("physics.gravity", [0.0, 0.0, float("inf")], True), ("physics.real_time_factor", 0, False),
    ("physics.solver_iterations", 50, False), ("physics.solver_iterations", 2.5, True),
    ("physics.solver_iterations", True, True), ("physics.nothing", 1.0, True),
])
def test_physics_parameter_checks(name, value, refused):
    from mexone.ros2.params import Parameters

    checker = Parameters.__new__(Parameters)
    checker.lab = SimpleNamespace(controllers=None)
    if refused:
        with pytest.raises(InputError):
            checker._check(name, value)
    else:
        assert checker._check(name, value)[0] == name
